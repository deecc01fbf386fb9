"""The plan of an unbiasedness audit of a Cycles release: which settings, on which scenes, at which level.

An audit compares every setting change of a list kept as data (`BUILTIN_CHANGES`, ``audits/cycles.toml``; a user's
own in the same form) against its default, on every scene (the built-in ones by default, and .blend files), with
one release (this bpy, another release's bpy, or a Blender binary). Each change says what Cycles documents it to
change: only the noise (`Change.control` False), or the image by design (a clamp, Filter Glossy: a control the
audit must find where its scene exercises it). The default against itself on disjoint seeds (`AA`, an A/A row)
is part of every audit. A cell is one change on one scene; `batch.decide.audit_run` runs it as a `check`.

The level (`AuditPlan.level`): with K cells, each cell's first check and its confirmation on fresh seeds are each
decided at alpha / K (Bonferroni over the audit's cells), and a cell is reported `biased` only where both reject:
the chance that an audit reports a difference in a cell where there is none is at most alpha / K per cell and
at most alpha over the whole audit. A cell's `equivalent` is a claim at the same level (its tolerance and the
tile size `check` sized it for are on the page). The explanation of a confirmed difference (a check with the
biased-by-design settings off, a bisect across releases) asks further questions, each at alpha / K too.

Nothing here imports bpy: a release is asked which settings it has by processes of its own (`support`).
"""

from __future__ import annotations

import dataclasses
import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..errors import BatchError
from ..jobs import options
from ..jobs.job import BUILTIN_SCENES, RenderJob
from ..jobs.lobes import COMPONENTS
from ..jobs.overrides import parse_override
from ..jobs.samples import BUILTIN, differing, side_settings
from .matrix import Build

#: The shipped list of changes (Cycles' settings documented to change only the noise, and the controls).
BUILTIN_CHANGES = Path(__file__).with_name("audits") / "cycles.toml"

#: What Cycles documents a change to do: only the noise (or the speed), or the image by design.
DOCUMENTED = {"noise": "changes only the noise", "bias": "biased by design"}

#: The biased-by-design settings turned off on both sides to explain a confirmed difference: does the change
#: itself move the image, or what these cut? (BLENDER_FACTS: Blender's defaults clamp indirect light at 10 and
#: blur glossy at 1.0; the caustics switches remove light; the light threshold ends light samples at random.)
UNBIASED_OVERRIDES = (
    "cycles.sample_clamp_direct=0",
    "cycles.sample_clamp_indirect=0",
    "cycles.blur_glossy=0",
    "cycles.caustics_reflective=true",
    "cycles.caustics_refractive=true",
    "cycles.light_sampling_threshold=0",
)

#: The light components a confirmation renders (`--lobes`): which one carries a difference.
LOBES = COMPONENTS

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
_KEYS = ("name", "setting", "reference", "test", "pattern", "test_pattern", "test_device", "documented", "samples",
         "why")  # fmt: skip
_AUDIT_KEYS = ("name", "scenes", "blends", "changes", "only", "resolution", "tile", "passes", "seconds", "min_passes",
               "alpha", "tolerance")  # fmt: skip


@dataclass(frozen=True)
class Change:
    """One row of an audit: `setting` changed from the `reference` overrides (its default, set explicitly) to the
    `test` ones (`pattern`: both sides' sampling pattern, `test_pattern` and `test_device` the test side's own),
    rendered at `samples` per pass, documented to change only the noise or biased by design (`documented`), with
    `why` in words."""

    name: str
    setting: str
    documented: str
    samples: int
    why: str
    reference: tuple[str, ...] = ()
    test: tuple[str, ...] = ()
    pattern: str | None = None
    test_pattern: str | None = None
    test_device: str | None = None

    @property
    def control(self) -> bool:
        """Biased by design: the audit must find it where its scene exercises it."""
        return self.documented == "bias"

    @property
    def aa(self) -> bool:
        """The default against itself (disjoint seeds)."""
        return not (self.test or self.test_pattern or self.test_device)

    def sides(self, base: tuple[str, ...] = ()) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """Both sides' overrides on top of `base` (a later override of a path replaces an earlier one)."""
        return merged(base, self.reference), merged(base, self.reference, self.test)

    def to_json(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(self).items()}


