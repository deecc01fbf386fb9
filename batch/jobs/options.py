"""The options of a job and of a check, declared once: each `Option` says its name on the command line and in a
suite file, its type and limits, its default, its help, which commands take it (with the default and help a
command gives it where they differ) and whether the test side of a check takes its own value. The command
line's parsers (`add_options`), a suite file's case keys and defaults (`from_mapping`, `default`), its ``[suite]``
table (`from_suite_table`) and the Blender add-on's properties read them here, and one function checks each value
however it arrives (a string on the command line, a TOML value, a panel property), with the same one-line error
naming the option as the user wrote it (``--spp`` on the command line, ``'spp'`` in a suite file, ``[suite]
alpha`` in its table).

The places an option is taken: a command's name as ``python -m batch`` spells it (``render``, ``check``, ``suite
run``...), ``case`` (a suite file's case, under the option's `Option.key`) and ``addon`` (the Blender add-on's
panel, under the option's `Option.dest`).
"""

from __future__ import annotations

import argparse
import math
import os
import weakref
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from ..errors import BatchError
from .lobes import LOBES, parse_lobes
from .seeds import MAX_PASSES, MAX_SEED, format_seeds, parse_seeds

#: The p-values' methods (`welch_core.ttest.PVALUE_METHODS`; this module stays free of numpy for the add-on).
PVALUE_METHODS = ("exact", "gauss", "as_erf")

#: Cycles' largest render side (it clamps larger values) and largest samples per pixel (2**24).
MAX_RESOLUTION = 65536
MAX_SPP = 2**24
#: Seconds a budget may be: a week of rendering is far beyond any check (and `inf` is no budget).
MAX_SECONDS = 7 * 24 * 3600.0
#: The largest tolerance, as a fraction (1000 %).
MAX_TOLERANCE = 10.0
#: The smallest tolerance (0.001 %): ten times float rounding, below which differences count as none
#: (`welch_core.comparison.MIN_TOLERANCE`; this module stays free of numpy for the add-on's registration).
MIN_TOLERANCE = 1e-5
#: The largest seed offset: an unpaired check's test seeds (from `MAX_PASSES`, `batch.decide.check`) and a
#: budget of `MAX_PASSES` after it stay within Cycles' seeds.
MAX_SEED_OFFSET = MAX_SEED + 1 - 2 * MAX_PASSES
#: The most local worker processes (--workers): far more than any machine's cores.
MAX_WORKERS = 4096

#: The devices a job may ask for: the CPU, the first GPU backend that has a device, or one backend.
GPU_BACKENDS = ("OPTIX", "CUDA", "HIP", "METAL", "ONEAPI")
DEVICES = ("CPU", "GPU", *GPU_BACKENDS)
#: The pixel-variance test's modes (`welch_core.PIXEL_MODES`; spelled here so that the add-on's registration, which
#: reads these declarations, imports nothing of the statistics; a test holds the two equal).
PIXEL_MODES = ("auto", "on", "off")
#: What a pass with NaN or inf pixels does to a run (`batch.jobs.passes`).
ON_NAN = ("stop", "skip", "keep")


# -- values ------------------------------------------------------------------------------------------------------


def integer(name: str, value, low: int, high: int) -> int:
    """An integer in low..high, from an int or from its decimal text; anything else (a float such as ``1e9``, a
    bool, out of range) raises BatchError naming `name`."""
    number = value
    if isinstance(value, str):
        text = value.strip()
        number = int(text) if text.lstrip("+-").isdigit() and len(text) <= 20 else None
    if isinstance(number, bool) or not isinstance(number, int) or not low <= number <= high:
        raise BatchError(f"{name} must be an integer in {low}..{high}, got {_show(value)}")
    return number


