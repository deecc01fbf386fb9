"""Progress events of a render job, defined once, with one way out (`to_line`) and one way in (`parse`).

A job run with ``--json-progress`` writes each event as one JSON object on its own line of stdout, e.g.
``{"event": "pass", "done": 3, "total": 8, "seed": 2, "seconds": 0.21, "eta": 1.05}``; whoever started it (the
add-on, a launcher for another Blender binary, a worker) reads the lines back with `parse`, which skips
anything else a renderer prints.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from typing import ClassVar


@dataclass(frozen=True)
class Started:
    """The job starts: `total` passes in all, `todo` of them still to render (fewer when resuming)."""

    name: ClassVar[str] = "start"
    total: int
    todo: int
    out: str


@dataclass(frozen=True)
class PassDone:
    """A pass was rendered and accumulated: `done` of `total`, in `seconds`; `eta` seconds left (estimated)."""

    name: ClassVar[str] = "pass"
    done: int
    total: int
    seed: int
    seconds: float
    eta: float | None = None


@dataclass(frozen=True)
class Warned:
    """Something worth knowing that does not stop the job."""

    name: ClassVar[str] = "warning"
    message: str


@dataclass(frozen=True)
class Failed:
    """The job stops with an error (one line)."""

    name: ClassVar[str] = "error"
    message: str


@dataclass(frozen=True)
class Saved:
    """A chunk of passes is done and saved (``render --serve``): `out` holds `passes` passes now."""

    name: ClassVar[str] = "saved"
    out: str
    passes: int


@dataclass(frozen=True)
class Looked:
    """``check`` looked at the data: `passes` a side so far, the smallest p-value of a tested tile and the level
    it must reach to stop the run, the relative bias ruled out so far (None: none yet), the verdict if reached
    (None: go on), the looks left and the render seconds spent."""

    name: ClassVar[str] = "look"
    passes: int
    p_value: float
    threshold: float
    ruled_out: float | None
    verdict: str | None
    left: int
    seconds: float


@dataclass(frozen=True)
class Finished:
    """The job is done: `passes` passes are in `out`."""

    name: ClassVar[str] = "done"
    out: str
    passes: int


Event = Started | PassDone | Warned | Failed | Saved | Looked | Finished

EVENT_TYPES: dict[str, type] = {cls.name: cls for cls in (Started, PassDone, Warned, Failed, Saved, Looked, Finished)}

_FIELD_TYPES = {
    "int": (int,),
    "str": (str,),
    "float": (int, float),
    "float | None": (int, float, type(None)),
    "str | None": (str, type(None)),
}


def to_json(event: Event) -> dict:
    return {"event": event.name, **dataclasses.asdict(event)}


def from_json(data: dict) -> Event | None:
    """The event `data` describes, or None when it is not one (unknown name, missing or mistyped fields)."""
    if not isinstance(data, dict):
        return None
    cls = EVENT_TYPES.get(data.get("event"))
    if cls is None:
        return None
    values = {}
    for f in dataclasses.fields(cls):
        if f.name not in data:
            if f.default is dataclasses.MISSING:
                return None
            continue
        value = data[f.name]
        if isinstance(value, bool) or not isinstance(value, _FIELD_TYPES[f.type]):
            return None
        values[f.name] = value
    return cls(**values)


def to_line(event: Event) -> str:
    """One line of JSON (no NaN or infinity: JSON has none)."""
    data = to_json(event)
    data = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in data.items()}
    return json.dumps(data)


def parse(line: str) -> Event | None:
    """The event on a line of output, or None for anything else (Cycles and Blender print too)."""
    text = line.strip()
    if not text.startswith("{"):
        return None
    try:
        return from_json(json.loads(text))
    except ValueError:
        return None
