"""The options of a job, declared once: the command line (``render``, ``check``, ``suite``), a suite file's case
keys and the Blender add-on read the same names, limits and help here, and one function checks each value
however it arrives (a string on the command line, a TOML value, a panel property), with the same one-line error
naming the option as the user wrote it (``--spp`` on the command line, ``'spp'`` in a suite file).

`add_options` declares options on an argparse parser; `from_mapping` reads them from a suite case, collecting
every problem instead of stopping at the first.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from ..errors import BatchError
from .lobes import LOBES, parse_lobes
from .seeds import MAX_PASSES

#: Cycles' largest render side (it clamps larger values) and largest samples per pixel (2**24).
MAX_RESOLUTION = 65536
MAX_SPP = 2**24
#: Seconds a budget may be: a week of rendering is far beyond any check (and `inf` is no budget).
MAX_SECONDS = 7 * 24 * 3600.0

#: The devices a job may ask for: the CPU, the first GPU backend that has a device, or one backend.
GPU_BACKENDS = ("OPTIX", "CUDA", "HIP", "METAL", "ONEAPI")
DEVICES = ("CPU", "GPU", *GPU_BACKENDS)


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


def seconds(name: str, value) -> float:
    """A positive, finite number of seconds (at most `MAX_SECONDS`), from a number or its text."""
    number = _number(value)
    if number is None or not 0 < number <= MAX_SECONDS:
        raise BatchError(f"{name} must be a number of seconds in (0, {MAX_SECONDS:.0f}], got {_show(value)}")
    return number


def percentage(name: str, value) -> float:
    """A relative difference written as a percentage, ``0.5%``, as a fraction (0.005), in (0 %, 1000 %)."""
    text = value.strip() if isinstance(value, str) else None
    number = math.nan
    if text is not None and text.endswith("%"):
        try:
            number = float(text[:-1]) / 100.0
        except ValueError:
            pass
    if not 0.0 < number < 10.0:
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


# -- the declaration ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Option:
    """One option: its destination (a `RenderJob` field or a run's setting), its command-line flag, its key in
    a suite case (None: not there), how a value is checked, and its help."""

    dest: str
    flag: str
    key: str | None
    convert: Callable[[str, Any], Any]  # (the name to show, the value) -> the value, or BatchError
    help: str
    metavar: str | None = None
    many: bool = False  # repeatable on the command line (append), a list in a suite case
    number: bool = False  # a number (text only on the command line: a suite file's "4" is a mistake)


def _side(name: str, value) -> int:
    return integer(name, value, 1, MAX_RESOLUTION)


def _resolution(name: str, value):
    items = value.split() if isinstance(value, str) else value
    if not isinstance(items, list | tuple) or len(items) != 2:
        raise BatchError(f"{name} must be a width and a height in pixels, got {_show(value)}")
    return tuple(_side(name, v) for v in items)


def _lobes(name: str, value) -> tuple[str, ...]:
    try:
        return parse_lobes(value if isinstance(value, str) else ",".join(value))
    except (BatchError, TypeError):
        raise BatchError(f"{name} takes 'all' or some of {','.join(LOBES)}, got {_show(value)}") from None


def _override(name: str, value) -> str:
    from .overrides import OverrideError, parse_override

    value = text(name, value)
    try:
        parse_override(value)
    except OverrideError as exc:
        raise BatchError(f"{name} {value!r}: {exc.reason}") from None
    return value


OPTIONS = {
    option.dest: option
    for option in (
        Option(
            "spp", "--spp", "spp", lambda n, v: integer(n, v, 1, MAX_SPP), "samples per pixel per pass", number=True
        ),
        Option(
            "tile",
            "--tile",
            "tile",
            lambda n, v: integer(n, v, 1, MAX_RESOLUTION),
            "finest tile edge in pixels",
            number=True,
        ),  # fmt: skip
        Option(
            "resolution",
            "--resolution",
            "resolution",
            _resolution,
            "override the resolution (width height)",
            metavar="W H",
        ),  # fmt: skip
        Option("device", "--device", None, lambda n, v: choice(n, v, DEVICES), "Cycles device"),
        Option("devices", "--device", "devices", lambda n, v: choice(n, v, DEVICES), "Cycles devices", many=True),
        Option(
            "sampling_pattern",
            "--sampling-pattern",
            "sampling_pattern",
            text,
            "Cycles sampling pattern, one of the values the running Blender offers (default: the scene file's own; "
            "a built-in scene's is TABULATED_SOBOL, or the Sobol pattern an older Blender has); recorded",
            metavar="PATTERN",
        ),
        Option(
            "overrides",
            "--set",
            "set",
            _override,
            'property override, repeatable: cycles.sample_clamp_indirect=0, lights["Light"].energy=100, '
            'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value=0.21,0.21,0.21,1',
            metavar="RNA.PATH=VALUE",
            many=True,
        ),
        Option(
            "lobes",
            "--lobes",
            None,
            _lobes,
            f"also accumulate light components and light groups as layers: 'all' or some of {','.join(LOBES)}",
            metavar="LIST",
        ),  # fmt: skip
        Option(
            "blend_scene",
            "--blend-scene",
            "blend_scene",
            text,
            "which scene of the .blend (default: its active one)",
            metavar="NAME",
        ),  # fmt: skip
        Option(
            "blender",
            "--blender",
            None,
            text,
            "render with this Blender executable (3.4 or later) instead of the bpy module; its version and build are "
            "recorded",
            metavar="PATH",
        ),  # fmt: skip
        Option(
            "python",
            "--python",
            None,
            text,
            "render with this Python interpreter, whose environment has another release's bpy module (python -m "
            "batch bpy VERSION makes one); its version and build are recorded",
            metavar="PATH",
        ),  # fmt: skip
        Option(
            "max_passes",
            "--max-passes",
            "passes",
            lambda n, v: integer(n, v, 2, MAX_PASSES),
            "the most passes a side",
            metavar="N",
        ),  # fmt: skip
        Option("max_seconds", "--max-seconds", "seconds", seconds, "the most render seconds", metavar="S"),
        Option(
            "tolerance",
            "--tolerance",
            "tolerance",
            percentage,
            "the relative difference within which the two count as equivalent, e.g. 1%",
            metavar="PERCENT",
        ),  # fmt: skip
        Option("alpha", "--alpha", "alpha", probability, "the false-positive rate of each verdict", number=True),
    )
}


def argparse_type(option: Option, flag: str | None = None) -> Callable[[str], Any]:
    """The option's check as an argparse ``type`` (its error as argparse's, which names the flag)."""

    def convert(value: str):
        try:
            return option.convert(flag or option.flag, value)
        except BatchError as exc:
            message = str(exc).removeprefix(f"{flag or option.flag} ")
            raise argparse.ArgumentTypeError(message) from None

    convert.__name__ = option.dest
    return convert


#: Options in which the test side may differ from the reference (``--test-spp``, a suite case's ``test_spp``):
#: settings that change only how the passes are drawn, so both sides still render the same converged image.
TEST_SIDE = ("spp", "device", "sampling_pattern")


def add_options(
    parser, dests: Iterable[str], defaults: dict[str, Any] | None = None, helps: dict | None = None, test=False
):
    """Declare the options `dests` on `parser` with their flags, checks and help; `defaults` and `helps` per dest
    (a default shows in the help). `test`: the test side's own (``--test-spp``, dest ``test_spp``; default
    None: the reference side's)."""
    defaults, helps = defaults or {}, helps or {}
    for dest in dests:
        option = OPTIONS[dest]
        if test:
            flag = "--test-" + option.flag.removeprefix("--")
            text = helps.get(
                dest, f"the test side's {option.help.split(',')[0].split(' (')[0]} (default: the reference's)"
            )
            option = Option(
                f"test_{dest}", flag, None, option.convert, text, option.metavar or dest.upper(), option.many
            )
        kwargs: dict[str, Any] = {"dest": option.dest, "help": helps.get(dest, option.help)}
        if option.metavar:
            kwargs["metavar"] = option.metavar if " " not in option.metavar else tuple(option.metavar.split())
        if dest == "resolution":
            kwargs |= {"nargs": 2, "type": argparse_type(Option("resolution", option.flag, None, _side, ""))}
        elif dest in ("device", "devices"):
            kwargs["choices"] = DEVICES
        else:
            kwargs["type"] = argparse_type(option)
        if option.many:
            kwargs |= {"action": "append", "default": []}
        if dest in defaults:
            kwargs["default"] = defaults[dest]
            kwargs["help"] += f" (default {defaults[dest]})" if defaults[dest] not in (None, [], ()) else ""
        parser.add_argument(option.flag, **kwargs)