#: The A/A row of every audit: the scene's settings against themselves, on disjoint seeds.
AA = Change(
    name="default",
    setting="(none)",
    documented="noise",
    samples=1,
    why="The scene's own settings against themselves on disjoint seeds: what the audit says where nothing changes.",
)


def merged(*lists: tuple[str, ...]) -> tuple[str, ...]:
    """Overrides of several lists in order, one per path: a later one replaces an earlier one of the same path."""
    by_path: dict[str, str] = {}
    for items in lists:
        for text in items:
            path = parse_override(text).path.removeprefix("scene.")
            by_path.pop(path, None)
            by_path[path] = text
    return tuple(by_path.values())


# -- the data file -------------------------------------------------------------------------------------------------


def load_changes(path: Path | str, taken: tuple[str, ...] = ()) -> tuple[Change, ...]:
    """The changes of a file of ``[[change]]`` tables (an audit file's own), every problem of it in one error
    (`taken`: names used already, by the shipped list)."""
    path = Path(path)
    data, problems = _read_tables(path, "a file of changes has [[change]] tables")
    changes = read_changes(data.get("change", []), problems, taken)
    if problems:
        raise BatchError(_problems(path, problems))
    return changes


def read_changes(entries, problems: list[str], taken: tuple[str, ...] = ()) -> tuple[Change, ...]:
    """The changes of a list of ``[[change]]`` tables; each bad entry adds one line to `problems` per problem,
    naming the change and the key (`taken`: names already used, by the shipped list)."""
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        problems.append("'change' must be a list of [[change]] tables")
        return ()
    changes, seen = [], set(taken)
    for index, entry in enumerate(entries, 1):
        label = f"change {entry.get('name', index)!r}"
        change = _change(entry, label, problems)
        if change is not None and change.name in seen:
            problems.append(f"{label}: the name is used twice")
        elif change is not None:
            seen.add(change.name)
            changes.append(change)
    return tuple(changes)


def _got(entry: dict, key: str) -> str:
    """How a bad value of `key` is named in a problem: the value, or that it is missing."""
    return f"got {entry[key]!r}" if key in entry else "and it is missing"


