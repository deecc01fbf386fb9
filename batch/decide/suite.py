"""Statistical render regression suites: a TOML file of cases, references rendered once (``suite bless``), and
runs that decide each case against its reference with the render-until-decided engine (``suite run``), for CI.

A suite file::

    [suite]
    name = "my renderer"      # optional; default: the file's name
    alpha = 0.01              # the false-positive rate of each case's `biased`
    tolerance = "5%"          # the bias every case must be able to find to pass (default 1%; see below)

    [defaults]                # optional: any case key, for every case
    resolution = [64, 64]

    [[case]]
    name = "glossy"           # letters, digits, - _ .
    scene = "glossy_rough"    # a built-in scene, or
    # blend = "scenes/glossy.blend"   # a .blend file, relative to the suite file (blend_scene = "Scene"), or
    # command = "{python} render.py --seed {seed} --out {out} {set}"  # another renderer (batch.jobs.command),
    #                                                                 # run in the suite file's folder
    set = ["cycles.max_bounces=64"]   # overrides of this case, both sides
    resolution = [64, 64]
    spp = 1                   # samples per pass
    tile = 16
    passes = 64               # the reference's passes, and the most the test side renders
    seconds = 60              # optional: the most render seconds of the test side
    devices = ["CPU", "OPTIX"]
    tolerance = "2%"          # optional: the suite's for this case, and stop early at `equivalent` once every
                              # tile is bounded within it
    equivalence_tile = 64     # optional: ...every tile of this size (a multiple of `tile`; default `tile` itself)
    expect = "same"           # or "biased": a known difference, the case passes when it is found
    sampling_pattern = "TABULATED_SOBOL"
    test_sampling_pattern = "BLUE_NOISE"  # optional: the test side's pattern (a known difference between them)
    test_spp = 4              # optional: the test side's samples per pass
    why = "what the case exercises and why its size and budget suffice"

References live in a folder (``--refs``): ``<case>.npz`` (the statistics, with what rendered them) and
``<case>.json`` (when, how, on which seeds). A run's test side renders seeds after the reference's, so the two
sides never share a seed; it stops at `biased` (or `equivalent` with a tolerance) or at the budget, where its
verdict is `no evidence of bias` (`inconclusive` when too much of the image could not be tested).

A case that could not have failed does not pass: an expected-same case passes on `equivalent`, or on `no evidence
of bias` when the bias its tiles find with 80 % power (the median over its tiles) is at most its tolerance (the
case's, else the suite's, 1 % by default); otherwise it is `underpowered` ("not enough passes to rule out 1 %: 13.2 %
could hide in an 8x8 tile"), a failure like `inconclusive` (exit code 3).

Nothing here imports bpy: the renders run in their own processes through the render-job contract.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import importlib.util
import json
import os
import re
import shlex
import shutil
import time
import tomllib
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError, Exit, Undecided
from ..jobs import command as jobs_command
from ..jobs import options
from ..jobs import template as jobs_template
from ..jobs.distributed import cluster as side_cluster
from ..jobs.job import BUILTIN_SCENES, NO_GPU_MESSAGE, RenderJob, builtin_scene_id
from ..jobs.launch import blender_version, bpy_version, no_bpy
from ..jobs.protocol import FAILING, CaseStatus, verdict_status
from .check import run_check
from .check_job import CheckRequest, check_job

#: The suite that ships with the tool: one minimal scene per Cycles feature, and its references.
BUILTIN = Path(__file__).with_name("suites") / "builtin.toml"
BUILTIN_REFS = Path(__file__).with_name("suites") / "builtin-refs"

EXPECTATIONS = ("same", "biased")

#: The bias a passing case must be able to find, where neither the case nor the suite says: `check`'s default.
DEFAULT_TOLERANCE = options.default("tolerance", "suite")
DEFAULT_ALPHA = options.default("alpha", "suite")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
#: A case's options (`batch.jobs.options`: their keys, checks and defaults) and the fields of `Case` they fill.
_FIELDS = {"max_passes": "passes", "max_seconds": "seconds"}
_CASE_KEYS = {"name", "scene", "blend", "expect", "why", "planted", "command", *(o.key for o in options.CASE_OPTIONS)}


def _default(dest: str):
    return options.default(dest, "case")


@dataclass(frozen=True)
class Case:
    """One case of a suite (see the module docstring for the keys)."""

    name: str
    scene: str | None = None
    blend: str | None = None
    blend_scene: str | None = _default("blend_scene")
    overrides: tuple[str, ...] = _default("overrides")
    resolution: tuple[int, int] | None = _default("resolution")
    spp: int = _default("spp")
    tile: int = _default("tile")
    passes: int = _default("max_passes")
    seconds: float | None = _default("max_seconds")
    devices: tuple[str, ...] = _default("devices")
    tolerance: float | None = _default("tolerance")  # None: the suite's
    equivalence_tile: int | None = _default("equivalence_tile")  # the tile size `equivalent` claims (default: tile)
    pixel_variance: str = _default("pixel_variance")  # the pixel-variance test (welch_core.pixels)
    expect: str = "same"
    sampling_pattern: str | None = _default("sampling_pattern")
    test_sampling_pattern: str | None = None  # the test side's, where it differs from the reference's on purpose
    test_spp: int | None = None  # the same for the samples of a pass
    why: str = ""
    planted: str | None = None  # a change of the case's feature that it must find (documentation, benchmarks)
    command: str | None = None  # renders a pass into an EXR instead of Cycles (batch.jobs.command)
    folder: str | None = None  # the suite file's folder, where a command runs

    def job(self, out: str, seeds, device: str, blender: str | None, test: bool = False,
            python: str | None = None) -> RenderJob:  # fmt: skip
        """The render job of one side of this case (`test`: the test side), rendered with bpy, or with `blender`
        (a binary) or `python` (another release's bpy)."""
        # The fields of one name: the scene, its overrides, samples, pattern, image and tiles, the command.
        shared = {f.name: getattr(self, f.name) for f in dataclasses.fields(RenderJob) if hasattr(self, f.name)}
        if test:  # the test side's own samples and pattern, where the case gives them
            shared |= {"spp": self.test_spp or self.spp,
                       "sampling_pattern": self.test_sampling_pattern or self.sampling_pattern}  # fmt: skip
        made = {"out": out, "seeds": tuple(seeds), "device": device, "blender": blender, "python": python}
        folder = self.folder if self.command else None
        return RenderJob(**shared | made, checkpoint_every=max(self.passes, 1), command_dir=folder)


@dataclass(frozen=True)
class Suite:
    path: Path
    name: str
    alpha: float
    cases: tuple[Case, ...]
    tolerance: float = DEFAULT_TOLERANCE  # the bias a case without its own tolerance must be able to find

    def select(self, patterns: list[str] | None) -> list[Case]:
        """The cases whose names match any of the shell patterns (all without patterns)."""
        if not patterns:
            return list(self.cases)
        chosen = [c for c in self.cases if any(fnmatch.fnmatchcase(c.name, p) for p in patterns)]
        if not chosen:
            raise BatchError(f"--filter {' '.join(patterns)} matches no case of {self.path}")
        return chosen


def suite_path(name: str) -> Path:
    """``builtin`` or a path."""
    return BUILTIN if name == "builtin" else Path(name)


def load_suite(name: str) -> Suite:
    """Read and check a whole suite file before anything renders: every problem (unknown keys or scenes, bad
    values or overrides, names used twice or unsafe as file names) is collected, and raised as one BatchError
    that lists them all, each naming the file and the case."""
    path = suite_path(name)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BatchError(f"{path}: no such suite file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise BatchError(f"{path}: not readable TOML: {exc}") from None
    problems: list[str] = []
    unknown = sorted(set(data) - {"suite", "defaults", "case"})
    if unknown:
        problems.append(f"unknown table [{unknown[0]}] (a suite has [suite], [defaults] and [[case]])")
    header = data.get("suite", {})
    if not isinstance(header, dict):
        header, _ = {}, problems.append("[suite] must be a table")
    known = {"name", *(option.key for option in options.SUITE_OPTIONS)}
    if set(header) - known:
        problems.append(f"unknown key {sorted(set(header) - known)[0]!r} in [suite]")
    declared = options.from_suite_table(header, problems)  # alpha and tolerance, checked as a case's
    alpha = declared.get("alpha", DEFAULT_ALPHA)
    tolerance = declared.get("tolerance", DEFAULT_TOLERANCE)
    suite_name = header.get("name", path.stem)
    try:
        suite_name = options.text("[suite] name", suite_name)
    except BatchError as exc:
        problems.append(str(exc))
    defaults = data.get("defaults", {})
    raw_cases = data.get("case", [])
    if not isinstance(defaults, dict):
        defaults, _ = {}, problems.append("[defaults] must be a table")
    if not isinstance(raw_cases, list) or not raw_cases or not all(isinstance(c, dict) for c in raw_cases):
        raise BatchError(f"{path}: " + "; ".join([*problems, "no [[case]] in the suite"]))
    cases, seen = [], {}
    for index, raw in enumerate(raw_cases):
        entry = {**defaults, **raw}
        label = f"case {entry.get('name', index + 1)!r}"
        name = entry.get("name")
        if isinstance(name, str) and name.lower() in seen:  # a case-insensitive file system would mix the two
            problems.append(f"{label}: the name is used twice (also case {seen[name.lower()]!r})")
        elif isinstance(name, str):
            seen[name.lower()] = name
        case = _case(entry, label, path.parent, problems)
        if case is not None:
            cases.append(case)
    if problems:
        count = f"{len(problems)} problems" if len(problems) > 1 else "a problem"
        raise BatchError(f"{path}: {count}, nothing rendered: " + "; ".join(problems))
    return Suite(path, str(suite_name), alpha, tuple(cases), tolerance)


def _case(entry: dict, label: str, folder: Path, problems: list[str]) -> Case | None:
    """The case `entry` describes, or None with its problems added to `problems`."""
    found = len(problems)
    unknown = sorted(set(entry) - _CASE_KEYS)
    if unknown:
        problems.append(f"{label}: unknown key {', '.join(repr(k) for k in unknown)}")
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME.fullmatch(name) or len(name) > 100:
        problems.append(f"{label}: 'name' must be letters, digits, '-', '_' or '.' (a file name), got {name!r}")
    if sum(key in entry for key in ("scene", "blend", "command")) != 1:
        problems.append(f"{label}: give 'scene' (a built-in scene), 'blend' (a .blend file) or 'command' (another "
                        "renderer), one of them")  # fmt: skip
    command = entry.get("command")
    if command is not None:
        try:
            jobs_template.words(options.text("'command'", command))
        except BatchError as exc:
            problems.append(f"{label}: {exc}")
    scene, blend = entry.get("scene"), None
    if scene is not None and scene not in BUILTIN_SCENES:
        problems.append(f"{label}: 'scene' {scene!r} is not a built-in scene (one of {', '.join(BUILTIN_SCENES)})")
    if "blend" in entry:
        if not isinstance(entry["blend"], str):
            problems.append(f"{label}: 'blend' must be a path, got {entry['blend']!r}")
        else:
            blend = str((folder / entry["blend"]).resolve())
            if not Path(blend).is_file():
                problems.append(f"{label}: blend file {blend} does not exist")
    values = options.from_mapping(entry, label, problems)
    expect = entry.get("expect", "same")
    if expect not in EXPECTATIONS:
        problems.append(f"{label}: 'expect' must be 'same' or 'biased', got {expect!r}")
    texts = {}
    for key in ("why", "planted"):
        if key in entry and not isinstance(entry[key], str):
            problems.append(f"{label}: {key!r} must be text, got {entry[key]!r}")
        texts[key] = entry.get(key) if isinstance(entry.get(key), str) else None
    claim = values.get("equivalence_tile")
    tile = values.get("tile", _default("tile"))
    if claim is not None and (claim < tile or claim % tile):
        problems.append(f"{label}: 'equivalence_tile' must be a multiple of the case's tile {tile}, got {claim!r}")
    elif claim is not None and values.get("tolerance") is None:
        problems.append(f"{label}: 'equivalence_tile' needs a 'tolerance'")
    if len(problems) > found:
        return None
    case = Case(
        name=name,
        scene=scene,
        blend=blend,
        expect=expect,
        why=texts["why"] or "",
        planted=texts["planted"],
        command=command,
        folder=str(folder.resolve()),
        **{_FIELDS.get(dest, dest): value for dest, value in values.items()},
    )
    for device in case.devices:  # what a render job refuses (a command with a Cycles setting, say), named now
        try:
            case.job("reference.npz", [0], device, None)
            case.job("test.npz", [1], device, None, test=True)
        except BatchError as exc:
            problems.append(f"{label}: {exc}")
            return None
    return case


# -- references ---------------------------------------------------------------------------------------------------


def reference_path(refs: Path, case: Case) -> Path:
    return refs / f"{case.name}.npz"


def default_refs(suite: Suite) -> Path | None:
    """The shipped references of the built-in suite; None for others (``--refs`` is required)."""
    return BUILTIN_REFS if suite.path == BUILTIN else None


@dataclass
class Blessed:
    """What ``suite bless`` did with one case."""

    case: str
    status: str  # "blessed", "re-blessed", "refused", "forced", "kept"
    message: str
    report: str | None = None


def require_build(cases: list[Case], blender: str | None, python: str | None) -> None:
    """One BatchError before anything renders, not one error per case, when what renders the Cycles cases in this
    process can't: a `blender` that is not a Blender, a `python` without bpy, or neither and no bpy here."""
    if all(case.command is not None for case in cases):
        return  # other renderers' commands only
    if blender:
        blender_version(blender)
    elif python:
        bpy_version(python)
    elif importlib.util.find_spec("bpy") is None:
        raise BatchError(no_bpy())


def bless(suite: Suite, cases: list[Case], refs: Path, progress_factory, force: bool = False, blender=None,
          device: str | None = None, say=print, missing: bool = False, python=None) -> list[Blessed]:  # fmt: skip
    """Render the reference of each case into `refs`. A case that has one already gets a new render on new
    seeds, compared with the stored one: where they differ significantly the old one stays (unless `force`), and
    the comparison's report is kept next to it: a silent re-bless is how thresholds creep. With `missing`, only
    the cases without a reference are rendered (the others are "kept")."""
    from ..jobs.side import run_job

    require_build([c for c in cases if not (missing and reference_path(refs, c).exists())], blender, python)
    refs.mkdir(parents=True, exist_ok=True)
    done = []
    for number, case in enumerate(cases, 1):
        target = reference_path(refs, case)
        if missing and target.exists():
            done.append(Blessed(case.name, "kept", f"{target} exists"))
            continue
        old = wc.load_stats(target) if target.exists() else None
        first = 0 if old is None else max(old.seeds) + 1
        fresh = refs / f".{case.name}.new.npz"
        fresh.unlink(missing_ok=True)
        chosen = device or case.devices[0]
        say(f"suite bless: {number}/{len(cases)} {case.name} ({case.passes} passes on {chosen})")
        job = case.job(str(fresh), range(first, first + case.passes), chosen, blender, python=python)
        start = time.perf_counter()
        run_job(job, progress_factory(case.passes))
        seconds = time.perf_counter() - start
        new = wc.load_stats(fresh)
        status, message, report = "blessed", f"{new.n} passes in {seconds:.1f} s", None
        if old is not None:
            differs, found, report = _against_stored(suite, refs / f"{case.name}.rebless", old, new)
            if differs and not force:
                fresh.unlink()
                done.append(Blessed(case.name, "refused", found, report))
                continue
            status = "forced" if differs else "re-blessed"
            message = f"{message}; {found}"
        os.replace(fresh, target)
        _write_provenance(refs, case, new, job, seconds, status)
        done.append(Blessed(case.name, status, message, report))
    return done


def _against_stored(suite: Suite, report: Path, old: wc.TileStats, new: wc.TileStats):
    """(whether the new reference contradicts the stored one, what was found, the comparison's report or None)."""
    from ..present.pipeline import present
    from ..present.summary import verdict_line

    try:
        result = wc.compare(old, new, suite.alpha, "welch")
    except wc.WelchInputError as exc:  # another size or tile: the case changed, nothing to compare
        return True, f"the stored reference can't be compared: {exc}", None
    summary = present(report, result, old, new, names=("stored reference", "new render"))
    line = verdict_line(summary)
    if result.verdict == wc.Verdict.BIASED:
        return True, f"the new render differs from the stored one: {line}", str(report)
    return False, f"against the stored one: {line}", str(report)


def _write_provenance(refs: Path, case: Case, stats: wc.TileStats, job: RenderJob, seconds: float, status: str):
    info = stats.info
    record = {
        "case": case.name,
        "blessed": datetime.now(UTC).isoformat(timespec="seconds"),
        "status": status,
        "renderer": info.renderer,
        "blender_version": info.renderer_version,
        "build_hash": info.build_hash,
        "device": info.device,
        "sampling_pattern": info.sampling_pattern,
        "seeds": [min(stats.seeds), max(stats.seeds) + 1],
        "passes": stats.n,
        "render_seconds": round(seconds, 3),
        "command": ["python", "-m", "batch", "render", *job.replace(out=f"{case.name}.npz").to_argv()],
    }
    text = json.dumps(record, indent=2)
    wc.formats.atomic_write(refs / f"{case.name}.json", lambda f: f.write(text.encode()))


# -- runs ---------------------------------------------------------------------------------------------------------


@dataclass
class CaseResult:
    """One case on one device."""

    case: Case
    device: str
    status: CaseStatus
    verdict: str | None = None
    message: str = ""
    seconds: float = 0.0
    passes: int = 0
    folder: str | None = None
    summary: dict | None = None

    @property
    def label(self) -> str:
        return f"{self.case.name} [{self.device}]"


def status_of(
    case: Case, verdict: wc.Verdict, detectable: float | None = None, tolerance: float | None = None
) -> CaseStatus:
    """Passed when the verdict is what the case expects and the case could have failed: a case expected to be
    `biased` fails when not found; given a `tolerance`, `no evidence of bias` passes only where `detectable` (the
    bias found with 80 % power, `Outcome.min_detectable`) is at most it, else the case is `underpowered`."""
    status = verdict_status(verdict)
    if case.expect == "biased" and status != CaseStatus.INCONCLUSIVE:
        return CaseStatus.PASSED if verdict == wc.Verdict.BIASED else CaseStatus.FAILED
    if (
        status == CaseStatus.PASSED
        and tolerance is not None
        and verdict == wc.Verdict.NO_EVIDENCE
        and (detectable is None or detectable > tolerance)
    ):
        return CaseStatus.UNDERPOWERED
    return status


def underpowered_text(detectable: float | None, tolerance: float, tile: int) -> str:
    """Why a case that found nothing does not pass, in a line."""
    hides = f"{detectable * 100:.1f} % could hide in a {tile}x{tile} tile" if detectable is not None else (
        "no tile was bounded")  # fmt: skip
    return f"not enough passes to rule out {tolerance * 100:g} %: {hides}"


def exit_code(outcomes: list[CaseResult]) -> int:
    """1 when a case is `biased` where it should not be (1 means biased and nothing else), else 2 when a case could
    not run, or when nothing ran at all (every case skipped: no device, say), else 3 when a case is inconclusive,
    underpowered or an expected difference was not found (the suite can't confirm every case), else 0 (skipped
    cases beside passed ones do not count)."""
    if any(o.status == CaseStatus.FAILED and o.verdict == wc.Verdict.BIASED for o in outcomes):
        return Exit.BIASED
    if any(o.status == CaseStatus.ERROR for o in outcomes) or all(o.status == CaseStatus.SKIPPED for o in outcomes):
        return Exit.USAGE
    if any(o.status in FAILING for o in outcomes):
        return Exit.INCONCLUSIVE
    return Exit.OK


def run_suite(suite: Suite, cases: list[Case], refs: Path, out: Path, progress_factory, blender=None,
              device: str | None = None, overrides: tuple[str, ...] = (), resume: bool = False,
              say=print, seed_offset: int = 0, cluster=(None, None), python=None) -> list[CaseResult]:  # fmt: skip
    """Decide every case on every device (its own, or `device` for all) against its reference in `refs`;
    `overrides` go to every case's test side (a planted change). The test side's seeds start `seed_offset`
    after the reference's last one: the same run gives the same answer, another offset draws new passes.
    `cluster` is (local workers, scheduler address) to render the passes on Dask (one local cluster for all
    cases), or (None, None)."""
    missing = [c.name for c in cases if not reference_path(refs, c).exists()]
    if missing:
        raise BatchError(f"no reference for {', '.join(missing)} in {refs}: run `suite bless` first")
    if not any(cluster):  # rendered here (a cluster's workers have what they have)
        require_build(cases, blender, python)
    runs = [(case, d) for case in cases for d in ((device,) if device else case.devices)]
    if not resume:
        taken = [str(out / c.name / d) for c, d in runs if (out / c.name / d).exists()]
        if taken:
            raise BatchError(f"{taken[0]} already exists: pass --resume to continue the run, or another --out")
    workers, scheduler = cluster
    with side_cluster(workers, scheduler) as where:  # one cluster for every case
        outcomes = []
        for number, (case, dev) in enumerate(runs, 1):
            say(f"suite run: {number}/{len(runs)} {case.name} on {dev}")
            outcome = _run_case(
                suite, case, dev, refs, out, progress_factory, (blender, python), overrides, resume, seed_offset, where
            )
            say(f"  {outcome.status}: {outcome.message}")
            outcomes.append(outcome)
    return outcomes


def _run_case(
    suite, case, device, refs, out, progress_factory, build, overrides, resume, seed_offset, where
) -> CaseResult:
    folder = out / case.name / device
    try:
        reference = wc.load_stats(reference_path(refs, case), pixels=False)
        problem = reference_problem(case, reference, refs)
    except wc.WelchInputError as exc:  # truncated, foreign: this case can't run, the others can
        problem = str(exc)
    if problem:
        advice = f"to render it anew: {bless_command(suite, case, refs)}"
        message = f"the reference {reference_path(refs, case)}: {problem} ({advice})"
        return CaseResult(case, device, CaseStatus.ERROR, message=message)
    start = time.perf_counter()
    resume = resume and (folder / "check.json").exists()  # a case the interrupted run had not started is new
    try:
        request = case_request(suite, case, device, reference_path(refs, case), folder, build, overrides,
                               seed_offset, resume)  # fmt: skip
        job = check_job(request)
        verdict, summary = run_check(job, progress_factory(case.passes), where)
    except Undecided as exc:  # its time budget ended the first passes: nothing to look at
        return CaseResult(case, device, CaseStatus.INCONCLUSIVE, wc.Verdict.INCONCLUSIVE.label, str(exc),
                          seconds=time.perf_counter() - start)  # fmt: skip
    except BatchError as exc:
        status = CaseStatus.SKIPPED if NO_GPU_MESSAGE in str(exc) else CaseStatus.ERROR
        if status == CaseStatus.SKIPPED:
            shutil.rmtree(folder, ignore_errors=True)
        return CaseResult(case, device, status, message=str(exc), seconds=time.perf_counter() - start)
    check = summary["check"]
    message = summary["sentence"]
    tolerance = case.tolerance if case.tolerance is not None else suite.tolerance
    detectable = summary["outcome"]["min_detectable"]
    status = status_of(case, verdict, detectable, tolerance)
    if case.expect == "biased":
        message += " (expected: biased)"
    if status == CaseStatus.UNDERPOWERED:
        message = f"{underpowered_text(detectable, tolerance, case.tile)}; {message}"
    if check.get("ended_pass"):
        message += f" ({check['ended_pass']})"
    return CaseResult(case, device, status, verdict.label, message,
                   seconds=check["looks"][-1]["seconds"] if check["looks"] else 0.0, passes=check["passes"],
                   folder=str(folder), summary=summary)  # fmt: skip


def case_request(suite: Suite, case: Case, device: str, reference: Path, folder: Path, build, overrides=(),
                 seed_offset: int = 0, resume: bool = False) -> CheckRequest:  # fmt: skip
    """The check of `case` on `device` against its blessed `reference` (`batch.decide.check_job`): the case's
    settings on both sides, the run's build (a Blender binary or a Python with bpy; None, None: this bpy) and its
    `overrides` (``suite run --set``) on the test side. The test side renders on the seeds after the reference's;
    `passes` bounds it under a time budget too: past the reference's passes the two means differ in how often
    they catch a rare bright path, which Welch's t does not forgive when one side has few passes."""
    blender, python = build
    made = {
        "out": str(folder),
        "reference_stats": str(reference),
        "reference_overrides": case.overrides,
        "overrides": case.overrides + tuple(overrides),
        "device": device,
        "test_blender": blender,
        "test_python": python,
        "pass_command": case.command,
        "command_dir": case.folder,
        "max_passes": case.passes,
        "max_seconds": case.seconds,
        "alpha": suite.alpha,
        "seed_offset": seed_offset,
        "resume": resume,
    }
    # The fields of one name: the scene, its samples, pattern, image and tiles, the claim and the pixel test.
    shared = {f.name: getattr(case, f.name) for f in dataclasses.fields(CheckRequest) if hasattr(case, f.name)}
    return CheckRequest(**shared | made)


def reference_problem(case: Case, reference: wc.TileStats, refs: Path) -> str | None:
    """Why `reference` is not this case's (another case's file copied or swapped in, a scene or a .blend that
    changed since it was blessed), or None. A reference is known by what rendered it: the scene and its content,
    the samples per pass, the overrides, the image and tile size, and the case named in its provenance file."""
    info, expected = reference.info, []
    if case.scene is not None and not info.scene_id.startswith(f"builtin:{case.scene}:"):
        expected.append(f"the built-in scene {case.scene!r}, it holds {info.scene or info.scene_id!r}")
    elif case.scene is not None and info.scene_id != builtin_scene_id(case.scene):
        expected.append(f"the built-in scene {case.scene!r} as it is built now ({builtin_scene_id(case.scene)}), it "
                        f"holds {info.scene_id}")  # fmt: skip
    if case.command is not None and info.scene_id != jobs_command.scene_id(case.command):
        expected.append(f"the command {case.command!r}, it holds {info.scene!r}")
    if case.blend is not None and info.scene_id != f"sha256:{_sha256(case.blend)}":
        expected.append(f"{case.blend} as it is now (the file changed since, or it is another scene's)")
    if info.spp != case.spp:
        expected.append(f"{case.spp} samples per pass, it holds {info.spp}")
    if tuple(info.overrides) != tuple(case.overrides):
        expected.append(f"the overrides {list(case.overrides)}, it holds {list(info.overrides)}")
    if reference.tile != case.tile or case.resolution and (reference.width, reference.height) != case.resolution:
        expected.append(f"{case.tile}-px tiles{' of ' + 'x'.join(map(str, case.resolution)) if case.resolution else ''}"
                        f", it holds {reference.tile}-px tiles of {reference.width}x{reference.height}")  # fmt: skip
    provenance = refs / f"{case.name}.json"
    if provenance.exists():
        try:
            named = json.loads(provenance.read_text()).get("case")
        except (OSError, ValueError):
            named = None
        if named not in (None, case.name):
            expected.append(f"case {case.name!r}, its provenance names case {named!r}")
    if not expected:
        return None
    return "not this case's reference: it should be of " + "; of ".join(expected)


def bless_command(suite: Suite, case: Case, refs: Path) -> str:
    """The command that renders `case`'s reference anew into `refs`, replacing the one there, for a shell."""
    name = "builtin" if suite.path == BUILTIN else str(suite.path)
    return shlex.join(["welch-bias", "suite", "bless", name, "--refs", str(refs), "--filter", case.name, "--force"])


def _sha256(path: str) -> str:
    import hashlib

    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


# -- outputs ------------------------------------------------------------------------------------------------------


def write_outputs(suite: Suite, outcomes: list[CaseResult], out: Path, refs: Path) -> dict:
    """``summary.json``, ``junit.xml`` and ``index.html`` (the dashboard) in `out`; returns the summary."""
    from ..present.dashboard import write_dashboard
    from ..present.junit import junit_xml

    out.mkdir(parents=True, exist_ok=True)
    summary = {
        "suite": suite.name,
        "file": str(suite.path),
        "refs": str(refs),
        "alpha": suite.alpha,
        "exit_code": exit_code(outcomes),
        "counts": {s: sum(o.status == s for o in outcomes) for s in CaseStatus},  # fmt: skip
        "cases": [_outcome_record(o, out) for o in outcomes],
    }
    text = json.dumps(summary, indent=2, allow_nan=False)
    wc.formats.atomic_write(out / "summary.json", lambda f: f.write(text.encode()))
    xml = junit_xml(suite.name, outcomes)
    wc.formats.atomic_write(out / "junit.xml", lambda f: f.write(xml))
    write_dashboard(out / "index.html", summary, outcomes, [reference_path(refs, o.case) for o in outcomes])
    return summary


def _outcome_record(o: CaseResult, out: Path) -> dict:
    outcome = o.summary["outcome"] if o.summary else None
    return {
        "case": o.case.name,
        "device": o.device,
        "status": o.status,
        "verdict": o.verdict,
        "expect": o.case.expect,
        "message": o.message,
        "passes": o.passes,
        "seconds": round(o.seconds, 3),
        "report": os.path.relpath(Path(o.folder) / "report.html", out) if o.folder else None,
        "whole_image": outcome["whole_image"] if outcome else None,
        "largest": outcome["largest"] if outcome else None,
        "most_significant": outcome["most_significant"] if outcome else None,
    }
