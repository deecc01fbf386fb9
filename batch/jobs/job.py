"""A render job, defined once: what to render, how, and where its statistics go.

The job is the contract between everything that starts renders (the command line, the Blender add-on's
background runs, a launcher that runs another Blender binary, workers) and the code that renders. It imports
neither Blender nor scipy. Its command-line form is defined here too: `add_arguments` declares the options,
`RenderJob.from_args` reads them back and `RenderJob.to_argv` writes a job as arguments of ``render``, so a job
survives the trip through a subprocess unchanged.
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass

from ..errors import BatchError
from . import options
from .lobes import LOBES
from .options import DEVICES, ON_NAN, add_options, default
from .seeds import MAX_PASSES
from .template import words

#: The built-in scenes (`batch.blender.scenes.SCENES` builds them; a test holds the two together), named here so
#: that a job or a suite naming another one is refused before anything starts.
BUILTIN_SCENES = (
    "corner", "corner_glass", "corner_mesh_light", "glossy", "glossy_rough", "glossy_sharp", "many_lights",
    "environment", "volume", "volume_noise", "sss", "depth_of_field", "motion_blur", "hair", "textured",
)  # fmt: skip

#: Scenes rebuilt since the builders' version (`batch.blender.scenes.BUILDER_VERSION`): their revision is part of
#: their identity, so a reference of the scene as it was is not taken for one of the scene as it is.
SCENE_REVISIONS = {"many_lights": 2}  # 2: its back rows of lights were on and behind the back wall


def builtin_scene_id(name: str, builder_version: int = 1) -> str:
    """What fixes a built-in scene's content in a run record: ``builtin:<name>:<revision>``."""
    return f"builtin:{name}:{SCENE_REVISIONS.get(name, builder_version)}"


#: How a job that asked for a GPU this machine lacks fails (a suite skips such a case with this reason).
NO_GPU_MESSAGE = "Cycles found no GPU"

#: A pass with NaN/inf pixels: stop the run (what was accumulated is kept), skip the pass, or keep it (its
#: tiles are excluded from the test with the reason non_finite).

#: The sampling pattern of a built-in scene, the first this Blender has: Cycles' tabulated Sobol (the startup
#: file's pattern), else the Sobol variant an older Blender has. A scene file renders with its own pattern unless
#: the job gives one; what was used is recorded with the run.
DEFAULT_SAMPLING_PATTERNS = ("TABULATED_SOBOL", "SOBOL_BURLEY", "SOBOL")