def _number(value) -> float | None:
    """A number from a number or its text; None for anything else (a bool, other text)."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return None
    return None if isinstance(value, bool) or not isinstance(value, int | float) else float(value)


def seconds(name: str, value, high: float = MAX_SECONDS) -> float:
    """A positive, finite number of seconds (at most `high`), from a number or its text."""
    number = _number(value)
    if number is None or not 0 < number <= high:
        raise BatchError(f"{name} must be a number of seconds in (0, {high:.0f}], got {_show(value)}")
    return number


def percentage(name: str, value, high: float = MAX_TOLERANCE) -> float:
    """A relative difference written as a percentage, ``0.5%``, as a fraction (0.005), in (0 %, `high`)."""
    text = value.strip() if isinstance(value, str) else None
    number = math.nan
    if text is not None and text.endswith("%"):
        try:
            number = float(text[:-1]) / 100.0
        except ValueError:
            pass
    if 0.0 < number < MIN_TOLERANCE:
        raise BatchError(f"{name} must be at least {100 * MIN_TOLERANCE:g}% (a smaller relative difference is float "
                         f"rounding), got {_show(value)}")  # fmt: skip
    if not 0.0 < number < high:
        raise BatchError(f"{name} must be a percentage such as 0.5%, got {_show(value)}")
    return number


def probability(name: str, value) -> float:
    """A number in (0, 1) (a false-positive rate), from a number or its text."""
    number = _number(value)
    if number is None or not 0 < number < 1:
        raise BatchError(f"{name} must be a number in (0, 1), got {_show(value)}")
    return number


def choice(name: str, value, choices: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise BatchError(f"{name} must be one of {', '.join(choices)}, got {_show(value)}")
    return value


def text(name: str, value) -> str:
    """A non-empty line of text (a name, a path): no control characters, which would break a report or a file."""
    if not isinstance(value, str) or not value.strip() or any(ord(c) < 32 or ord(c) == 127 for c in value):
        raise BatchError(f"{name} must be a non-empty line of text, got {_show(value)}")
    return value


def _show(value) -> str:
    shown = repr(value)
    return shown if len(shown) <= 60 else shown[:57] + "..."


def _resolution(name: str, value, low: int, high: int):
    items = value.split() if isinstance(value, str) else value
    if not isinstance(items, list | tuple) or len(items) != 2:
        raise BatchError(f"{name} must be a width and a height in pixels, got {_show(value)}")
    return tuple(integer(name, v, low, high) for v in items)


def _lobes(name: str, value) -> tuple[str, ...]:
    try:
        return parse_lobes(value if isinstance(value, str) else ",".join(value))
    except (BatchError, TypeError):
        raise BatchError(f"{name} takes 'all' or some of {','.join(LOBES)}, got {_show(value)}") from None


def _names(name: str, value) -> tuple[str, ...]:
    """Names separated by commas (``NAME,...``), or a list of them."""
    items = value.split(",") if isinstance(value, str) else value
    if not isinstance(items, list | tuple):
        raise BatchError(f"{name} must be names separated by commas, got {_show(value)}")
    return tuple(text(name, item).strip() for item in items if str(item).strip())


def _seeds(name: str, value) -> list[int]:
    try:
        return parse_seeds(value)
    except ValueError as exc:
        raise BatchError(f"{name} {str(exc).removeprefix('--seeds ')}") from None


def _override(name: str, value) -> str:
    from .overrides import OverrideError, parse_override

    value = text(name, value)
    try:
        parse_override(value)
    except OverrideError as exc:
        raise BatchError(f"{name} {value!r}: {exc.reason}") from None
    return value


#: How each kind of option checks a value: (the option, the name to show, the value) -> the value, or BatchError.
KINDS: dict[str, Callable[[Option, str, Any], Any]] = {
    "integer": lambda o, n, v: integer(n, v, o.low, o.high),
    "resolution": lambda o, n, v: _resolution(n, v, o.low, o.high),
    "seconds": lambda o, n, v: seconds(n, v, o.high),
    "percentage": lambda o, n, v: percentage(n, v, o.high),
    "probability": lambda o, n, v: probability(n, v),
    "choice": lambda o, n, v: choice(n, v, o.choices),
    "text": lambda o, n, v: text(n, v),
    "lobes": lambda o, n, v: _lobes(n, v),
    "override": lambda o, n, v: _override(n, v),
    "seeds": lambda o, n, v: _seeds(n, v),
    "flag": lambda o, n, v: bool(v),  # given or not: no value to check
    "names": lambda o, n, v: _names(n, v),
    "switch": lambda o, n, v: choice(n, v, tuple(const for _flag, const, _help in o.switches)),
}
#: The kinds whose limits exclude the bounds themselves: (low, high) open or half-open, as their errors say.
OPEN_LOW = ("seconds", "percentage", "probability")
OPEN_HIGH = ("percentage", "probability")


# -- the declaration ---------------------------------------------------------------------------------------------

#: A `Use` that keeps the option's own default.
SAME: Any = "<the option's default>"


@dataclass(frozen=True)
class Use:
    """How one place takes an option, where it differs from the option's declaration: its default (`SAME`: the
    option's), its help (None: the option's; ``{default}`` in it is replaced by the default, else a default that
    is not None is added as ``(default X)``), `required` (no default), `deferred` (the parser leaves None and the
    command applies the default itself: --max-passes only without --max-seconds), the help of the test side's
    flag where it has one of its own (`test_help`) and whether the place takes ``auto`` (`auto`: None, which the
    command resolves; a panel's property shows it as 0)."""

    default: Any = SAME
    help: str | None = None
    required: bool = False
    deferred: bool = False
    test_help: str | None = None
    auto: bool = False  # ``auto`` is a value here: None, which the command resolves (check's --spp)
    metavar: str | None = None  # what the value is here, where the option's own does not say it (--out DIR)
    nargs: str | None = None  # argparse's: ``?`` an optional positional, ``+`` and ``*`` a list in one flag
    exclusive: str | None = None  # the options of one name here are mutually exclusive (--workers, --scheduler)


_USE = Use()


@dataclass(frozen=True)
class Option:
    """One option: its destination (a `RenderJob` or check field, an add-on property), its command-line flag (a
    positional argument's: its name as shown, without ``-``), its key in a suite case (None: not there), its kind
    (`KINDS`: how a value is checked) with its limits (`low` and `high` for numbers, `choices`), its default, its
    help, the places that take it (`uses`: place -> `Use`) and the sides of a check that take their own value
    (``test``: ``--test-blender``; for an option that only `draws` the passes also a suite case's ``test_spp``)."""

    dest: str
    flag: str
    key: str | None
    kind: str
    help: str
    default: Any = None
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    metavar: str | None = None
    many: bool = False  # repeatable on the command line (append), a list in a suite case
    number: bool = False  # a number (text only on the command line: a suite file's "4" is a mistake)
    off: bool = False  # ``off`` on the command line is None (no such limit)
    uses: Mapping[str, Use] = field(default_factory=dict)
    sides: tuple[str, ...] = ("reference",)
    draws: bool = False  # changes only how the passes are drawn: both sides converge to the same image
    #: A `switch`'s flags, each with the value it stores and its help (compare's --paired and --unpaired).
    switches: tuple[tuple[str, str, str], ...] = ()

    @property
    def positional(self) -> bool:
        return not self.flag.startswith("-")

    def convert(self, name: str, value):
        """`value` checked (the value itself, or a tuple for a resolution and lobes), or BatchError naming `name`."""
        return KINDS[self.kind](self, name, value)

    def use(self, place: str) -> Use:
        try:
            return self.uses[place]
        except KeyError:
            raise KeyError(f"{self.flag} is not declared for {place}") from None

    def default_for(self, place: str):
        """The default `place` gives the option (the option's own unless the place says otherwise)."""
        use = self.use(place)
        return self.default if use.default is SAME else use.default

    def show(self, value) -> str:
        """A value as a user writes it (a tolerance of 0.01 as ``1%``)."""
        return f"{value * 100:g}%" if self.kind == "percentage" else str(value)

    @property
    def open_low(self) -> bool:
        return self.kind in OPEN_LOW

    @property
    def open_high(self) -> bool:
        return self.kind in OPEN_HIGH

    def admits(self, number: float) -> bool:
        """Whether a number is within the limits (for a test of what another place allows)."""
        low_ok = self.low is None or (self.low < number if self.open_low else self.low <= number)
        high_ok = self.high is None or (number < self.high if self.open_high else number <= self.high)
        return low_ok and high_ok


#: The commands that render a job of their own settings, and the places that take a job's setting.
_RENDERING = ("render", "check", "matrix", "bisect")
_JOB = (*_RENDERING, "case")
#: The sides of an option that the test side of a check may set apart.
_BOTH = ("reference", "test")

#: The commands that render on a Dask cluster where asked (--workers, --scheduler).
_CLUSTERED = ("render", "check", "suite run", "audit")

#: The help of --pixel-variance, before what each place says of paired runs.
_PIXEL_HELP = (
    "test a tile by its pixels' variances where they are independent, far fewer passes at small counts: auto where "
    "both runs' records prove it (Cycles passes this tool rendered, a sampling pattern measured independent, "
    "scrambling distance 1), on to vouch for another renderer, off for the tile test everywhere"
)

#: The help of matrix's and bisect's --tolerance.
_MATRIX_TOLERANCE = "also say `equivalent` where every finest tile is within it (default: off)"

OPTIONS = {
    option.dest: option
    for option in (
        Option(
            "spp",
            "--spp",
            "spp",
            "integer",
            "samples per pixel per pass",
            default=1,
            low=1,
            high=MAX_SPP,
            number=True,
            sides=_BOTH,
            draws=True,
            uses=dict.fromkeys(_JOB, _USE)
            | {
                "render": Use(required=True, help=f"samples per pixel per pass (at most {MAX_SPP})"),
                "ingest": Use(required=True, help="samples per pixel of each pass"),
                "check": Use(
                    None,
                    "samples per pixel per pass, or auto (default {default}): 1, unless the sides differ in a "
                    "setting that acts only above some samples per render (path guiding, a blue-noise or "
                    "Sobol-Burley pattern, automatic scrambling distance): then the scene files' own samples, and "
                    "at least those it acts at; a scene file is opened once to read them",
                    auto=True,
                ),
                "addon": Use(None, auto=True),
            },
        ),
        Option(
            "tile",
            "--tile",
            "tile",
            "integer",
            "finest tile edge in pixels",
            default=16,
            low=1,
            high=MAX_RESOLUTION,
            number=True,
            uses=dict.fromkeys((*_JOB, "addon"), _USE)
            | {
                "render": Use(32, "tile edge in pixels"),
                "ingest": Use(32, "tile edge in pixels"),
                **dict.fromkeys(
                    ("compare", "selftest"),
                    Use(
                        None,
                        "test only this tile size (a multiple of the stored one); default: the stored size and "
                        "every multiple 2x, 4x, ... that fits the image",
                    ),
                ),
                "matrix": Use(help="tile edge in pixels"),
                "bisect": Use(help="tile edge in pixels"),
                "audit": Use(help="finest tile edge in pixels of every cell's check"),
            },
        ),
        Option(
            "equivalence_tile",
            "--equivalence-tile",
            "equivalence_tile",
            "integer",
            "claim `equivalent` for N x N tiles (a multiple of --tile) and only there, instead of the size chosen for "
            "the budget (check: the finest its budget bounds; compare: the finest); stated with its tile size "
            "everywhere the verdict is shown",
            low=1,
            high=MAX_RESOLUTION,
            metavar="N",
            number=True,
            uses={
                "check": _USE,
                **dict.fromkeys(
                    ("compare", "selftest"),
                    Use(
                        help="with --tolerance: claim `equivalent` for N x N tiles (one of the tested sizes) instead "
                        "of the finest"
                    ),
                ),
                "case": _USE,
            },
        ),
        Option(
            "resolution",
            "--resolution",
            "resolution",
            "resolution",
            "override the resolution (width height)",
            low=1,
            high=MAX_RESOLUTION,
            metavar="W H",
            uses=dict.fromkeys(_JOB, _USE)
            | {
                "render": Use(help=f"override the resolution (at most {MAX_RESOLUTION})"),
                "audit": Use(help="every scene at this resolution (width height; default: each scene's own)"),
            },
        ),
        Option(
            "device",
            "--device",
            None,
            "choice",
            "Cycles device",
            default="CPU",
            choices=DEVICES,
            sides=_BOTH,
            draws=True,
            uses=dict.fromkeys((*_RENDERING, "addon"), _USE)
            | dict.fromkeys(("suite bless", "suite run"), Use(None, "every case on this device instead of its own")),
        ),
        Option(
            "devices",
            "--device",
            "devices",
            "choice",
            "Cycles devices",
            default=("CPU",),
            choices=DEVICES,
            many=True,
            uses={"case": _USE},
        ),
        Option(
            "sampling_pattern",
            "--sampling-pattern",
            "sampling_pattern",
            "text",
            "Cycles sampling pattern, one of the values the running Blender offers (default: the scene file's own; "
            "a built-in scene's is TABULATED_SOBOL, or the Sobol pattern an older Blender has); recorded",
            metavar="PATTERN",
            sides=_BOTH,
            draws=True,
            uses=dict.fromkeys(_JOB, _USE)
            | {"bisect": Use(test_help="the sampling pattern whose effect is bisected, within each build")},
        ),
        Option(
            "overrides",
            "--set",
            "set",
            "override",
            'property override, repeatable: cycles.sample_clamp_indirect=0, lights["Light"].energy=100, '
            'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value=0.21,0.21,0.21,1',
            default=(),
            metavar="RNA.PATH=VALUE",
            many=True,
            sides=_BOTH,
            uses=dict.fromkeys(_JOB, _USE)
            | {
                "check": Use(help="property override of the test side, repeatable (as render --set)"),
                "bisect": Use(test_help="the change whose effect is bisected, within each build (repeatable)"),
                "suite run": Use(help="an override for every case's test side (a planted change)"),
            },
        ),
        Option(
            "lobes",
            "--lobes",
            None,
            "lobes",
            f"also accumulate light components and light groups as layers: 'all' or some of {','.join(LOBES)}",
            default=(),
            metavar="LIST",
            uses={
                "render": _USE,
                "check": Use(
                    help="also render light components and light groups (as render --lobes); the report tests each"
                ),
            },
        ),
        Option(
            "scene",
            "--scene",
            None,  # a suite case's scene is checked by the suite (a file or a built-in scene)
            "text",
            "a built-in scene instead of a file",
            uses={
                "render": Use(help="a built-in scene instead of a file (see --help of `demo` for the list)"),
                "check": Use(help="a built-in scene instead of a file (both sides)"),
                "matrix": _USE,
                "bisect": _USE,
            },
        ),
        Option(
            "pass_command",
            "--command",
            None,  # a suite case's command is checked by the suite
            "text",
            "render each pass with this command instead of Cycles (another renderer): it must write the pass of "
            "{seed} into the EXR {out}; also {spp}, {set} (the overrides, one argument each), {python} (this "
            "Python); e.g. '{python} render.py --seed {seed} --out {out}'",
            metavar="TEMPLATE",
            uses={
                "render": _USE,
                "check": Use(
                    help="render the reference's passes with this command of another renderer instead of "
                    "Cycles (as render --command; no scene)",
                    test_help="the test side's command (default: --command)",
                ),
            },
            sides=_BOTH,
        ),
        Option(
            "command_dir",
            "--command-dir",
            None,
            "text",
            "the folder --command runs in (default: this one)",
            metavar="DIR",
            uses={"render": _USE, "check": Use(help="the folder the commands run in (default: this one)")},
        ),
        Option(
            "on_nan",
            "--on-nan",
            None,
            "choice",
            "a pass with NaN/inf pixels: stop the run, skip the pass, or keep it (its tiles are excluded)",
            default="stop",
            choices=ON_NAN,
            uses=dict.fromkeys(("render", "ingest"), _USE),
        ),
        Option(
            "blend_scene",
            "--blend-scene",
            "blend_scene",
            "text",
            "which scene of the .blend (default: its active one)",
            metavar="NAME",
            uses=dict.fromkeys((*_JOB, "lint"), _USE) | {"check": Use(test_help="which scene of the test side's file")},
            sides=_BOTH,
        ),
        Option(
            "blender",
            "--blender",
            None,
            "text",
            "render with this Blender executable (3.4 or later) instead of the bpy module; its version and build are "
            "recorded",
            metavar="PATH",
            sides=_BOTH,
            uses={
                "render": _USE,
                "check": Use(
                    help="Blender executable of the reference side (default: bpy)",
                    test_help="Blender executable of the test side (default: --blender)",
                ),
                **dict.fromkeys(
                    ("suite bless", "suite run"), Use(help="render with this Blender executable instead of bpy")
                ),
                "audit": Use(help="audit the release of this Blender executable (3.4 or later) instead of bpy"),
            },
        ),
        Option(
            "python",
            "--python",
            None,
            "text",
            "render with this Python interpreter, whose environment has another release's bpy module (python -m "
            "batch bpy VERSION makes one); its version and build are recorded",
            metavar="PATH",
            sides=_BOTH,
            uses={
                "render": _USE,
                "check": Use(
                    help="a Python with another release's bpy module for the reference side (python -m batch bpy "
                    "VERSION makes one)",
                    test_help="the test side's Python with a bpy module (default: --python)",
                ),
                **dict.fromkeys(
                    ("suite bless", "suite run"), Use(help="render with this Python's bpy module (another release)")
                ),
                "audit": Use(
                    help="audit the release of this Python's bpy module (python -m batch bpy VERSION makes "
                    "one; --release VERSION does it for you)"
                ),
            },
        ),
        Option(
            "max_passes",
            "--max-passes",
            "passes",
            "integer",
            "the most passes a side",
            default=512,
            low=2,
            high=MAX_PASSES,
            metavar="N",
            uses={
                "check": Use(
                    deferred=True,
                    help="the most passes a side (default {default}; with --max-seconds, whichever ends first)",
                ),
                "case": Use(64),
                "addon": _USE,
                "audit": Use(
                    128,
                    "the most passes a side of each check of a cell (with --max-seconds, whichever ends first: "
                    "every cell has the same budget)",
                ),
            },
        ),
        Option(
            "passes",
            "--passes",
            None,
            "integer",
            "passes per build",
            low=2,
            high=MAX_PASSES,
            uses={"matrix": Use(32), "bisect": Use(32), "demo": Use(help="passes per side")},
        ),
        Option(
            "max_seconds",
            "--max-seconds",
            "seconds",
            "seconds",
            "the most render seconds",
            low=0,
            high=MAX_SECONDS,
            metavar="S",
            off=True,
            uses={
                "check": Use(
                    help="the most render seconds, both sides together (with --max-passes, whichever ends first)"
                ),
                "case": _USE,
                "audit": Use(
                    20.0,
                    "the most render seconds of each check of a cell, both sides together (default {default}; "
                    "`off`: the passes alone): a cell whose passes render many samples stops at it",
                ),
            },
        ),
        Option(
            "min_passes",
            "--min-passes",
            None,
            "integer",
            "the fewest passes a side a time budget renders, whatever their seconds",
            low=2,
            high=MAX_PASSES,
            metavar="N",
            uses={
                "check": Use(
                    help="with --max-seconds: the fewest passes a side, rendered whatever their seconds (up to 10 "
                    "times the budget, so that a renderer that hangs still ends); default: none, and a check whose "
                    "budget ends before 2 passes a side ends inconclusive"
                ),
                "audit": Use(
                    8,
                    "the fewest passes a side of each check of a cell, rendered whatever their seconds (default "
                    "{default}): a scene whose first pass builds much still gets a few passes",
                ),
            },
        ),
        Option(
            "tolerance",
            "--tolerance",
            "tolerance",
            "percentage",
            "the relative difference within which the two count as equivalent, e.g. 1%",
            default=0.01,
            low=0.0,
            high=MAX_TOLERANCE,
            metavar="PERCENT",
            off=True,
            uses={
                "check": Use(
                    help="stop at `equivalent` once every tile of the claim's size (the finest the budget bounds, "
                    "or --equivalence-tile) is bounded within this relative difference (default {default}; `off`: "
                    "stop only at `biased`, so that a bias smaller than any tolerance is found given the passes)"
                ),
                **dict.fromkeys(
                    ("compare", "selftest"),
                    Use(
                        None,
                        "e.g. 0.5%: the verdict is `equivalent` when every tile of the finest tile size is "
                        "bounded within it (else `inconclusive`, saying what is bounded and what is not)",
                    ),
                ),
                "matrix": Use(None, _MATRIX_TOLERANCE),
                "bisect": Use(None, _MATRIX_TOLERANCE),
                "case": Use(None),  # None: the suite's
                "suite": _USE,  # the suite file's [suite] tolerance
                "addon": _USE,
                "audit": Use(
                    help="a cell is `equivalent` once every tile of its claim's size is bounded within it "
                    "(default {default}; `off`: a cell stops only at `biased`)"
                ),
            },
        ),
        Option(
            "pixel_variance",
            "--pixel-variance",
            "pixel_variance",
            "choice",
            _PIXEL_HELP + "; unpaired runs only",
            default="auto",
            choices=PIXEL_MODES,
            uses={
                "check": Use(
                    help=_PIXEL_HELP + "; paired runs by each pixel's difference over the seeds (each side's "
                    "passes kept as images in --out; not with --workers or --scheduler)"
                ),
                "compare": Use(help=_PIXEL_HELP + "; unpaired runs only (a paired check keeps what it needs)"),
                "case": _USE,
            },
        ),
        Option(
            "seed_offset",
            "--seed-offset",
            None,
            "integer",
            "shift both sides' seeds by N: the same check on other passes, an independent second answer (the "
            "report records the seeds); --resume continues only with the offset it started with",
            default=0,
            low=0,
            high=MAX_SEED_OFFSET,
            metavar="N",
            number=True,
            uses={
                "check": _USE,
                "suite run": Use(
                    help="start the test seeds N after the reference's (default {default}: a rerun gives the same "
                    "answer; a nightly run can pass a new N for new passes)"
                ),
                "addon": _USE,
                "audit": Use(
                    help="the first seed of every cell (each check of a cell renders its own block of the "
                    "budget's seeds after it): another N, another independent audit"
                ),
            },
        ),
        # -- how a command talks to programs, and how render serves one
        Option(
            "json_progress",
            "--json-progress",
            None,
            "flag",
            "one JSON line per event on stdout, for programs",
            default=False,
            uses={
                "render": _USE,
                "check": _USE,
                **dict.fromkeys(("suite bless", "suite run"), Use(help="one JSON line per event on stdout")),
            },
        ),
        Option(
            "serve",
            "--serve",
            None,
            "flag",
            "for programs: render the seeds in chunks, one per line of stdin giving the number of passes; the scene "
            "stays loaded, the statistics are saved after each chunk; or a JSON line "
            '{"seeds": [...], "out": FILE} renders exactly those seeds into FILE',
            default=False,
            uses={"render": _USE},
        ),
        Option(
            "probe",
            "--probe",
            None,
            "flag",
            "for programs: render nothing, only open the scene and print what it asks of the passes (its own samples "
            "and its settings that act only above some samples per render) as one JSON event; with --set, "
            "--sampling-pattern or a --device other than the CPU, also set the scene up as its passes would be, "
            "refusing what this build lacks as a render does",
            default=False,
            uses={"render": _USE},
        ),
        Option(
            "chunk",
            "--chunk",
            None,
            "integer",
            "passes a worker renders per task with --workers or --scheduler (default: about 4 tasks a worker, at most "
            "64); a worker that dies loses at most its chunk",
            low=1,
            high=MAX_PASSES,
            metavar="N",
            number=True,
            uses={"render": _USE},
        ),
        # -- what a check alone takes
        Option(
            "futility",
            "--no-futility",
            None,
            "flag",
            "render the whole budget even when neither claim is within its reach (by default the check stops "
            "`inconclusive` once its claim can't be bounded by the budget at the current estimates and no "
            "tile-channel has a --futility-loss chance (5%) left to reach `biased` by the budget, even with the bias "
            "the budget detects there: the stop gives up at most that share of the power against such a bias)",
            default=True,  # the flag turns it off
            uses={"check": _USE},
        ),
        Option(
            "futility_loss",
            "--futility-loss",
            None,
            "probability",
            "the most power the futility stop may give up against the bias the budget detects: it stops only where "
            "no tile-channel has this chance left to reach `biased` by the budget; more stops sooner, less finds "
            "more",
            default=0.05,
            low=0.0,
            high=1.0,
            metavar="P",
            number=True,
            uses={"check": _USE},
        ),
        Option(
            "unpaired",
            "--unpaired",
            None,
            "flag",
            "disjoint seeds even on one build (an A/A check)",
            default=False,
            uses={"check": _USE},
        ),
        # -- what a render job alone takes: its seeds and its file, resuming, checkpoints, the pass images
        Option(
            "seeds",
            "--seeds",
            None,
            "seeds",
            "A:B (half-open range) or S1,S2,...",
            uses={
                "render": Use(required=True),
                "ingest": Use(
                    help="the passes' seeds, in file order; without it each pass gets an id from its "
                    "content, so the run counts as independent of every other (unpaired test)"
                ),
            },
        ),
        Option(
            "resume",
            "--resume",
            None,
            "flag",
            "continue an interrupted run in --out",
            default=False,
            uses={
                "render": _USE,
                "suite run": _USE,
                "check": Use(help="continue a stopped check in --out"),
                "audit": Use(help="continue the audit in --out, reusing every decided cell"),
            },
        ),
        Option(
            "checkpoint_every",
            "--checkpoint-every",
            None,
            "integer",
            "save the statistics file every N passes, or further apart where writing it would take more than a tenth "
            "of the time (fast passes of a large image)",
            default=8,
            low=1,
            high=MAX_PASSES,
            metavar="N",
            number=True,
            uses={"render": _USE},
        ),
        Option(
            "out",
            "--out",
            None,
            "text",
            "statistics file to write (.npz)",
            metavar="STATS",
            uses={
                "render": Use(required=True),
                "ingest": Use(required=True, help="statistics file to write (must not exist)"),
                "merge": Use(required=True, help="merged statistics file to write (must not exist)"),
                **dict.fromkeys(
                    ("compare", "selftest"),
                    Use(required=True, help="folder for the report (created if missing)", metavar="REPORT_DIR"),
                ),
                "check": Use(required=True, help="folder for both sides' statistics and the report", metavar="DIR"),
                "suite run": Use(required=True, help="folder for the results and the dashboard", metavar="DIR"),
                **dict.fromkeys(
                    ("matrix", "bisect"),
                    Use(required=True, help="folder for the renders, reports and index.html", metavar="DIR"),
                ),
                "audit": Use(
                    required=True,
                    help="folder for the cells' checks, summary.json, junit.xml and index.html",
                    metavar="DIR",
                ),
                "demo": Use(
                    os.path.join("out", "demo"),
                    "folder for both sides' statistics and the report",
                    metavar="REPORT_DIR",
                ),
            },
        ),
        Option(
            "pass_images",
            "--pass-images",
            None,
            "text",
            "also keep each pass's image in DIR as SEED.exr (the pass's own EXR file, moved there): what a paired "
            "check folds into each pixel's difference per seed for the pixel-variance test",
            metavar="DIR",
            uses={"render": _USE},
        ),
        Option(
            "alpha",
            "--alpha",
            "alpha",
            "probability",
            "the false-positive rate of each verdict",
            default=0.01,
            low=0.0,
            high=1.0,
            number=True,
            uses={
                "check": _USE,
                **dict.fromkeys(("compare", "selftest"), Use(help="false-positive rate of a biased verdict")),
                "matrix": _USE,
                "bisect": _USE,
                "suite": _USE,  # the suite file's [suite] alpha
                "addon": _USE,
                "audit": Use(help="the false-positive rate of the whole audit, split evenly over its cells"),
            },
        ),
        # -- what one command alone takes
        Option(
            "pvalue_method",
            "--pvalue-method",
            None,
            "choice",
            "exact Student t (default); gauss/as_erf: the paper's approximations where nu >= 20",
            default="exact",
            choices=PVALUE_METHODS,
            uses=dict.fromkeys(("compare", "selftest"), _USE),
        ),
        Option(
            "test_blend",
            "--test-blend",
            None,
            "text",
            "the test side's scene file (default: SCENE.blend)",
            metavar="OTHER.blend",
            uses={"check": _USE},
        ),
        Option(
            "full_maps",
            "--full-maps",
            None,
            "flag",
            "also write the p-value map and its overlay on the mean render as PNG at the image's resolution "
            "(pvalue_map.png, overlay.png)",
            default=False,
            uses=dict.fromkeys(("compare", "selftest"), _USE),
        ),
        Option(
            "changes_file",
            "--changes",
            None,
            "text",
            "a file of your own [[change]] tables (the form of batch/decide/audits/cycles.toml), audited beside the "
            "shipped ones",
            metavar="FILE",
            uses={"audit": _USE},
        ),
        Option(
            "refs",
            "--refs",
            None,
            "text",
            "the references' folder (default for `builtin`: shipped ones)",
            metavar="DIR",
            uses=dict.fromkeys(("suite bless", "suite run"), _USE),
        ),
        Option(
            "force",
            "--force",
            None,
            "flag",
            "replace a reference even where the new one differs",
            default=False,
            uses={"suite bless": _USE},
        ),
        Option(
            "missing",
            "--missing",
            None,
            "flag",
            "render only the cases that have no reference",
            default=False,
            uses={"suite bless": _USE},
        ),
        Option(
            "baseline",
            "--baseline",
            None,
            "text",
            "the build every other is compared with (default: the first)",
            metavar="BUILD",
            uses={"matrix": _USE},
        ),
        Option(
            "release",
            "--release",
            None,
            "text",
            "audit this bpy release, e.g. 5.2.3 (its environment made once and cached, as `bpy VERSION` does)",
            metavar="VERSION",
            uses={"audit": _USE},
        ),
        Option(
            "bisect_passes",
            "--bisect-passes",
            None,
            "integer",
            "passes per release and side of a bisect",
            default=32,
            low=1,
            high=MAX_PASSES,
            metavar="N",
            number=True,
            uses={"audit": _USE},
        ),
        Option(
            "plan",
            "--plan",
            None,
            "flag",
            "say what the release supports, the cells, the level and the time expected, and render nothing",
            default=False,
            uses={"audit": _USE},
        ),
        Option(
            "list",
            "--list",
            None,
            "flag",
            "list the cached releases, their Pythons and sizes",
            default=False,
            uses={"bpy": _USE},
        ),
        Option(
            "base_python",
            "--base-python",
            None,
            "text",
            "the Python to make the environment with (default: the one the release needs, found on PATH or among "
            "pyenv's)",
            metavar="PATH",
            uses={"bpy": _USE},
        ),
        # -- the files and names a command works on (positional arguments), and the options of one command
        Option(
            "blend",
            "SCENE.blend",
            None,  # a suite case's scene file is checked by the suite
            "text",
            "the scene file",
            uses={
                "render": Use(nargs="?", help="scene file (default: the file Blender opened)"),
                "check": Use(nargs="?", help="scene file of the reference side"),
                "lint": Use(required=True, help="the scene file to lint"),
                **dict.fromkeys(("matrix", "bisect"), Use(nargs="?")),
            },
        ),
        Option(
            "blends", "SCENE.blend", None, "text", "scene files to audit", default=(), uses={"audit": Use(nargs="*")}
        ),
        Option(
            "pass_files",
            "PASS.exr",
            None,
            "text",
            "the passes' EXR files, one a pass",
            uses={"ingest": Use(nargs="+", required=True)},
        ),
        Option(
            "runs", "STATS", None, "text", "statistics files to merge", uses={"merge": Use(nargs="+", required=True)}
        ),
        Option("ref", "REF", None, "text", "statistics file of the reference", uses={"compare": Use(required=True)}),
        Option(
            "test", "TEST", None, "text", "statistics file of the run under test", uses={"compare": Use(required=True)}
        ),
        Option(
            "run",
            "RUN",
            None,
            "text",
            "a statistics file with at least 4 passes",
            uses={"selftest": Use(required=True)},
        ),
        Option(
            "suite_file",
            "SUITE",
            None,
            "text",
            "a suite file (.toml), or `builtin`",
            uses=dict.fromkeys(("suite bless", "suite run"), Use(required=True)),
        ),
        Option("version", "VERSION", None, "text", "the release, e.g. 4.5.4", uses={"bpy": Use(nargs="?")}),
        Option(
            "pairing",
            "--paired",
            None,
            "switch",
            "the test of two finished runs",
            default="auto",
            switches=(
                ("--paired", "paired", "paired test (identical seeds on both sides)"),
                ("--unpaired", "welch", "Welch's test (disjoint seeds)"),
            ),
            uses={"compare": _USE},
        ),
        Option(
            "renderer", "--renderer", None, "text", "renderer name to record", default="unknown", uses={"ingest": _USE}
        ),
        Option(
            "layers",
            "--layers",
            None,
            "names",
            "also read these layers of multilayer EXRs (each NAME.R/G/B, under any view-layer prefix) into layers of "
            "the statistics file, tested by compare one by one (light components of other renderers)",
            default=(),
            metavar="NAME,...",
            uses={"ingest": _USE},
        ),
        Option(
            "filter",
            "--filter",
            None,
            "text",
            "only the cases whose names match",
            metavar="PATTERN",
            uses=dict.fromkeys(("suite bless", "suite run"), Use(nargs="+")),
        ),
        Option(
            "builds",
            "--builds",
            None,
            "text",
            "the builds, oldest first",
            metavar="BUILD",
            uses=dict.fromkeys(("matrix", "bisect"), Use(nargs="+", required=True)),
        ),
        Option(
            "scenes",
            "--scene",
            None,
            "text",
            "a built-in scene to audit, repeatable; `all` for every one (default: every one where no scene file is "
            "given)",
            default=(),
            metavar="NAME",
            many=True,
            uses={"audit": _USE},
        ),
        Option(
            "only",
            "--only",
            None,
            "text",
            "only these changes, by name (the default against itself is always audited)",
            metavar="CHANGE",
            uses={"audit": Use(nargs="+")},
        ),
        Option(
            "releases",
            "--releases",
            None,
            "text",
            "bisect each confirmed difference over these builds, oldest first (as bisect --builds: current, a release "
            "such as 4.5.4, or a path); the audited release is the last",
            metavar="BUILD",
            uses={"audit": Use(nargs="+")},
        ),
        Option(
            "square",
            "--resolution",
            None,
            "integer",
            "square image size in pixels",
            low=1,
            high=MAX_RESOLUTION,
            metavar="RESOLUTION",
            number=True,
            uses={"demo": _USE},
        ),
        Option(
            "workers",
            "--workers",
            None,
            "integer",
            "render the passes on N worker processes on this machine (a Dask LocalCluster, the cores split among "
            "them; one for all sides and cases); pays off for long runs. Needs the `workers` extra",
            low=1,
            high=MAX_WORKERS,
            metavar="N",
            number=True,
            uses=dict.fromkeys(_CLUSTERED, Use(exclusive="cluster")),
        ),
        Option(
            "scheduler",
            "--scheduler",
            None,
            "text",
            "render the passes on a running Dask cluster, e.g. tcp://head:8786; every worker needs this tool, its "
            "Blender and the scene (and its textures) at the same path. Needs the `workers` extra",
            metavar="ADDRESS",
            uses=dict.fromkeys(_CLUSTERED, Use(exclusive="cluster")),
        ),
    )
}

#: Options in which the test side may differ from the reference (``--test-spp``, a suite case's ``test_spp``):
#: settings that change only how the passes are drawn, so both sides still render the same converged image.
TEST_SIDE = tuple(dest for dest, o in OPTIONS.items() if "test" in o.sides and o.draws)


def default(dest: str, place: str):
    """The default of option `dest` at `place` (a command, ``case``, ``suite`` or ``addon``)."""
    return OPTIONS[dest].default_for(place)


def argparse_type(option: Option, flag: str | None = None, auto: bool = False) -> Callable[[str], Any]:
    """The option's check as an argparse ``type`` (its error as argparse's, which names the flag); ``off`` is
    None where the option has `Option.off`, ``auto`` where the place takes it (`auto`)."""
    flag = flag or option.flag

    def convert(value: str):
        if option.off and value.strip().lower() == "off" or auto and value.strip().lower() == "auto":
            return None
        try:
            return option.convert(flag, value)
        except BatchError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f"{flag} ")) from None

    convert.__name__ = option.dest
    return convert


