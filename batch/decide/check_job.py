"""What a check is: the request (``check``'s command line, the Blender add-on's panel, an audit's case) made into a
`CheckJob`, the two sides' render jobs and the budget, refused in one line where it can't work, before anything
renders. `batch.decide.check` runs it.

Nothing here imports bpy.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError
from ..jobs import options
from ..jobs.job import RenderJob
from ..jobs.options import OPTIONS, TEST_SIDE, default
from ..jobs.pairs import PixelPairs
from ..jobs.samples import BUILTIN, AutoSamples, SceneSamples, auto_samples, side_settings
from ..jobs.seeds import MAX_PASSES
from ..jobs.side import probe_scenes

#: The seeds of an unpaired check's test side start here, whatever the budget (the reference's start at 0): a
#: grown budget extends both sides' seeds and they never overlap.
UNPAIRED_SEEDS = MAX_PASSES  # --max-passes is at most this

#: Passes a side when neither --max-passes nor --max-seconds is given.
DEFAULT_MAX_PASSES = default("max_passes", "check")

#: Seeds a side may use under a time budget (the pass budget is fixed once the speed is known).
MAX_SEEDS_FOR_SECONDS = 100_000


@dataclass(frozen=True)
class CheckJob:
    """A check: the two sides' render jobs (their seeds are the most either may render), the budget (passes a
    side, or render seconds: then the pass budget is fixed from the speed of the first chunk), the verdicts'
    alpha and tolerance, and the output folder."""

    reference: RenderJob
    test: RenderJob
    out: str
    max_passes: int | None = DEFAULT_MAX_PASSES
    max_seconds: float | None = None
    #: The fewest passes a side a time budget renders, whatever their seconds (None: none; a check whose budget
    #: ends its first passes then ends `inconclusive`, too few to look at): a scene whose first pass builds much
    #: (Cycles 5's volume octree) still gets a few passes.
    min_passes: int | None = None
    alpha: float = default("alpha", "check")
    tolerance: float | None = default("tolerance", "check")
    equivalence_tile: int | None = None  # claim `equivalent` at this tile size (default: sized for the budget)
    futility: bool = True  # stop once neither claim is within the budget's reach (welch_core.decision)
    futility_loss: float = default("futility_loss", "check")  # ...giving up at most this power
    pixel_variance: str = default("pixel_variance", "check")  # the pixel-variance test (welch_core.pixels)
    resume: bool = False
    #: The reference is a finished statistics file (a suite's blessed reference), not rendered: only the test
    #: side renders, and the looks' information fractions count its passes against the reference's fixed ones.
    fixed_reference: bool = False
    #: Render the passes on a Dask cluster (batch.jobs.distributed): local worker processes, or a running cluster.
    workers: int | None = None
    scheduler: str | None = None
    seed_offset: int = 0  # both sides' seeds shifted by it (--seed-offset): another, independent check
    auto_samples: dict | None = None  # why --spp auto renders more than 1 sample a pass (`AutoSamples.to_json`)

    def plan(self, max_passes: int, early_share: float | None = None, started: dict | None = None) -> wc.SequentialPlan:
        """The design for `max_passes`; a resumed check keeps the early share it was started with (None: the
        default), and one `started` (its stored plan) before the pixel-variance test existed goes on without it."""
        # The design's fields of one name: alpha, the tolerance, the claim, the futility stop, the pixel test.
        design = {f.name: getattr(self, f.name) for f in dataclasses.fields(wc.SequentialPlan) if hasattr(self, f.name)}
        design["max_passes"] = max_passes
        if early_share is not None:
            design["early_share"] = early_share
        if started is not None and "pixel_variance" not in started:
            design["pixel_variance"] = "off"
        return wc.SequentialPlan(**design)

    @property
    def paired(self) -> bool:
        return self.reference.seeds == self.test.seeds


def sides_identical(reference: RenderJob, test: RenderJob) -> bool:
    """Both sides render the same scene the same way with the same seeds: every difference would be zero."""
    fields = (
        "blend",
        "scene",
        "blend_scene",
        "resolution",
        "device",
        "sampling_pattern",
        "overrides",
        "blender",
        "python",
        "spp",
        "command",
        "command_dir",
    )
    same = all(getattr(reference, f) == getattr(test, f) for f in fields)
    return same and reference.seeds == test.seeds


def _absolute(path: str | None) -> str | None:
    """A scene file's path as its sides record it: absolute, so a check resumed from another folder is the same."""
    return None if path is None else os.path.abspath(path)