def _change(entry: dict, label: str, problems: list[str]) -> Change | None:
    found = len(problems)
    unknown = sorted(set(entry) - set(_KEYS))
    if unknown:
        problems.append(f"{label}: unknown key {unknown[0]!r} (a change has {', '.join(_KEYS)})")
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME.fullmatch(name) or name == AA.name:
        problems.append(f"{label}: 'name' must be lower-case letters, digits and '_' (not {AA.name!r}), "
                        f"{_got(entry, 'name')}")  # fmt: skip
    for key, meaning in (("setting", "the setting changed"), ("why", "what Cycles documents it to change")):
        if not isinstance(entry.get(key), str) or not entry[key].strip():
            problems.append(f"{label}: {key!r} must be text ({meaning}), {_got(entry, key)}")
    documented = entry.get("documented")
    if documented not in DOCUMENTED:
        problems.append(f"{label}: 'documented' must be 'noise' or 'bias', {_got(entry, 'documented')}")
    sides = {}
    for key in ("reference", "test"):
        value = entry.get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            problems.append(f"{label}: {key!r} must be a list of overrides such as \"cycles.use_guiding=true\", got "
                            f"{value!r}")  # fmt: skip
            continue
        for text in value:
            try:
                options.OPTIONS["overrides"].convert(f"{key!r}", text)
            except BatchError as exc:
                problems.append(f"{label}: {exc}")
        sides[key] = tuple(value)
    for key in ("pattern", "test_pattern"):
        if key in entry and not (isinstance(entry[key], str) and re.fullmatch(r"[A-Z][A-Z_]*", entry[key])):
            problems.append(f"{label}: {key!r} must be a sampling pattern such as BLUE_NOISE, got {entry[key]!r}")
    device = entry.get("test_device")
    if device is not None and device not in options.DEVICES:
        problems.append(f"{label}: 'test_device' must be one of {', '.join(options.DEVICES)}, got {device!r}")
    samples = entry.get("samples")
    if isinstance(samples, bool) or not isinstance(samples, int) or not 1 <= samples <= options.MAX_SPP:
        problems.append(f"{label}: 'samples' (samples per render, at least what the setting acts at) must be an "
                        f"integer in 1..{options.MAX_SPP}, {_got(entry, 'samples')}")  # fmt: skip
        samples = None
    same = (sides.get("reference", ()), entry.get("pattern")) == (sides.get("test", ()), entry.get("test_pattern"))
    if "reference" in sides and "test" in sides and same and device is None:
        problems.append(f"{label}: 'test' is the same as 'reference': the change changes nothing")
    if len(problems) > found:
        return None
    change = Change(name=name, setting=entry["setting"], documented=documented, samples=samples, why=entry["why"],
                    reference=sides.get("reference", ()), test=sides.get("test", ()), pattern=entry.get("pattern"),
                    test_pattern=entry.get("test_pattern"), test_device=device)  # fmt: skip
    if change.aa:
        problems.append(f"{label}: the two sides are the same: give 'test', 'test_pattern' or 'test_device' (the "
                        "default against itself is part of every audit)")  # fmt: skip
        return None
    fewest = acts_from(change)
    if fewest is not None and samples < fewest[1]:
        problems.append(f"{label}: 'samples' {samples} is fewer than {fewest[0]} acts at ({fewest[1]} samples a "
                        "render, batch/jobs/samples.py): its passes would render the default")  # fmt: skip
        return None
    return change


def acts_from(change: Change) -> tuple[str, int] | None:
    """(the setting, the fewest samples per render it acts at) where the change's sides differ in a setting that
    acts only above some samples per render (`batch.jobs.samples`), on a built-in scene; None where none."""
    reference, test = change.sides()
    found = differing(side_settings(BUILTIN, change.pattern, reference),
                      side_settings(BUILTIN, change.test_pattern or change.pattern, test))  # fmt: skip
    if not found:
        return None
    most = max(found, key=lambda d: d.fewest)
    return most.path, most.fewest


def _read_toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BatchError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise BatchError(f"{path}: not readable TOML: {exc}") from None


def _read_tables(path: Path, tables: str) -> tuple[dict, list[str]]:
    """An audit file's or a file of changes' tables, and its first problem where it has a table other than
    ``[audit]`` and ``[[change]]`` (`tables` says which it has)."""
    data = _read_toml(path)
    unknown = sorted(set(data) - {"audit", "change"})
    return data, [f"unknown table [{unknown[0]}] ({tables})"] if unknown else []


def _problems(path: Path, problems: list[str]) -> str:
    count = f"{len(problems)} problems" if len(problems) > 1 else "a problem"
    return f"{path}: {count}, nothing rendered: " + "; ".join(problems)


# -- scenes and the plan -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scene:
    """A scene of an audit: a built-in one (`scene`) or a .blend file (`blend`), by its `label` (a folder name)."""

    label: str
    scene: str | None = None
    blend: str | None = None