def to_argv(option: Option, value, side: str = "reference") -> list[str]:
    """`value` on the command line as `option`'s flag (`side` ``test``: its test side's, ``--test-spp``) and its
    text: what its parser reads back to `value` (None: ``off`` where the option takes it, else nothing)."""
    flag = option.flag if side == "reference" else "--test-" + option.flag.removeprefix("--")
    if option.positional:
        return [str(value)]
    if option.kind == "flag":  # given where it is not the default: a flag that turns something off stores False
        return [flag] if bool(value) != bool(option.default) else []
    if value is None:
        return [flag, "off"] if option.off else []
    if option.many:
        return [word for item in value for word in (flag, str(item))]
    if option.kind == "resolution":
        return [flag, *map(str, value)]
    text = {"lobes": ",".join, "seeds": format_seeds}.get(option.kind, option.show)(value)
    return [flag, text]


def add_options(parser, command: str, dests: Iterable[str] | None = None, side: str = "reference"):
    """Declare the options `dests` on `parser` as `command` takes them: flags, checks, defaults and help from
    the declaration. `side` ``test``: the test side's own (``--test-spp``, dest ``test_spp``; default None: the
    reference's). No `dests`: every option declared for `command` that no call before named, in the
    declaration's order (an option declared for a command is on its parser without naming it there)."""
    added = _ADDED.setdefault(parser, set())
    if dests is None:
        dests = [dest for dest, option in OPTIONS.items() if command in option.uses and (dest, side) not in added]
    for dest in dests:
        added.add((dest, side))
        option = OPTIONS[dest]
        use = option.use(command)
        value = None if use.deferred else option.default_for(command)
        shown = option.default_for(command)
        help_text = use.help or option.help
        flag, dest_name, metavar = option.flag, dest, use.metavar or option.metavar
        if side == "test":
            if "test" not in option.sides:
                raise KeyError(f"{option.flag} has no test side")
            flag, dest_name, metavar = "--test-" + flag.removeprefix("--"), f"test_{dest}", metavar or dest.upper()
            what = option.help.split(",")[0].split(" (")[0]
            help_text = use.test_help or f"the test side's {what} (default: the reference's)"
            value = shown = () if option.many else None
        auto = use.auto and side == "reference"
        target = _group(parser, use.exclusive) if use.exclusive else parser
        if option.kind == "flag":  # given or not; a flag that turns something off stores False
            action = "store_false" if option.default is True else "store_true"
            target.add_argument(flag, dest=dest_name, action=action, help=help_text.replace("%", "%%"))
            continue
        if option.kind == "switch":  # one of its flags, each storing its value
            group = parser.add_mutually_exclusive_group()
            for switch, const, said in option.switches:
                group.add_argument(switch, dest=dest_name, action="store_const", const=const, help=said)
            parser.set_defaults(**{dest_name: value})
            continue
        if "{default}" in help_text:
            help_text = help_text.format(default="auto" if auto and shown is None else option.show(shown))
        elif shown not in (None, [], ()) and not use.required and "(default" not in help_text:
            help_text += f" (default {option.show(shown)})"  # unless the help says it in its own words
        kwargs: dict[str, Any] = {"dest": dest_name, "help": help_text.replace("%", "%%")}
        if metavar:
            kwargs["metavar"] = metavar if " " not in metavar else tuple(metavar.split())
        if option.kind == "resolution":
            side_of = replace(option, kind="integer")
            kwargs |= {"nargs": 2, "type": argparse_type(side_of, flag)}
        elif option.kind == "choice" and side == "reference":
            kwargs["choices"] = option.choices
        else:
            kwargs["type"] = argparse_type(option, flag, auto)
        if use.nargs:
            kwargs["nargs"] = use.nargs
        if option.many:
            kwargs |= {"action": "append", "default": []}
        elif use.required and not option.positional:
            kwargs["required"] = True
        elif not use.required:
            kwargs["default"] = value
        if option.positional:  # its name is its dest; it is shown as its flag
            target.add_argument(kwargs.pop("dest"), **kwargs | {"metavar": flag})
        else:
            target.add_argument(flag, **kwargs)