@dataclass(frozen=True)
class CheckRequest:
    """What a check is asked for, as the command line (``check``'s arguments: `from_args`) and the Blender add-on
    give it, values already checked; `check_job` makes the check of it. The defaults are the command line's
    (`batch.jobs.options`)."""

    out: str
    blend: str | None = None
    scene: str | None = None
    blend_scene: str | None = None
    test_blend: str | None = None
    test_blend_scene: str | None = None
    overrides: tuple[str, ...] = ()  # the test side's
    #: The reference side's own overrides (the command line gives it none: its scene holds its values; a suite
    #: case's overrides are both sides', an audit sets each side's value of the change explicitly).
    reference_overrides: tuple[str, ...] = ()
    #: A finished statistics file as the reference (a suite's blessed one): only the test side renders, on the
    #: seeds after the reference's, and the reference's device is the one it was rendered on.
    reference_stats: str | None = None
    spp: int | None = default("spp", "check")  # None: auto (`batch.jobs.samples.auto_samples`)
    tile: int = default("tile", "check")
    resolution: tuple[int, int] | None = None
    device: str = default("device", "check")
    sampling_pattern: str | None = None
    lobes: tuple[str, ...] = default("lobes", "check")
    test_spp: int | None = None
    test_device: str | None = None
    test_sampling_pattern: str | None = None
    blender: str | None = None
    python: str | None = None
    test_blender: str | None = None
    test_python: str | None = None
    pass_command: str | None = None
    test_pass_command: str | None = None
    command_dir: str | None = None
    max_passes: int | None = None  # None: DEFAULT_MAX_PASSES, unless max_seconds is given
    max_seconds: float | None = None
    min_passes: int | None = None
    alpha: float = default("alpha", "check")
    tolerance: float | None = default("tolerance", "check")
    equivalence_tile: int | None = None
    futility: bool = True
    futility_loss: float = default("futility_loss", "check")
    pixel_variance: str = default("pixel_variance", "check")
    unpaired: bool = False
    seed_offset: int = default("seed_offset", "check")
    resume: bool = False
    workers: int | None = None
    scheduler: str | None = None

    def to_argv(self) -> list[str]:
        """``check``'s arguments that ask for this request (`from_args` of them is this request, but for the fields
        the command line has no option for: a finished reference, the reference's overrides): each field that is
        not its default, as its declared option writes it; the scene file first, --out last."""
        fields = sorted(dataclasses.fields(self), key=lambda f: (f.name != "blend", f.name == "out"))
        argv = []
        for field in fields:
            value = getattr(self, field.name)
            if field.name in _NOT_ARGUMENTS or value == field.default:
                continue
            own = field.name.removeprefix("test_")  # the test side's own value of an option (--test-spp)
            if own != field.name and own in TEST_OPTIONS:
                argv += options.to_argv(OPTIONS[own], value, "test")
            else:
                argv += options.to_argv(OPTIONS[field.name], value)
        return argv

    @classmethod
    def from_args(cls, args) -> CheckRequest:
        """The request of ``check``'s parsed command line (the fields it has no option for keep their defaults:
        a finished reference, the reference's overrides)."""
        return cls(**{f.name: getattr(args, f.name) for f in dataclasses.fields(cls) if f.name not in _NOT_ARGUMENTS})


#: The request's fields that ``check``'s command line does not give.
_NOT_ARGUMENTS = ("reference_overrides", "reference_stats")

#: The options whose test side ``check`` takes (``--test-spp``, ``--test-blender``...), by destination.
TEST_OPTIONS = tuple(dest for dest, o in OPTIONS.items() if "check" in o.uses and "test" in o.sides)


def check_job_from_args(args) -> CheckJob:
    """The check the command line describes (`check_job` of its `CheckRequest`)."""
    return check_job(CheckRequest.from_args(args))