@dataclass(frozen=True)
class RenderJob:
    """One run: one pass per seed of one configuration, accumulated into the statistics file `out`.

    Exactly one of `blend` (a .blend file) and `scene` (a built-in scene) names the scene; neither means the file
    the running Blender has open. `blender`, if set, is the Blender executable that renders the job (the job is
    handed to it as arguments), and `python` a Python interpreter whose environment has some release's bpy module
    (the job runs in it as ``python -m batch render``); otherwise the job renders in this process through bpy.
    """

    out: str
    seeds: tuple[int, ...]
    spp: int = default("spp", "render")
    blend: str | None = None
    scene: str | None = None
    blend_scene: str | None = None
    tile: int = default("tile", "render")
    resolution: tuple[int, int] | None = None
    device: str = default("device", "render")
    sampling_pattern: str | None = None
    overrides: tuple[str, ...] = ()
    resume: bool = False
    on_nan: str = default("on_nan", "render")
    checkpoint_every: int = default("checkpoint_every", "render")
    blender: str | None = None
    lobes: tuple[str, ...] = ()  # light components and light groups accumulated as layers (batch.lobes)
    python: str | None = None  # a Python whose environment has a bpy module (another release) to render in
    command: str | None = None  # a command that renders one pass into an EXR, instead of Cycles (batch.jobs.command)
    command_dir: str | None = None  # the folder the command runs in (default: the current one)
    pass_images: str | None = None  # also write each pass's image here (a paired check's pixels, batch.jobs.pairs)

    def __post_init__(self):
        object.__setattr__(self, "seeds", tuple(self.seeds))
        object.__setattr__(self, "overrides", tuple(self.overrides))
        object.__setattr__(self, "lobes", tuple(self.lobes))
        unknown = [lobe for lobe in self.lobes if lobe not in LOBES]
        if unknown:
            raise BatchError(f"--lobes takes 'all' or some of {','.join(LOBES)}, got {unknown[0]!r}")
        if self.resolution is not None:
            object.__setattr__(self, "resolution", tuple(self.resolution))
        if not self.seeds:
            raise BatchError("a render job needs at least one seed")
        if len(self.seeds) > MAX_PASSES:
            raise BatchError(f"a run takes at most {MAX_PASSES} seeds, got {len(self.seeds)}")
        if self.blend is not None and self.scene is not None:
            raise BatchError(f"give a .blend file or a built-in scene, not both ({self.blend}, {self.scene!r})")
        if self.scene is not None and self.scene not in BUILTIN_SCENES:
            raise BatchError(f"unknown built-in scene {self.scene!r}; choose from {', '.join(BUILTIN_SCENES)}")
        _check_declared("spp", self.spp)
        _check_declared("tile", self.tile)
        _check_range("--checkpoint-every", self.checkpoint_every, 1, MAX_PASSES)
        if self.resolution is not None:
            if len(self.resolution) != 2:
                raise BatchError(f"--resolution takes a width and a height, got {self.resolution}")
            for side in self.resolution:
                _check_declared("resolution", side)
            if self.tile > min(self.resolution):
                width, height = self.resolution
                raise BatchError(f"--tile {self.tile} is larger than the image {width}x{height}")
        if self.blender is not None and self.python is not None:
            raise BatchError(f"give --blender or --python, not both ({self.blender}, {self.python})")
        if self.device not in DEVICES:
            raise BatchError(f"--device must be one of {', '.join(DEVICES)}, got {self.device!r}")
        if self.on_nan not in ON_NAN:
            raise BatchError(f"--on-nan must be one of {', '.join(ON_NAN)}, got {self.on_nan!r}")
        if self.command is not None:
            self._check_command()

    def _check_command(self) -> None:
        if self.overrides and "{set}" not in words(self.command):
            raise BatchError(f"--command {self.command!r} has no {{set}} for the overrides {list(self.overrides)}")
        cycles = {"a scene": self.blend or self.scene or self.blend_scene, "--blender": self.blender,
                  "--python": self.python, "--sampling-pattern": self.sampling_pattern, "--lobes": self.lobes,
                  "--resolution": self.resolution, "--device": self.device != "CPU"}  # fmt: skip
        given = [name for name, value in cycles.items() if value]
        if given:
            raise BatchError(f"--command renders the passes itself: {given[0]} does not apply to it")

    def replace(self, **changes) -> RenderJob:
        return dataclasses.replace(self, **changes)

    # -- the command-line form -------------------------------------------------------------------------------

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> RenderJob:
        """The job described by arguments parsed with a parser that `add_arguments` set up (a field whose option
        the parser lacks keeps its default)."""
        return cls(**{field: getattr(args, dest) for field, dest in ARGUMENTS if hasattr(args, dest)})

    def to_argv(self) -> list[str]:
        """The arguments of ``render`` that describe this job (what `from_args` reads back): each field in the
        order of `ARGUMENTS`, as its declared option writes it, where it is set (`ALWAYS_WRITTEN`: even at its
        default); the scene file first, as the positional argument."""
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        argv = []
        for field, dest in ARGUMENTS:
            value = getattr(self, field)
            unset = value is None or value is False or value == ()
            if unset or (field not in ALWAYS_WRITTEN and value == defaults[field]):
                continue
            argv += options.to_argv(options.OPTIONS[dest], value)
        return argv


#: A job's fields in the order `to_argv` writes them, each with the option (its dest in `options.OPTIONS`) that
#: carries it on the command line. A check's state records its sides' arguments: the order is part of the record.
ARGUMENTS = (
    ("blend", "blend"), ("scene", "scene"), ("blend_scene", "blend_scene"), ("seeds", "seeds"), ("spp", "spp"),
    ("tile", "tile"), ("resolution", "resolution"), ("device", "device"), ("sampling_pattern", "sampling_pattern"),
    ("overrides", "overrides"), ("resume", "resume"), ("on_nan", "on_nan"), ("checkpoint_every", "checkpoint_every"),
    ("blender", "blender"), ("lobes", "lobes"), ("python", "python"), ("command", "pass_command"),
    ("command_dir", "command_dir"), ("pass_images", "pass_images"), ("out", "out"),
)  # fmt: skip
#: The fields written even at their defaults (what renders the passes, where they go).
ALWAYS_WRITTEN = ("seeds", "spp", "tile", "device", "out")


def _check_declared(dest: str, value) -> None:
    """A number of a job made in code within its option's declared limits."""
    option = options.OPTIONS[dest]
    _check_range(option.flag, value, option.low, option.high)


def _check_range(option: str, value, low: int, high: int) -> None:
    if isinstance(value, str):  # a job made in code: an int, or refused
        raise BatchError(f"{option} must be an integer in {low}..{high}, got {value!r}")
    options.integer(option, value, low, high)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of a render job (the ``render`` command's) as `batch.jobs.options` declares them."""
    declared = ("blend", "scene", "seeds", "blend_scene", "spp", "tile", "resolution", "device", "sampling_pattern",
                "overrides", "lobes", "blender", "python", "pass_command", "command_dir", "resume", "on_nan",
                "checkpoint_every", "out", "pass_images")  # fmt: skip
    add_options(parser, "render", declared)