def _group(parser, name: str):
    """The mutually exclusive group `name` of `parser`, made where it is first used."""
    groups = _GROUPS.setdefault(parser, {})
    if name not in groups:
        groups[name] = parser.add_mutually_exclusive_group()
    return groups[name]


#: The options each parser was given (`add_options`), by destination and side; its mutually exclusive groups.
_ADDED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_GROUPS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _case_options() -> tuple[Option, ...]:
    """The options a suite case takes, by their keys: the declared ones, and ``test_<key>`` for those whose test
    side may differ (default None: the reference's)."""
    declared = [o for o in OPTIONS.values() if o.key is not None and "case" in o.uses]
    test_side = [replace(o, dest=f"test_{o.dest}", key=f"test_{o.key}", uses={"case": Use(None)})
                 for o in declared if o.dest in TEST_SIDE]  # fmt: skip
    return (*declared, *test_side)


#: The options a suite case takes (`from_mapping` reads them; the other keys of a case are the suite's own).
CASE_OPTIONS = _case_options()


def from_file(option: Option, name: str, value):
    """A value of `option` as a suite file (TOML) gives it, checked as the declaration says, or BatchError naming
    `name` (``'spp'`` in a case, ``[suite] alpha`` in the suite's table): a number written as text is refused (on
    the command line every value is text; in a file ``"4"`` is a mistake), a repeatable option is a list."""
    if option.number and (isinstance(value, str) or isinstance(value, list) and any(
            isinstance(v, str) for v in value)):  # fmt: skip
        raise BatchError(f"{name} must be a number, not text: {_show(value)}")
    if not option.many:
        return option.convert(name, value)
    if not isinstance(value, list):
        raise BatchError(f"{name} must be a list, got {_show(value)}")
    if option.dest == "devices" and not value:  # a case rendered nowhere would test nothing
        raise BatchError(f"{name} must name at least one of {', '.join(DEVICES)}, got []")
    values = tuple(option.convert(name, v) for v in value)
    if len(set(values)) != len(values):
        raise BatchError(f"{name} repeats an item: {_show(value)}")
    return values


