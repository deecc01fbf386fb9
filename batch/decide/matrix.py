"""Across Cycles builds and releases: a matrix (every adjacent pair of builds compared, and each against a
baseline) and a bisect (the first build of an ordered list where a difference appears).

A build is this process's bpy module (``current``), another release's bpy (``4.5.4``: its cached environment,
`batch.jobs.releases`), or a Blender binary (a path). Each build renders the same job on its own seeds (build k
the k-th block of `passes` seeds: disjoint, so any two are independent), into ``<out>/<build>.npz``, resumed
where it stopped; the comparisons are the fixed-design `compare` of those files, one report each.

What each answer controls: a matrix cell is one comparison at alpha (its own question: "do these two builds
converge to the same image?"). A bisect decides each of its steps at alpha / steps (Bonferroni over the at most
``ceil(log2(builds)) + 2`` steps it can take), so the chance that it follows a difference that is not there is at
most alpha; a difference too small for the passes can be missed, so each step's evidence (the bias it rules out)
is part of the answer.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError
from ..jobs import releases
from ..jobs.job import RenderJob
from ..jobs.launch import blender_version, bpy_version
from .suite import Case, CaseResult, status_of

_FULL_VERSION = re.compile(r"^\d+\.\d+\.\d+$")


@dataclass(frozen=True)
class Build:
    """One build to render with: its label (a file name too), and how (neither: this process's bpy)."""

    label: str
    python: str | None = None
    blender: str | None = None


def build_of(spec: str) -> Build:
    """``current``, a full bpy release (its environment made if missing), or the path of a Blender binary or of a
    Python with bpy. Checked here, before anything renders."""
    if spec == "current":
        return Build("current")
    if _FULL_VERSION.match(spec):
        return Build(spec, python=str(releases.ensure(spec, say=lambda _line: None)))
    path = Path(spec)
    if not path.exists():
        raise BatchError(f"build {spec!r}: not `current`, a release such as 4.5.4, or an existing program")
    if path.name.startswith("python"):
        version = bpy_version(spec).split()[1]  # "bpy 4.5.4 (build ...)"
        return Build(f"bpy-{version}", python=spec)
    banner = blender_version(spec)  # "Blender 4.5.4 LTS"
    return Build("blender-" + "-".join(banner.split()[1:]), blender=spec)


def unique(builds: list[Build]) -> list[Build]:
    labels = [b.label for b in builds]
    twice = sorted({label for label in labels if labels.count(label) > 1})
    if twice:
        raise BatchError(f"build {twice[0]} is given twice")
    if len(builds) < 2:
        raise BatchError("give at least two builds to compare")
    return builds


def render_builds(job: RenderJob, builds: list[Build], passes: int, out: Path, progress_factory,
                  say=print, test_changes: dict | None = None, blocks: dict[str, int] | None = None,
                  ) -> dict[str, Path]:  # fmt: skip
    """Render `job` with each build on its own block of seeds (its position in `blocks`, default in `builds`)
    into ``out/<label>.npz`` (``<label>.test.npz`` with `test_changes`, the job's fields of a second run on the
    same seeds). A finished file is reused; a partial one resumed (its passes so far kept)."""
    from ..jobs.side import run_job

    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    blocks = blocks or {b.label: k for k, b in enumerate(builds)}
    for build in builds:
        index = blocks[build.label]
        runs = [("", {})] + ([(".test", test_changes)] if test_changes is not None else [])
        for suffix, changes in runs:
            path = out / f"{build.label}{suffix}.npz"
            # A file from an earlier run keeps its seeds (the builds' order may have changed since); the render
            # process checks that it is this job's, and `compare` refuses two files that share some seeds.
            start = min(wc.load_stats(path, pixels=False).seeds) if path.exists() else index * passes
            side = job.replace(out=str(path), seeds=tuple(range(start, start + passes)), blender=build.blender,
                               python=build.python, resume=path.exists(), **changes)  # fmt: skip
            say(f"{build.label}{suffix}: {passes} passes")
            run_job(side, progress_factory(passes), name=build.label)
            paths[build.label + suffix] = path
    return paths


@dataclass
class Pair:
    """One comparison of two statistics files: its verdict, sentence, whole-image difference and report."""

    reference: str
    test: str
    verdict: str
    sentence: str
    whole_image: dict | None
    ruled_out: float | None  # the bias ruled out in every finest tile (None: not bounded)
    folder: str
    seconds: float = 0.0

    def result(self, scene: str) -> CaseResult:
        """As a suite case's result (for JUnit): passed when the two converge to the same image."""
        case = Case(name=f"{self.reference} vs {self.test}", scene=scene)
        status = status_of(case, wc.Verdict(self.verdict))
        return CaseResult(case, "CPU", status, self.verdict, self.sentence, self.seconds, folder=self.folder)


def compare_pair(ref: Path, test: Path, out: Path, alpha: float, tolerance: float | None, labels) -> Pair:
    from ..present.pipeline import compare_files

    start = time.perf_counter()
    report = compare_files(str(ref), str(test), str(out), alpha=alpha, tolerance=tolerance)
    finest = report["outcome"]["scales"][0]
    return Pair(*labels, report["verdict"], report["sentence"], report["outcome"]["whole_image"],
                finest["ruled_out"], str(out), time.perf_counter() - start)  # fmt: skip


def matrix_pairs(labels: list[str], baseline: str) -> list[tuple[str, str]]:
    """Every adjacent pair in order, then the baseline against each build it is not adjacent to."""
    pairs = list(zip(labels, labels[1:], strict=False))
    for label in labels:
        if label != baseline and (baseline, label) not in pairs and (label, baseline) not in pairs:
            pairs.append((baseline, label))
    return pairs


def run_matrix(paths: dict[str, Path], labels: list[str], baseline: str, out: Path, alpha: float,
               tolerance: float | None) -> list[Pair]:  # fmt: skip
    pairs = []
    for a, b in matrix_pairs(labels, baseline):
        pairs.append(compare_pair(paths[a], paths[b], out / "pairs" / f"{a}__{b}", alpha, tolerance, (a, b)))
    return pairs


@dataclass
class Step:
    """One step of a bisect: the build looked at, the level of its decision, and its comparison."""

    build: str
    alpha: float
    pair: Pair


@dataclass
class Bisection:
    """What a bisect found: the first build that shows the difference (None: none does, or the first already
    does), and every step with its evidence."""

    first: str | None
    steps: list[Step] = field(default_factory=list)
    message: str = ""

    def to_json(self) -> dict:
        return {"first": self.first, "message": self.message, "steps": [dataclasses.asdict(s) for s in self.steps]}


def bisect(labels: list[str], shows: Callable[[str, float], Pair], alpha: float) -> Bisection:
    """The first of the ordered `labels` for which `shows(label, level)` is `biased`, given that the last one
    shows it and the first does not (both checked first), each step at level alpha / steps."""
    planned = math.ceil(math.log2(max(len(labels) - 1, 1))) + 2
    level = wc.bonferroni(alpha, planned)
    steps: list[Step] = []

    def step(label: str) -> bool:
        steps.append(Step(label, level, shows(label, level)))
        return steps[-1].pair.verdict == "biased"

    if not step(labels[-1]):
        return Bisection(None, steps, f"{labels[-1]} does not show the difference at alpha {level:.2g}: no bisect")
    if step(labels[0]):
        return Bisection(None, steps, f"{labels[0]} already shows the difference: it is older than every build given")
    good, bad = 0, len(labels) - 1
    while bad - good > 1:
        mid = (good + bad) // 2
        if step(labels[mid]):
            bad = mid
        else:
            good = mid
    return Bisection(
        labels[bad], steps, f"the difference appears in {labels[bad]} (not in {labels[good]}, the build before it)"
    )


def run_bisect(job: RenderJob, builds: list[Build], passes: int, out: Path, alpha: float, tolerance: float | None,
               progress_factory, say=print, changes: dict | None = None) -> Bisection:  # fmt: skip
    """Bisect `builds` (oldest first) for the first that shows a difference: with `changes` (fields of `job`: the
    change whose effect is bisected) within each build, `job` against `job` with the changes on the same seeds;
    without, each build against the first. Renders into ``out/renders``, each step's comparison into
    ``out/steps/<build>``."""
    labels = [b.label for b in builds]
    paths: dict[str, Path] = {}
    blocks = {b.label: k for k, b in enumerate(builds)}

    def shows(label: str, level: float) -> Pair:
        build = builds[labels.index(label)]
        first = [] if changes or label == labels[0] else [builds[0]]
        paths.update(render_builds(job, [build, *first], passes, out / "renders", progress_factory, say, changes,
                                   blocks))  # fmt: skip
        ref, test = (label, f"{label}.test") if changes else (labels[0], label)
        if not changes and label == labels[0]:  # the first against itself: nothing to compare
            return Pair(label, label, "no_evidence", "the first build is the reference", None, None, "")
        pair = compare_pair(paths[ref], paths[test], out / "steps" / label, level, tolerance, (ref, test))
        say(f"{label}: {pair.sentence}")
        return pair

    return bisect(labels, shows, alpha)


def write_json(path: Path, data) -> None:
    text = json.dumps(data, indent=2, allow_nan=False, default=str)
    wc.formats.atomic_write(path, lambda f: f.write(text.encode()))