def scenes_of(names: list[str] | tuple[str, ...], blends: list[str] | tuple[str, ...]) -> tuple[Scene, ...]:
    """The built-in scenes named (``all``: every one) and the .blend files, each labelled once (a file by its name,
    numbered where two share one)."""
    if "all" in names:
        names = [*BUILTIN_SCENES, *(n for n in names if n != "all" and n not in BUILTIN_SCENES)]
    unknown = [n for n in names if n not in BUILTIN_SCENES]
    if unknown:
        raise BatchError(f"unknown built-in scene {unknown[0]!r}; choose from {', '.join(BUILTIN_SCENES)} or all")
    scenes = [Scene(n, scene=n) for n in dict.fromkeys(names)]
    labels = {s.label for s in scenes}
    for blend in blends:
        path = Path(blend)
        if not path.is_file():
            raise BatchError(f"{blend}: no such .blend file")
        label, number = path.stem, 2
        while label in labels or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", label):
            label, number = f"{re.sub(r'[^A-Za-z0-9_.-]', '_', path.stem) or 'scene'}-{number}", number + 1
        labels.add(label)
        scenes.append(Scene(label, blend=str(path.resolve())))
    if not scenes:
        raise BatchError("no scene to audit")
    return tuple(scenes)


@dataclass(frozen=True)
class AuditSpec:
    """What an audit is asked: its scenes, changes (the A/A row first), release and per-cell budget (passes a
    side, and render seconds where given, with a floor of passes a side that the seconds do not cut), the audit's
    alpha, the tolerance of `equivalent`, the image, the first seed, and the releases a confirmed difference is
    bisected over (oldest first; empty: no bisect)."""

    name: str
    scenes: tuple[Scene, ...]
    changes: tuple[Change, ...]
    build: Build = Build("current")  # this bpy (`batch.decide.matrix.build_of` makes another)
    max_passes: int = options.default("max_passes", "audit")
    max_seconds: float | None = options.default("max_seconds", "audit")
    min_passes: int = options.default("min_passes", "audit")
    alpha: float = options.default("alpha", "audit")
    tolerance: float | None = options.default("tolerance", "audit")
    resolution: tuple[int, int] | None = None
    tile: int = options.default("tile", "audit")
    seed_offset: int = 0
    releases: tuple[Build, ...] = ()
    bisect_passes: int = options.default("passes", "bisect")

    @property
    def floor(self) -> int | None:
        """The passes a side each check renders whatever their seconds (None: no time budget, every pass of the
        budget renders)."""
        return None if self.max_seconds is None else min(self.min_passes, self.max_passes)

    def fingerprint(self) -> dict:
        """What a resumed audit must share with the one it continues (its cells' level and budget depend on it; a
        floor of passes may differ: the cells it would change run again)."""
        return {
            "scenes": [dataclasses.asdict(s) for s in self.scenes],
            "changes": [c.to_json() for c in self.changes],
            "build": dataclasses.asdict(self.build),
            "max_passes": self.max_passes,
            "max_seconds": self.max_seconds,
            "min_passes": self.floor,
            "alpha": self.alpha,
            "tolerance": self.tolerance,
            "resolution": list(self.resolution) if self.resolution else None,
            "tile": self.tile,
            "seed_offset": self.seed_offset,
        }


@dataclass(frozen=True)
class Cell:
    """One change on one scene."""

    change: Change
    scene: Scene

    @property
    def key(self) -> str:
        return f"{self.change.name}/{self.scene.label}"


@dataclass(frozen=True)
class AuditPlan:
    """The audit's cells: those the release can render (`cells`), those it can't with the reason
    (`not_applicable`), and the level each of their checks is decided at (`level`: alpha / K)."""

    spec: AuditSpec
    cells: tuple[Cell, ...]
    not_applicable: tuple[tuple[Cell, str], ...] = ()

    @property
    def k(self) -> int:
        return len(self.cells)

    @property
    def level(self) -> float:
        """Each check's alpha: the audit's, split evenly over its cells (Bonferroni)."""
        return self.spec.alpha / max(self.k, 1)

    def alpha_text(self) -> str:
        """How alpha was split, in words (the page and the log say it)."""
        return (
            f"alpha {self.spec.alpha:g} over the audit's {self.k} cells: each cell's first check and its "
            f"confirmation on fresh seeds (tile sums only) at alpha / {self.k} = {self.level:.3g}, and a cell is "
            f"reported biased only where both reject (at most {self.level:.3g} a cell, {self.spec.alpha:g} in all); "
            f"an `equivalent` is claimed at the same level; each explanation (the change with the biased-by-design "
            f"settings off, a bisect) at {self.level:.3g} too"
        )