def from_mapping(entry: dict, label: str, problems: list[str]) -> dict[str, Any]:
    """The options a suite case gives (by their keys), checked (`from_file`): a bad value is added to `problems`
    (naming `label` and the key) and left out."""
    return _from_table(CASE_OPTIONS, entry, "'{}'", f"{label}: ", problems)


#: The options a suite file's ``[suite]`` table takes (by their keys): those declared for the place ``suite``.
SUITE_OPTIONS = tuple(o for o in OPTIONS.values() if o.key is not None and "suite" in o.uses)


def from_suite_table(table: dict, problems: list[str]) -> dict[str, Any]:
    """The options a suite file's ``[suite]`` table gives (`SUITE_OPTIONS`, by their keys), checked as a case's
    are (`from_file`), each error naming ``[suite] <key>``: a bad value is added to `problems` and left out."""
    return _from_table(SUITE_OPTIONS, table, "[suite] {}", "", problems)


def _from_table(options, table: dict, naming: str, prefix: str, problems: list[str]) -> dict[str, Any]:
    """The values `table` gives for `options` (by their keys), each named in an error as `naming` formats the key;
    a bad one is added to `problems` after `prefix` and left out."""
    values = {}
    for option in options:
        if option.key in table:
            try:
                values[option.dest] = from_file(option, naming.format(option.key), table[option.key])
            except BatchError as exc:
                problems.append(f"{prefix}{exc}")
    return values
