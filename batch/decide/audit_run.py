"""Running an audit (`batch.decide.audit` plans it): every cell a `check`, every `biased` one confirmed, every
confirmed difference explained, each cell recorded as it ends so that a second run reuses it.

A cell (one change on one scene, in ``<out>/cells/<change>/<scene>/``):

1. ``first/``: `check` of the change against its default at the audit's level (alpha / K), paired (the same seeds
   on both sides; the A/A row on disjoint seeds), its pixel-variance test where the passes allow it.
2. ``confirm/``, where the first said `biased`: the same check on fresh seeds (the next block of the budget's
   seeds) with the tile sums alone (``--pixel-variance off``: no assumption about pixels), rendering the light
   components too (``--lobes``: which one carries the difference). The cell is `biased` only where both are.
3. For a confirmed change documented to change only the noise: ``explain/``, the change with the biased-by-design
   settings off on both sides (`batch.decide.audit.UNBIASED_OVERRIDES`; a built-in scene has them off already), on
   the seeds after; and, where releases are given, ``bisect/``: the first of them that shows it
   (`batch.decide.matrix.run_bisect`, within each release).

The record of every cell goes into ``<out>/audit.json`` as it ends; an interrupted cell's checks are resumed where
they stopped. Nothing here imports bpy.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shlex
import shutil
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError, Exit, Undecided
from ..jobs import protocol
from ..jobs.distributed import cluster as side_cluster
from ..jobs.job import NO_GPU_MESSAGE, RenderJob
from ..present import fmt
from ..present.progress import Progress
from . import audit as plans
from .audit import LOBES, UNBIASED_OVERRIDES, AuditPlan, AuditSpec, Cell
from .check import run_check
from .check_job import CheckRequest, check_job

STATE_FILE = "audit.json"
STATE_VERSION = 1

#: A cell's status: confirmed `biased`, `biased` at first but not on fresh seeds, `equivalent` (every pass
#: bit-identical on both sides counts only from `welch_core.identical_passes` passes: fewer identical ones are
#: `undecided`, as `check` says), neither (`undecided`; also a cell whose time budget ended before two passes a
#: side), a setting the release lacks, or a cell that could not run.
STATUSES = ("biased", "unconfirmed", "equivalent", "undecided", "not_applicable", "error")


@dataclass
class CellResult:
    """What an audit found in one cell: its `status` (`STATUSES`), a line of words, the wall seconds it took, and
    the record of each check it ran (`check_record`): the first, its confirmation, the explanation with the
    biased-by-design settings off, and the bisect across releases (`batch.decide.matrix.Bisection.to_json`)."""

    cell: Cell
    status: str
    message: str = ""
    seconds: float = 0.0
    first: dict | None = None
    confirm: dict | None = None
    explain: dict | None = None
    bisect: dict | None = None
    command: str | None = None  # the command that reproduces a confirmed difference (`check_command`)
    reused: bool = False

    @property
    def finding(self) -> bool:
        """A confirmed difference of a change documented to change only the noise, larger than float rounding (a
        rounding-level one is listed apart: Cycles 4.5.4 renders the same passes twice with such differences)."""
        return self.status == "biased" and not self.cell.change.control and not self.rounding

    @property
    def rounding(self) -> bool:
        """A confirmed difference no larger than float rounding in any tile its checks estimate (`rounding_only`)."""
        return self.status == "biased" and rounding_only(self.first, self.confirm)

    @property
    def found(self) -> bool:
        """A control found: biased by design and confirmed so, beyond float rounding (a control confirmed only at
        the scale of rounding is one its scene does not exercise: the scene's settings changed, not its light)."""
        return self.status == "biased" and self.cell.change.control and not self.rounding

    def to_json(self) -> dict:
        return {
            "change": self.cell.change.name,
            "scene": self.cell.scene.label,
            "status": self.status,
            "documented": self.cell.change.documented,
            "message": self.message,
            "seconds": round(self.seconds, 3),
            "first": self.first,
            "confirm": self.confirm,
            "explain": self.explain,
            "bisect": self.bisect,
            "command": self.command,
            "rounding": self.rounding,
        }

    @classmethod
    def from_json(cls, cell: Cell, record: dict) -> CellResult:
        """A recorded cell, its status and sentence said again from its checks' records (as this version of the
        tool says them: an earlier one called too few identical passes `identical`)."""
        keys = ("status", "message", "seconds", "first", "confirm", "explain", "bisect", "command")
        result = cls(cell, reused=True, **{k: record.get(k) for k in keys})
        if result.first is not None and result.status in ("biased", "unconfirmed", "equivalent", "identical",
                                                           "undecided"):  # fmt: skip
            result.status = status_of(result.first, result.confirm)
            result.message = cell_sentence(cell, result.status, result.first, result.confirm)
        return result


def check_record(summary: dict, folder: Path, out: Path) -> dict:
    """What the audit keeps of one check's report.json: its verdict and sentence, the whole image's and the largest
    tile's difference, the claim (tolerance and tile size) of an `equivalent`, the bias ruled out at the finest
    bounded size, the passes and render seconds, the seeds, the light components' attribution, the report's path
    relative to the audit's folder."""
    outcome, check = summary["outcome"], summary.get("check") or {}
    bounded = [s for s in outcome.get("scales", []) if s.get("ruled_out") is not None]
    looks = check.get("looks") or []
    layers = summary.get("layers")
    return {
        "verdict": summary["verdict"],
        "sentence": summary["sentence"],
        "alpha": summary["alpha"],
        "p_value": looks[-1]["p_value"] if looks else summary["p_value"],  # a check's p is its last look's
        "whole_image": outcome.get("whole_image"),
        "largest": outcome.get("largest"),
        "most_significant": outcome.get("most_significant"),
        "claim_tile": outcome.get("claim_tile"),
        "identical": bool(outcome.get("identical")),
        "identical_needed": outcome.get("identical_needed"),
        "reason": outcome.get("reason"),
        "tolerance": outcome.get("tolerance"),
        "ruled_out": {"tile": bounded[0]["tile"], "bias": bounded[0]["ruled_out"]} if bounded else None,
        "passes": check.get("passes", summary.get("n_test")),
        "render_seconds": looks[-1]["seconds"] if looks else 0.0,
        "ended_pass": check.get("ended_pass"),
        "paired": check.get("paired"),
        "seeds": [summary["reference"]["seeds"], summary["test_run"]["seeds"]],
        "renderer": summary["test_run"]["info"].get("renderer_version"),
        "build": summary["test_run"]["info"].get("build_hash"),
        "layers": {"explained_by": layers["explained_by"], "explanation": layers["explanation"]} if layers else None,
        "report": os.path.relpath(folder / "report.html", out),
    }


def status_of(first: dict | None, confirm: dict | None) -> str:
    """A cell's status from its first check and its confirmation (both records of `check_record`). Identical
    passes are `equivalent` only where the check says so (from `identical_needed` passes on): fewer do not rule out
    a change that alters one pass in ten, and the cell is `undecided`."""
    if first is None:
        return "error"
    if first["verdict"] == "biased":
        return "biased" if confirm is not None and confirm["verdict"] == "biased" else "unconfirmed"
    if first["verdict"] == "equivalent":
        return "equivalent"
    return "undecided"


#: A relative difference below this wherever a check estimates one is the size of float rounding
#: (`welch_core.tile_test.ROUNDING`), not a difference of the light. Paired passes that are bit-identical but for
#: rounding can still make a test see one where the rounding has a sign: Cycles 4.5.4 renders the same scene, seeds
#: and settings twice with tile sums that differ in their last bits (also with one thread; 5.2.3 renders them
#: bit-identically), and its audit confirmed 15 such cells. They are listed apart (`summary_of`'s ``rounding``),
#: not as findings.
ROUNDING = wc.tile_test.ROUNDING


def rounding_only(*records: dict | None) -> bool:
    """Whether every difference the checks' records estimate (the whole image's, the largest tile's, the most
    significant one's) is below `ROUNDING` in size."""
    found = [r.get(key) for r in records if r for key in ("whole_image", "largest", "most_significant")]
    sizes = [abs(d["estimate"]) for d in found if d and d.get("estimate") is not None]
    return bool(sizes) and max(sizes) < ROUNDING


def rounding_text(*records: dict | None) -> str:
    """The size of a rounding-level difference, in words."""
    found = [r.get(key) for r in records if r for key in ("whole_image", "largest", "most_significant")]
    size = max(abs(d["estimate"]) for d in found if d and d.get("estimate") is not None)
    return (f"the largest difference estimated in any tile is {size:.1e} relative (below {ROUNDING:g}, the size of "
            "float rounding): the passes differ in their rounding, not in their light")  # fmt: skip


def identical_needed(record: dict) -> int:
    """The identical passes a side that rule out, at the record's level, a change altering one pass in ten
    (`welch_core.identical_passes`; the record's own where it has it)."""
    return record.get("identical_needed") or wc.identical_passes(record["alpha"])


def cut_short(record: dict | None, floor: int | None) -> bool:
    """Whether a check ended undecided with fewer passes a side than the audit's floor now asks (a time budget
    that ended it before a floor existed, or a renderer that hung in the floor's passes)."""
    return record is not None and floor is not None and record["verdict"] == "inconclusive" and (
        record["passes"] or 0) < floor  # fmt: skip


# -- the checks of a cell --------------------------------------------------------------------------------------------

#: The roles of a cell's checks, and which block of seeds (of the budget's size) each renders.
ROLES = {"first": 0, "confirm": 1, "explain": 2}


def cell_request(plan: AuditPlan, cell: Cell, role: str, folder: Path) -> CheckRequest:
    """The `check` of one role of a cell (`ROLES`): the change against its default at the audit's level, each
    side's overrides set explicitly; the confirmation with the tile sums alone and the light components, the
    explanation with the biased-by-design settings off on both sides; each on its own block of seeds."""
    spec, change, scene = plan.spec, cell.change, cell.scene
    reference, test = change.sides(UNBIASED_OVERRIDES if role == "explain" else ())
    return CheckRequest(
        out=str(folder),
        blend=scene.blend,
        scene=scene.scene,
        reference_overrides=reference,  # its default, set explicitly (``check`` gives its reference none)
        overrides=test,
        spp=change.samples,
        tile=spec.tile,
        resolution=spec.resolution,
        sampling_pattern=change.pattern,
        lobes=LOBES if role == "confirm" else (),
        test_device=change.test_device,
        test_sampling_pattern=change.test_pattern,
        blender=spec.build.blender,
        python=spec.build.python,
        alpha=plan.level,
        tolerance=spec.tolerance,
        pixel_variance="off" if role == "confirm" else "auto",
        unpaired=change.aa,
        seed_offset=spec.seed_offset + ROLES[role] * spec.max_passes,
        max_passes=spec.max_passes,
        max_seconds=spec.max_seconds,
        min_passes=spec.floor,
    )


def cell_job(plan: AuditPlan, cell: Cell, role: str, folder: Path, resume: bool = False,
             workers: int | None = None, scheduler: str | None = None):  # fmt: skip
    """The check of one role of a cell (`cell_request`), resumed or on a cluster where asked."""
    request = cell_request(plan, cell, role, folder)
    return check_job(dataclasses.replace(request, resume=resume, workers=workers, scheduler=scheduler))


def check_command(plan: AuditPlan, cell: Cell, role: str, out: Path) -> str:
    """The ``check`` command line that renders the check of a cell's `role` again (the same seeds, level and
    budget) into `out`. The reference side of ``check`` takes no overrides: a scene file must hold the reference
    side's values itself (a built-in scene does), which the line then says. A release's bpy (``--release``) is
    named by the command that prints its Python (``welch-bias bpy VERSION``), not by this machine's path."""
    request = cell_request(plan, cell, role, out)
    release = is_release(plan.spec.build)
    if release:
        request = dataclasses.replace(request, python=PYTHON_OF_RELEASE)
    line = shlex.join(["welch-bias", "check", *request.to_argv()])
    if release:
        line = line.replace(PYTHON_OF_RELEASE, f'"$(welch-bias bpy {plan.spec.build.label})"')
    if cell.scene.blend and request.reference_overrides:
        line += f"  (with {', '.join(request.reference_overrides)} in the scene file itself)"
    return line


#: Where `check_command` names a release's Python by the command that prints it.
PYTHON_OF_RELEASE = "PYTHON_OF_RELEASE"


def is_release(build) -> bool:
    """Whether `build` is a cached release's bpy (``--release VERSION``: ``python -m batch bpy VERSION`` made it)."""
    from ..jobs import releases

    if build.python is None:
        return False
    return str(build.python) == str(releases.python_of(releases.cache_folder() / build.label))


def bisect_job(plan: AuditPlan, cell: Cell) -> tuple[RenderJob, dict]:
    """The reference job of a cell and the changes of its test side, for `batch.decide.matrix.run_bisect`."""
    spec, change, scene = plan.spec, cell.change, cell.scene
    reference, test = change.sides()
    job = RenderJob(out="x.npz", seeds=(0,), spp=change.samples, blend=scene.blend, scene=scene.scene,
                    tile=spec.tile, resolution=spec.resolution, sampling_pattern=change.pattern,
                    overrides=reference)  # fmt: skip
    changes = {"overrides": test}
    if change.test_pattern:
        changes["sampling_pattern"] = change.test_pattern
    if change.test_device:
        changes["device"] = change.test_device
    return job, changes


# -- the run ---------------------------------------------------------------------------------------------------------


def refuse_other(out: Path, stored: dict | None, spec: AuditSpec) -> None:
    """Raise where the audit in `out` (its stored spec) is not `spec`: a resumed audit must be the same one."""
    asked = spec.fingerprint()
    # The floor may differ (an audit started before it, or with another): the cells it would change run again.
    differs = [key for key in asked if key != "min_passes" and (not isinstance(stored, dict) or
                                                                 stored.get(key) != asked[key])]  # fmt: skip
    if differs:
        raise BatchError(f"can't resume the audit in {out}: it was started with other {', '.join(differs)} (the "
                         "cells' level and budget depend on them): use another --out")  # fmt: skip


class Quiet(Progress):
    """The checks' progress inside an audit: nothing of their passes or looks (the audit prints a line per cell),
    each distinct warning once."""

    def __init__(self):
        super().__init__(0, label="audit", live=False, brief=True)
        self.seen: set[str] = set()

    def emit(self, event) -> None:
        if isinstance(event, protocol.Warned):
            if event.message in self.seen:
                return
            self.seen.add(event.message)
        super().emit(event)


@dataclass
class Audit:
    """Runs the cells of a plan into `out` (`run`, or one cell at a time: `result`), keeping their records in
    ``audit.json``. `cluster` is (local workers, scheduler address) to render on Dask, or (None, None)."""

    plan: AuditPlan
    out: Path
    support: dict = field(default_factory=dict)
    resume: bool = False
    cluster: tuple = (None, None)
    say: object = print
    records: dict = field(default_factory=dict)

    def __post_init__(self):
        self.out = Path(self.out)
        self.quiet = Quiet()
        self.again: list[str] = []  # recorded cells that run again: an error, or cut short below the floor

    # -- state ---------------------------------------------------------------------------------------------------

    def state_path(self) -> Path:
        return self.out / STATE_FILE

    def load(self) -> None:
        """The records of an earlier run in `out` (`resume`), which must be the same audit; none without."""
        path = self.state_path()
        if not self.resume:
            if path.exists():
                raise BatchError(f"{self.out} holds an audit already: pass --resume to continue it, or another --out")
            return
        if not path.exists():
            return
        try:
            state = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise BatchError(f"{path} is not a readable audit state ({exc})") from None
        if not isinstance(state, dict) or state.get("format") != "welch-bias-audit":
            raise BatchError(f"{path} is not an audit state file")
        if state.get("version") != STATE_VERSION:
            raise BatchError(f"{path} was written by another version of this tool: start the audit in another --out")
        refuse_other(self.out, state.get("spec"), self.plan.spec)
        self.records = dict(state.get("cells", {}))
        floor = self.plan.spec.floor
        for key, record in list(self.records.items()):
            checks = [record.get("first"), record.get("confirm")]
            if record.get("status") == "error" or (record.get("status") == "undecided" and checks[0] is None) or any(
                    cut_short(c, floor) for c in checks):  # fmt: skip
                self.again.append(key)
                del self.records[key]

    def save(self) -> None:
        state = {
            "format": "welch-bias-audit",
            "version": STATE_VERSION,
            "spec": self.plan.spec.fingerprint(),
            "support": self.support,
            "cells": self.records,
            "saved": datetime.now(UTC).isoformat(timespec="seconds"),
        }
        text = json.dumps(state, indent=2, allow_nan=False)
        self.out.mkdir(parents=True, exist_ok=True)
        wc.formats.atomic_write(self.state_path(), lambda f: f.write(text.encode()))

    # -- cells ---------------------------------------------------------------------------------------------------

    def run(self) -> list[CellResult]:
        """Every cell of the plan, each reused where an earlier run decided it; one line per cell through `say`,
        with the time the rest is expected to take."""
        self.load()
        plan, say = self.plan, self.say
        done = {key for key in self.records}
        ahead = plans.estimate(plan, done)
        say(f"audit {plan.spec.name}: {len(plan.spec.changes)} changes x {len(plan.spec.scenes)} scenes, "
            f"{plan.k} cells ({len(plan.not_applicable)} not applicable), {plans.budget_text(plan.spec)}")  # fmt: skip
        say(f"audit: {plan.alpha_text()}")
        if self.again:
            say(f"audit: {fmt.count(len(self.again), 'recorded cell')} run again (an error, or passes a side cut "
                f"below the floor of {plan.spec.floor}): {', '.join(self.again)}")  # fmt: skip
        say(f"audit: {len(done)} cells decided already; " + ahead.text() if done else f"audit: {ahead.text()}")
        results, spent, modelled = [], 0.0, 0.0
        workers, scheduler = self.cluster
        with side_cluster(workers, scheduler) as where:
            for number, cell in enumerate(plan.cells, 1):
                result = self.result(cell, where)
                results.append(result)
                if not result.reused:
                    spent += result.seconds
                    modelled += plans.estimate(plans.AuditPlan(plan.spec, (cell,))).expected
                left = plans.estimate(plan, done | {c.key for c in plan.cells[:number]}).expected  # decided: none
                left *= spent / modelled if modelled else 1.0
                tail = f"; about {fmt.duration(left)} left" if number < plan.k and left > 0 else ""
                say(f"audit: {number}/{plan.k} {cell.change.name} on {cell.scene.label}: "
                    f"{'reused: ' if result.reused else ''}{result.message}{tail}")  # fmt: skip
        results += [CellResult(cell, "not_applicable", f"not applicable: {why}") for cell, why in plan.not_applicable]
        return results

    def result(self, cell: Cell, where=None) -> CellResult:
        """The cell's result: its record where an earlier run decided it, else its checks run now (and recorded)."""
        if cell.key in self.records:
            return self._reused(cell)
        if cell.key in self.again:
            shutil.rmtree(self.folder(cell), ignore_errors=True)  # its checks start again, with this floor
        start = time.perf_counter()
        result = self._run_cell(cell, where)
        result.seconds = time.perf_counter() - start
        self.records[cell.key] = result.to_json()
        self.save()
        return result

    def folder(self, cell: Cell) -> Path:
        return self.out / "cells" / cell.change.name / cell.scene.label

    def _check(self, cell: Cell, role: str, where) -> dict:
        folder = self.folder(cell) / role
        resume = (folder / "check.json").exists()
        workers, scheduler = self.cluster
        job = cell_job(self.plan, cell, role, folder, resume, workers, scheduler)
        _verdict, summary = run_check(job, self.quiet, where)
        return check_record(summary, folder, self.out)

    def _reused(self, cell: Cell) -> CellResult:
        """A recorded cell, said as this version says it (its status, sentence, command and bisect)."""
        result = CellResult.from_json(cell, self.records[cell.key])
        if result.status == "biased" and not cell.change.control:  # a finding, or one at the scale of rounding
            result.command = check_command(self.plan, cell, "confirm", self.folder(cell) / "again")
        if result.bisect and result.bisect.get("steps") is not None:
            result.bisect["message"] = bisect_sentence(result.bisect, self._bisect_builds(), self.plan.spec)
        return result

    def _run_cell(self, cell: Cell, where) -> CellResult:
        try:
            first = self._check(cell, "first", where)
            confirm = self._check(cell, "confirm", where) if first["verdict"] == "biased" else None
        except Undecided as exc:  # its time budget ended the first passes: no look, no verdict, not the tool's error
            return CellResult(cell, "undecided", f"not decided, too few passes within the budget: {exc}")
        except BatchError as exc:
            if NO_GPU_MESSAGE in str(exc):
                shutil.rmtree(self.folder(cell), ignore_errors=True)
                return CellResult(cell, "not_applicable", f"not applicable: {exc}")
            return CellResult(cell, "error", f"error: {' '.join(str(exc).split())}")
        status = status_of(first, confirm)
        result = CellResult(cell, status, cell_sentence(cell, status, first, confirm), first=first, confirm=confirm)
        if result.status == "biased" and not cell.change.control:  # a finding, or one at the scale of rounding
            result.command = check_command(self.plan, cell, "confirm", self.folder(cell) / "again")
        if result.finding and not cell.change.aa:  # the default against itself: no change to explain
            result.explain = self._explain(cell, where)
            result.bisect = self._bisect(cell)
        return result

    def _explain(self, cell: Cell, where) -> dict:
        """The change with the biased-by-design settings off on both sides: the change itself, or what those cut?"""
        if cell.scene.scene is not None:
            return {"skipped": "a built-in scene has every biased-by-design setting off already (no clamp, no "
                    "Filter Glossy, caustics on): the difference is the change's own"}  # fmt: skip
        try:
            record = self._check(cell, "explain", where)
        except BatchError as exc:
            return {"error": " ".join(str(exc).split())}
        return record | {"meaning": explain_sentence(record)}

    def _bisect_builds(self) -> list:
        """The builds a bisect looks at, oldest first: the audit's releases, then the audited one."""
        spec = self.plan.spec
        return [b for b in spec.releases if b.label != spec.build.label] + [spec.build]

    def _bisect(self, cell: Cell) -> dict | None:
        """The first release of the audit's `releases` (then the audited one) that shows the difference."""
        spec = self.plan.spec
        if not spec.releases:
            return None
        from .matrix import run_bisect

        builds = self._bisect_builds()
        job, changes = bisect_job(self.plan, cell)
        folder = self.folder(cell) / "bisect"
        try:
            found = run_bisect(job, builds, spec.bisect_passes, folder, self.plan.level, spec.tolerance,
                               lambda _total: self.quiet, lambda _line: None, changes)  # fmt: skip
        except BatchError as exc:
            return {"error": " ".join(str(exc).split())}
        record = found.to_json()
        record["versions"] = versions = {}
        for build in builds:
            path = folder / "renders" / f"{build.label}.npz"
            with contextlib.suppress(OSError, wc.WelchInputError):
                versions[build.label] = wc.load_stats(path, pixels=False).info.renderer_version
        record["message"] = bisect_sentence(record, builds, spec)
        for step in record["steps"]:
            step["pair"]["folder"] = os.path.relpath(step["pair"]["folder"], self.out) if step["pair"]["folder"] else ""
        return record


# -- words ----------------------------------------------------------------------------------------------------------


def bisect_sentence(record: dict, builds: list, spec: AuditSpec) -> str:
    """What a bisect found, each build by its release ("5.0.1 (current)"), the build before the first that shows
    the difference with what its step said (not shown is not absent: its verdict and interval)."""
    versions = record.get("versions") or {}

    def name(label: str) -> str:
        version = (versions.get(label) or "").removesuffix(" LTS")
        return f"{version} ({label})" if version and version != label else label

    first, steps = record.get("first"), {s["build"]: s for s in record.get("steps", [])}
    if first is None:
        text = record.get("message") or ""
        for label in steps:
            text = text.replace(f"{label} ", f"{name(label)} ", 1)
        return text
    order = [b.label for b in builds]
    before = [label for label in order[: order.index(first)] if label in steps] if first in order else []
    if not before:
        return f"the difference appears in {name(first)}"
    good = steps[before[-1]]["pair"]
    whole = f", whole image {fmt.difference(good['whole_image'])}" if good.get("whole_image") else ""
    return (f"the difference appears in {name(first)} and is not shown in {name(before[-1])}, the build before it "
            f"({good['verdict']} at {spec.bisect_passes} passes a side{whole})")  # fmt: skip


def claim_text(record: dict) -> str:
    """An `equivalent` check's claim: "within ±1.00 % in every 32x32 tile" (the whole image where that is its size)."""
    tolerance, tile = record.get("tolerance"), record.get("claim_tile")
    where = "in every tile" if tile is None else f"in every {tile}x{tile} tile"
    return f"within ±{100 * tolerance:.2f} % {where}" if tolerance else where


def cell_sentence(cell: Cell, status: str, first: dict, confirm: dict | None) -> str:
    """A cell in a line, as the page and the log say it."""
    passes = f"{first['passes']} passes a side"
    if status == "equivalent" and first.get("identical"):
        return (f"no difference: every pass identical on both sides ({passes}; {identical_needed(first)} rule out a "
                "change that alters one pass in ten)")  # fmt: skip
    if status == "equivalent":
        return f"no difference {claim_text(first)} ({passes})"
    if status == "biased":
        whole = fmt.difference(confirm["whole_image"]) if confirm["whole_image"] else "—"
        what = "found (biased by design)" if cell.change.control else "biased"
        if rounding_only(first, confirm):
            what = "biased at the scale of float rounding" + (", not exercised" if cell.change.control else "")
            strongest = f"; {rounding_text(first, confirm)}"
        else:
            strongest = strongest_text(confirm)
        return (f"{what}: whole image {whole}{strongest} (confirmed on fresh seeds: {confirm['passes']} passes, p "
                f"{fmt.p_value(confirm['p_value'])}; first {passes})")  # fmt: skip
    if status == "unconfirmed":
        again = f"{confirm['verdict'].replace('_', ' ')}, whole image {fmt.difference(confirm['whole_image'])}"
        return f"biased on its first seeds ({passes}), not on fresh ones ({confirm['passes']} passes a side: {again})"
    if first.get("identical"):
        return (f"not decided: every pass identical on both sides so far ({passes}; {identical_needed(first)} would "
                "rule out a change that alters one pass in ten)")  # fmt: skip
    ruled = first.get("ruled_out")
    bound = f"; a bias beyond {100 * ruled['bias']:.2f} % ruled out per {ruled['tile']}x{ruled['tile']} tile" if (
        ruled) else ""  # fmt: skip
    return f"not decided ({passes}){bound}"


def strongest_text(record: dict) -> str:
    """The most significant tile of a check's record, where it is a tile ("; most significant -3.10 % [...] in R of
    a 16x16 tile at 0, 16"): what rejected, where the whole image's interval may hold 0."""
    strongest = record.get("most_significant") or {}
    if not strongest.get("tile") or strongest.get("estimate") is None:
        return ""
    size = strongest["tile"]
    return (f"; most significant {fmt.difference(strongest)} in {strongest['channel']} of a {size}x{size} tile at "
            f"{strongest['x']}, {strongest['y']}")  # fmt: skip


def explain_sentence(record: dict) -> str:
    """What the check with the biased-by-design settings off says about a confirmed difference."""
    whole = fmt.difference(record["whole_image"]) if record.get("whole_image") else "—"
    if record["verdict"] == "biased":
        return f"the change itself moves the image: with the biased-by-design settings off it is biased too ({whole})"
    if record["verdict"] == "equivalent":
        return (f"with the biased-by-design settings off it is equivalent {claim_text(record)}: the change moves what "
                "those settings cut, not the converged image")  # fmt: skip
    return f"with the biased-by-design settings off: not decided (whole image {whole})"


# -- outcome --------------------------------------------------------------------------------------------------------


def unfound_controls(plan: AuditPlan, results: list[CellResult]) -> list[str]:
    """The controls (biased by design) the audit found in no scene: where none is found, it could not have found
    a noise-only setting's bias either."""
    rows = plans.cells_per_row(plan)
    found = {r.cell.change.name for r in results if r.found}
    return [c.name for c in plan.spec.changes if c.control and rows[c.name] and c.name not in found]


def exit_code(plan: AuditPlan, results: list[CellResult]) -> int:
    """1 where a setting documented to change only the noise is confirmed biased beyond float rounding (the A/A row
    included), else 2
    where a cell could not run, else 3 where a control was found in no scene (the audit can't vouch for its
    power), else 0."""
    if any(r.finding for r in results):
        return Exit.BIASED
    if any(r.status == "error" for r in results):
        return Exit.USAGE
    if unfound_controls(plan, results):
        return Exit.INCONCLUSIVE
    return Exit.OK


def summary_of(plan: AuditPlan, results: list[CellResult], seconds: float | None = None) -> dict:
    """summary.json: the audit's plan, level, outcome, findings and every cell."""
    counts = {s: sum(r.status == s for r in results) for s in STATUSES}
    findings = [r for r in results if r.finding]
    renderer = next((r.first.get("renderer") for r in results if r.first and r.first.get("renderer")), None)
    build = next((r.first.get("build") for r in results if r.first and r.first.get("build")), None)
    return {
        "audit": plan.spec.name,
        "release": {"label": plan.spec.build.label, "version": renderer, "build": build},
        "alpha": plan.spec.alpha,
        "cells_k": plan.k,
        "level": plan.level,
        "alpha_split": plan.alpha_text(),
        "budget": plans.budget_text(plan.spec),
        "exit_code": exit_code(plan, results),
        "seconds": round(sum(r.seconds for r in results), 1),  # the cells' own, those reused included
        "wall_seconds": None if seconds is None else round(seconds, 1),  # this run's
        "counts": counts,
        "equal_budget": plans.equal_budget_text(plan.spec),
        "controls_found": {
            c.name: [r.cell.scene.label for r in results if r.found and r.cell.change.name == c.name]
            for c in plan.spec.changes
            if c.control
        },
        "unfound_controls": unfound_controls(plan, results),
        "findings": [r.cell.key for r in findings],
        "rounding": [r.cell.key for r in results if r.rounding],
        "changes": [c.to_json() for c in plan.spec.changes],
        "scenes": [s.label for s in plan.spec.scenes],
        "cells": [r.to_json() for r in results],
    }


def write_outputs(plan: AuditPlan, results: list[CellResult], out: Path, seconds: float | None = None) -> dict:
    """summary.json, junit.xml (a test case per cell) and index.html (the audit page) in `out`."""
    from ..present.audit_page import write_audit_page
    from ..present.junit import junit_xml

    out.mkdir(parents=True, exist_ok=True)
    summary = summary_of(plan, results, seconds)
    text = json.dumps(summary, indent=2, allow_nan=False)
    wc.formats.atomic_write(out / "summary.json", lambda f: f.write(text.encode()))
    xml = junit_xml(f"audit {plan.spec.name}", [junit_case(r, out) for r in results])
    wc.formats.atomic_write(out / "junit.xml", lambda f: f.write(xml))
    write_audit_page(out / "index.html", plan, summary, results)
    return summary


def junit_case(result: CellResult, out: Path):
    """A cell as a suite case's result, for JUnit: failed where a noise-only setting is confirmed biased or the
    cell could not run, skipped where not applicable, passed otherwise (a control's cell passes found or not)."""
    from .suite import Case, CaseResult

    status = {"error": "error", "not_applicable": "skipped"}.get(result.status, "passed")
    if result.finding:
        status = "failed"
    case = Case(name=result.cell.key, scene=result.cell.scene.scene, why=result.cell.change.why)
    folder = str(out / result.first["report"]).removesuffix("/report.html") if result.first else None
    verdict = "biased" if result.status == "biased" else None
    return CaseResult(case, "CPU", status, verdict, result.message, result.seconds, folder=folder)


def run_audit(plan: AuditPlan, out: Path, support: dict, resume: bool = False, cluster=(None, None),
              say=print) -> tuple[list[CellResult], dict]:  # fmt: skip
    """Run every cell of `plan` into `out` and write its outputs: (the cells' results, summary.json's content)."""
    start = time.perf_counter()
    audit = Audit(plan, out, support, resume, cluster, say)
    results = audit.run()
    return results, write_outputs(plan, results, Path(out), time.perf_counter() - start)


def prepare(spec: AuditSpec, out: Path, resume: bool, say=print, probe=None) -> tuple[AuditPlan, dict]:
    """The plan of `spec` with what its release supports: read from the audit being resumed in `out`, else asked of
    the release (`batch.decide.audit.support`, a few seconds a change)."""
    state = Path(out) / STATE_FILE
    found = None
    if resume and state.exists():
        stored = None
        with contextlib.suppress(OSError, ValueError):
            stored = json.loads(state.read_text())
        if isinstance(stored, dict) and stored.get("format") == "welch-bias-audit":
            refuse_other(Path(out), stored.get("spec"), spec)  # before asking the release anything
            found = stored.get("support")
    if not isinstance(found, dict) or set(found) != {c.name for c in spec.changes}:
        say(f"audit: asking {spec.build.label} which of the {len(spec.changes) - 1} changes it can render")
        found = plans.support(spec, probe)
    return plans.plan_audit(spec, found), found