def from_mapping(entry: dict, label: str, problems: list[str]) -> dict[str, Any]:
    """The options a suite case gives (by their keys), checked: a bad value is added to `problems` (naming
    `label` and the key) and left out."""
    values = {}
    test_side = [Option(f"test_{o.dest}", o.flag, f"test_{o.key}", o.convert, o.help, number=o.number)
                 for o in OPTIONS.values() if o.dest in TEST_SIDE and o.key is not None]  # fmt: skip
    for option in [*OPTIONS.values(), *test_side]:
        if option.key is None or option.key not in entry:
            continue
        value = entry[option.key]
        try:
            if option.number and (isinstance(value, str) or isinstance(value, list) and any(
                    isinstance(v, str) for v in value)):  # fmt: skip
                raise BatchError(f"'{option.key}' must be a number, not text: {_show(value)}")
            if option.many:
                if not isinstance(value, list):
                    raise BatchError(f"'{option.key}' must be a list, got {_show(value)}")
                if option.dest == "devices" and not value:  # a case rendered nowhere would test nothing
                    raise BatchError(f"'{option.key}' must name at least one of {', '.join(DEVICES)}, got []")
                values[option.dest] = tuple(option.convert(f"'{option.key}'", v) for v in value)
                if len(set(values[option.dest])) != len(values[option.dest]):
                    raise BatchError(f"'{option.key}' repeats an item: {_show(value)}")
            else:
                values[option.dest] = option.convert(f"'{option.key}'", value)
        except BatchError as exc:
            values.pop(option.dest, None)
            problems.append(f"{label}: {exc}")
    return values