def plan_audit(spec: AuditSpec, support: dict[str, str | None]) -> AuditPlan:
    """The cells of `spec` (change-major, the A/A row first), split by what the release supports (`support`:
    change name -> why it can't render, or None)."""
    cells, skipped = [], []
    for change in spec.changes:
        for scene in spec.scenes:
            reason = support.get(change.name)
            (cells.append(Cell(change, scene)) if reason is None else skipped.append((Cell(change, scene), reason)))
    return AuditPlan(spec, tuple(cells), tuple(skipped))


def probe_job(spec: AuditSpec, change: Change, test: bool) -> RenderJob:
    """The job that asks the release whether it can render a side of `change` (`batch.cli.commands`' ``render
    --probe``: the scene set up as its passes would be, on the corner scene)."""
    reference, tested = change.sides()
    return RenderJob(out="probe.npz", seeds=(0,), scene="corner", spp=change.samples, tile=spec.tile,
                     sampling_pattern=(change.test_pattern or change.pattern) if test else change.pattern,
                     device=(change.test_device or "CPU") if test else "CPU", overrides=tested if test else reference,
                     blender=spec.build.blender, python=spec.build.python)  # fmt: skip


def support(spec: AuditSpec, probe: Callable[[list[RenderJob]], list[str | None]] | None = None,
            ) -> dict[str, str | None]:  # fmt: skip
    """Which changes the release can render: change name -> None, or the reason it can't (a setting, pattern or
    device it lacks), as the release's own processes say. `probe` takes jobs and returns each one's refusal or None
    (default `probe_release`); a release that can't even render the plain scene is an error."""
    probe = probe or probe_release
    plain = RenderJob(out="probe.npz", seeds=(0,), scene="corner", blender=spec.build.blender,
                      python=spec.build.python)  # fmt: skip
    changes = [c for c in spec.changes if not c.aa]
    jobs = [plain] + [probe_job(spec, c, test) for c in changes for test in (False, True)]
    answers = probe(jobs)
    if answers[0] is not None:
        raise BatchError(f"the release {spec.build.label} can't render: {answers[0]}")
    found: dict[str, str | None] = {c.name: None for c in spec.changes}
    for index, change in enumerate(changes):
        refusals = [a for a in answers[1 + 2 * index : 3 + 2 * index] if a is not None]
        found[change.name] = refusals[0] if refusals else None
    return found


#: Probe processes at once (each a Blender of about 300 MB).
PROBES_AT_ONCE = 4


def probe_release(jobs: list[RenderJob]) -> list[str | None]:
    """Each job's refusal by its build (``render --probe``), or None where it would render; a few processes at once."""
    from ..jobs.side import Side

    answers: list[str | None] = []
    for start in range(0, len(jobs), PROBES_AT_ONCE):
        sides = [Side(None, job) for job in jobs[start : start + PROBES_AT_ONCE]]
        try:
            for side in sides:
                side.start_probe()
            for side in sides:
                try:
                    side.probed()
                    answers.append(None)
                except BatchError as exc:
                    answers.append(" ".join(str(exc).split()))
        finally:
            for side in sides:
                side.stop()
    return answers


# -- the estimate ----------------------------------------------------------------------------------------------------