def _check_claim_tile(claim: int | None, tile: int, resolution) -> None:
    """Refuse an --equivalence-tile the check will not test (its tested sizes: the tile times 1, 2, 4, ... up to
    the first that covers the image, `welch_core.comparison.scale_factors`) before anything renders."""
    if claim is None:
        return
    factor = claim // tile
    sizes = ", ".join(str(tile << k) for k in range(3))
    if claim % tile or factor & (factor - 1) or factor < 1:
        raise BatchError(f"--equivalence-tile {claim} is not a tested tile size: the tile ({tile}) times a power of "
                         f"two ({sizes}, ...)")  # fmt: skip
    if resolution and factor > 1 and claim >= 2 * max(resolution):
        raise BatchError(f"--equivalence-tile {claim} is larger than the image ({resolution[0]}x{resolution[1]})")


def _refuse(args: CheckRequest) -> None:
    """What can't work, refused in one line before anything renders."""
    if args.blend is not None and args.scene is not None:
        raise BatchError(f"give a .blend file or a built-in scene, not both ({args.blend}, {args.scene!r})")
    if args.test_pass_command and not args.pass_command:
        raise BatchError("--test-command needs --command: the reference side's passes are rendered the same way")
    if args.blend is None and args.scene is None and not args.pass_command:
        raise BatchError("no scene to check: give a .blend file or a built-in scene (--scene), or --command")
    for option, path in (("SCENE.blend", args.blend), ("--test-blend", args.test_blend)):
        if path is not None and not Path(path).is_file():
            raise BatchError(f"{option} {path}: no such file")
    if args.min_passes is not None and args.max_seconds is None:
        raise BatchError("--min-passes is the floor of a time budget: give --max-seconds too (without it every pass "
                         "of --max-passes renders)")  # fmt: skip
    if args.min_passes is not None and args.max_passes is not None and args.min_passes > args.max_passes:
        raise BatchError(f"--min-passes {args.min_passes} is more than --max-passes {args.max_passes}")
    _check_claim_tile(args.equivalence_tile, args.tile, args.resolution)
    if (args.blender and args.python) or (args.test_blender and args.test_python):
        raise BatchError("give a side's build as a Blender binary or as a Python with bpy, not both (--blender or "
                         "--python; --test-blender or --test-python)")  # fmt: skip