#: Wall seconds a check costs beyond its passes: both render processes started and the scene built, the two at once,
#: and its looks. Fitted with the next two on 28 cells of an audit of bpy 5.2.3 here (64x64, 64 passes a side, two
#: cores shared): wall = 3.4 s + 0.58 x render seconds.
CHECK_OVERHEAD = 3.5
#: Render seconds of one sample of one pixel of one side's pass, both sides rendering at once (`check`'s render
#: seconds count both): the built-in scenes took 4-9e-6 (1 sample a pass), 7e-6 with path guiding at 16, 3e-6 at 32.
SAMPLE_SECONDS = 6e-6
#: Wall seconds per render second: the two sides render at once on two cores.
WALL_SHARE = 0.6
#: The share of its budget a cell renders, as the estimate expects it (a check stops at `equivalent` from 44 passes
#: a side, at `biased` at once, at its futility stop, or at the budget).
EXPECTED_SHARE = 0.75
#: A confirmed difference's share of the cells, as the estimate expects it (the controls, mostly).
EXPECTED_FINDINGS = 0.15


@dataclass(frozen=True)
class Estimate:
    """What an audit expects to take, in wall seconds: `expected`, and `at_most` with every cell rendering its whole
    budget (and every one confirmed)."""

    expected: float
    at_most: float
    cells: int

    def text(self) -> str:
        from ..present import fmt

        return (f"{self.cells} cells to run: about {fmt.duration(self.expected)}, at most about "
                f"{fmt.duration(self.at_most)} (each cell rendering its whole budget and confirmed)")  # fmt: skip


def cell_seconds(spec: AuditSpec, cell: Cell, pixels: int, share: float = 1.0) -> float:
    """The wall seconds a cell's check takes by the estimate's model (`share`: of its budget's passes): its overhead
    and its passes' render seconds (both sides), at most the budget's render seconds."""
    render = 2 * share * spec.max_passes * cell.change.samples * pixels * SAMPLE_SECONDS
    if spec.max_seconds is not None:
        floor = 2 * spec.floor * cell.change.samples * pixels * SAMPLE_SECONDS
        render = max(min(render, spec.max_seconds), floor)
    return CHECK_OVERHEAD + WALL_SHARE * render


def estimate(plan: AuditPlan, done: set[str] = frozenset()) -> Estimate:
    """The estimate of the cells of `plan` not in `done` (their keys): each cell its check, a share of them
    confirmed (`EXPECTED_FINDINGS`), at the image size of the audit (64x64 for a built-in scene, and for a scene
    file whose size is not known before it renders)."""
    width, height = plan.spec.resolution or (64, 64)
    todo = [c for c in plan.cells if c.key not in done]
    expected = sum(cell_seconds(plan.spec, c, width * height, EXPECTED_SHARE) for c in todo)
    at_most = sum(cell_seconds(plan.spec, c, width * height) for c in todo)
    return Estimate(expected * (1 + EXPECTED_FINDINGS), 2 * at_most, len(todo))


# -- an audit file (the suite kind) ---------------------------------------------------------------------------------


def is_audit_file(path: Path | str) -> bool:
    """Whether a suite file is an audit (an ``[audit]`` table) rather than a suite of cases."""
    try:
        return "audit" in _read_toml(Path(path))
    except BatchError:
        return False


@dataclass(frozen=True)
class AuditFile:
    """An audit described by a file: its spec (without the release, which the runner gives) and its path."""

    path: Path
    spec: AuditSpec


def load_audit_file(path: Path | str) -> AuditFile:
    """An audit file: an ``[audit]`` table (its name; `scenes`, built-in ones or ``all``; `blends`, relative to the
    file; `changes`, ``cycles`` for the shipped list or ``none``; `only`, the change names to keep; `resolution`,
    `tile`, `passes` and `seconds` a cell, `alpha`, `tolerance`) and the user's own ``[[change]]`` tables. Every
    problem in one error."""
    path = Path(path)
    data, problems = _read_tables(path, "an audit file has [audit] and [[change]]")
    head = data.get("audit", {})
    if not isinstance(head, dict):
        head, _ = {}, problems.append("[audit] must be a table")
    bad = sorted(set(head) - set(_AUDIT_KEYS))
    if bad:
        problems.append(f"unknown key {bad[0]!r} in [audit] (it takes {', '.join(_AUDIT_KEYS)})")
    shipped = head.get("changes", "cycles")
    if shipped not in ("cycles", "none"):
        problems.append(f"[audit] 'changes' must be 'cycles' (the shipped list) or 'none', got {shipped!r}")
    changes = list(load_changes(BUILTIN_CHANGES)) if shipped == "cycles" else []
    changes += read_changes(data.get("change", []), problems, tuple(c.name for c in changes))
    only = head.get("only")
    if only is not None:
        names = {c.name for c in changes} | {AA.name}
        if not isinstance(only, list) or not all(isinstance(n, str) and n in names for n in only):
            problems.append(f"[audit] 'only' must list changes of the audit ({', '.join(sorted(names))}), got {only!r}")
        else:
            changes = [c for c in changes if c.name in only]
    values = {}
    for key, dest in (("resolution", "resolution"), ("tile", "tile"), ("passes", "max_passes"),
                      ("seconds", "max_seconds"), ("min_passes", "min_passes"), ("alpha", "alpha"),
                      ("tolerance", "tolerance")):  # fmt: skip
        if key in head:
            try:
                values[dest] = options.OPTIONS[dest].convert(f"[audit] {key!r}", head[key])
            except BatchError as exc:
                problems.append(str(exc))
    scenes: tuple[Scene, ...] = ()
    try:
        names = head.get("scenes", [] if head.get("blends") else ["all"])
        blends = [str((path.parent / b).resolve()) for b in head.get("blends", [])]
        scenes = scenes_of(list(names), blends)
    except (BatchError, TypeError) as exc:
        problems.append(f"[audit] {exc}")
    if problems:
        raise BatchError(_problems(path, problems))
    name = head.get("name", path.stem)
    spec = AuditSpec(name=str(name), scenes=scenes, changes=(AA, *changes), **values)
    return AuditFile(path, spec)


def cells_per_row(plan: AuditPlan) -> dict[str, list[Cell]]:
    """The cells of each change (a row of the page), in the plan's order."""
    rows: dict[str, list[Cell]] = {c.name: [] for c in plan.spec.changes}
    for cell in plan.cells:
        rows[cell.change.name].append(cell)
    return rows


def budget_text(spec: AuditSpec) -> str:
    """A cell's budget in words."""
    seconds = f" and {spec.max_seconds:g} s of rendering" if spec.max_seconds is not None else ""
    floor = f" (at least {spec.floor} passes a side whatever their seconds)" if spec.floor is not None else ""
    if spec.resolution:
        size = "x".join(map(str, spec.resolution))
    elif all(s.scene is not None for s in spec.scenes):
        size = "64x64 (the built-in scenes' own size)"
    else:
        size = "each scene's own size (64x64 for a built-in one)"
    tolerance = "off" if spec.tolerance is None else f"±{100 * spec.tolerance:g} %"
    return (f"at most {spec.max_passes} passes a side{seconds} a cell{floor}, {size}, {spec.tile}-px tiles, "
            f"tolerance {tolerance}")  # fmt: skip


def equal_budget_text(spec: AuditSpec) -> str:
    """How every cell's budget is the same, in words (the page and the findings say it)."""
    from .check import FLOOR_LIMIT

    if spec.max_seconds is None:
        return f"every cell's checks render the same {spec.max_passes} passes a side at most"
    return (f"every cell's checks have the same budget: at most {spec.max_passes} passes a side and "
            f"{spec.max_seconds:g} render seconds (both sides together), whichever ends first, and at least "
            f"{spec.floor} passes a side whatever their seconds (up to {FLOOR_LIMIT:g} times the budget): equal in "
            f"render seconds for every cell whose first {spec.floor} passes fit in them, equal in passes for a cell "
            "whose passes are slower (a scene that builds much before its first sample); a cell's samples per pass "
            "are its change's")  # fmt: skip