def check_job(request: CheckRequest, probe=None) -> CheckJob:
    """The check `request` describes, refused in one line where it can't work, before anything renders. `probe`
    reads what scene files ask of the passes for ``--spp auto`` (default `batch.jobs.side.probe_scenes`: a process
    of each side's build opens its file; the add-on reads its own scenes)."""
    args = request
    _refuse(args)
    max_passes = None if args.max_seconds is not None else (args.max_passes or DEFAULT_MAX_PASSES)
    # A time budget renders at most --max-passes where given too (whichever ends first): its pass budget, fixed from
    # the speed of the first chunk, is at most the seeds a side has.
    count = args.max_passes or max_passes or MAX_SEEDS_FOR_SECONDS
    # The test side's build: its own, else the reference's (a binary given to one side is not the other's Python).
    test_blender = args.test_blender or (None if args.test_python else args.blender)
    test_python = args.test_python or (None if args.test_blender else args.python)
    same_build = test_blender == args.blender and test_python == args.python and (
        args.test_pass_command or args.pass_command
    ) == args.pass_command  # fmt: skip
    paired = same_build and not args.unpaired
    offset = args.seed_offset
    ref_seeds = range(offset, offset + count)
    test_seeds = ref_seeds if paired else range(UNPAIRED_SEEDS + offset, UNPAIRED_SEEDS + offset + count)
    fixed = {}  # a finished reference: its file, seeds and device
    if args.reference_stats is not None:
        stored = wc.load_stats(args.reference_stats, pixels=False)
        ref_seeds, first = stored.seeds, max(stored.seeds) + 1 + offset
        test_seeds, paired = range(first, first + count), False
        fixed = {"out": args.reference_stats, "device": stored.info.device or "CPU", "resume": False}
    out = Path(args.out)
    common = {
        "spp": args.spp or 1,  # auto: resolved below
        "tile": args.tile,
        "resolution": tuple(args.resolution) if args.resolution else None,
        "device": args.device,
        "sampling_pattern": args.sampling_pattern,
        "resume": args.resume,
        "checkpoint_every": MAX_PASSES,  # saved after every chunk anyway (and the same whatever the budget)
        "lobes": args.lobes,
        "command_dir": str(Path(args.command_dir or ".").resolve()) if args.pass_command else None,
    }
    reference = RenderJob(
        out=str(out / "reference.npz"),
        seeds=tuple(ref_seeds),
        blend=_absolute(args.blend),
        scene=args.scene,
        blend_scene=args.blend_scene,
        blender=args.blender,
        python=args.python,
        overrides=tuple(args.reference_overrides),
        command=args.pass_command,
        **common,
    ).replace(**fixed)
    own = {dest: value for dest in TEST_SIDE if (value := getattr(args, f"test_{dest}", None)) is not None}
    test = RenderJob(
        out=str(out / "test.npz"),
        seeds=tuple(test_seeds),
        blend=_absolute(args.test_blend or args.blend),
        scene=None if args.test_blend else args.scene,
        blend_scene=args.test_blend_scene or (None if args.test_blend else args.blend_scene),
        blender=test_blender,
        python=test_python,
        overrides=tuple(args.overrides),
        command=args.test_pass_command or args.pass_command,
        **(common | own),
    )
    if sides_identical(reference, test):
        raise BatchError(
            "the two sides are identical by construction (same scene, build, settings and seeds): every difference "
            "would be zero; give --set, --test-blend, --test-blender, --test-command or a --test- setting such as "
            "--test-sampling-pattern, or --unpaired for an A/A check"
        )
    if not args.resume:
        for job in (reference, test)[1 if fixed else 0 :]:
            if Path(job.out).exists():
                raise BatchError(f"{job.out} already exists: pass --resume to continue the check, or another --out")
    auto = AutoSamples(args.spp) if args.spp is not None else _auto_samples(reference, test, probe)
    reference = reference.replace(spp=auto.spp)
    test = test.replace(spp=own.get("spp", auto.spp))
    if paired and args.pixel_variance != "off" and args.workers is None and args.scheduler is None:
        # Each side also writes its passes' images: the pixel test of paired runs needs each pixel's difference.
        reference = reference.replace(pass_images=PixelPairs.folder(out, "reference"))
        test = test.replace(pass_images=PixelPairs.folder(out, "test"))
    # The request's values the job carries as they are: its fields of the same name (the budget, alpha, tolerance,
    # the claim, the stops, resuming, the cluster, the seed offset).
    carried = {f.name: getattr(args, f.name) for f in dataclasses.fields(CheckJob) if hasattr(args, f.name)}
    made = {"reference": reference, "test": test, "out": str(out), "max_passes": max_passes}
    return CheckJob(**carried | made, fixed_reference=bool(fixed), auto_samples=auto.to_json())


def _auto_samples(reference: RenderJob, test: RenderJob, probe=None) -> AutoSamples:
    """``--spp auto`` (`batch.jobs.samples.auto_samples`): what each side's scene asks of the passes (a built-in
    scene's is known; each scene file is read once, by `probe`), with the test side's pattern and overrides.
    Another renderer's passes (``--command``) take 1 sample."""
    if reference.command is not None:
        return AutoSamples(1)
    files = {}  # each scene file by what reads it: the file, its scene and the build
    for name, job in (("reference", reference), ("test", test)):
        if job.scene is None:
            read = job.replace(seeds=(0,), spp=1, overrides=(), sampling_pattern=None, lobes=(), pass_images=None)
            files.setdefault((job.blend, job.blend_scene, job.blender, job.python), (name, read))
    found = dict(zip(files, (probe or probe_scenes)(list(files.values())), strict=True))
    scenes: list[SceneSamples] = [
        BUILTIN if job.scene is not None else found[(job.blend, job.blend_scene, job.blender, job.python)]
        for job in (reference, test)
    ]
    settings = [
        side_settings(scene, job.sampling_pattern, job.overrides)
        for scene, job in zip(scenes, (reference, test), strict=True)
    ]
    return auto_samples(*scenes, *settings)
