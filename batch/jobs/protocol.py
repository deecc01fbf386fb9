"""What crosses between the tool's processes, defined once: a render job's progress events, the chunk requests
a serving job takes on stdin, and the exit codes of every process and what each means. Each has one way out
and one way in (`to_line` / `parse`, `ChunkRequest.to_line` / `parse_request`), and every sender and receiver
(the command line, ``check``, the suites, the Dask workers, the Blender add-on) uses them.

A job run with ``--json-progress`` writes each event as one JSON object on its own line of stdout, e.g.
``{"event": "pass", "done": 3, "total": 8, "seed": 2, "seconds": 0.21, "eta": 1.05}``; whoever started it reads
the lines back with `parse`, which skips anything else a renderer prints.
"""

from __future__ import annotations

import dataclasses
import json
import math
import signal
from dataclasses import dataclass
from typing import ClassVar

from ..errors import Exit


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


@dataclass(frozen=True)
class Probed:
    """What a scene asks of the passes (``render --probe``): its own samples per render, and its settings that act
    only above some samples (`batch.jobs.samples.SceneSamples`)."""

    name: ClassVar[str] = "scene"
    samples: int
    settings: dict


Event = Started | PassDone | Warned | Failed | Saved | Looked | Finished | Probed

EVENT_TYPES: dict[str, type] = {
    cls.name: cls for cls in (Started, PassDone, Warned, Failed, Saved, Looked, Finished, Probed)
}

_FIELD_TYPES = {
    "int": (int,),
    "str": (str,),
    "float": (int, float),
    "float | None": (int, float, type(None)),
    "str | None": (str, type(None)),
    "dict": (dict,),
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


# -- chunk requests ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ChunkRequest:
    """A serving job's request for exactly `seeds` (all among the job's seeds), rendered into a new statistics
    file `out` that holds those passes only; the job answers with a `Saved` event for `out`. A worker asks for
    its chunks this way (`batch.jobs.distributed`).

    On the job's stdin it is one JSON line, ``{"seeds": [4, 5, 6], "out": "/dev/shm/chunk-3.npz"}``: `to_line`
    writes it, `parse_request` reads it (a plain count ``N`` asks for the job's next N seeds instead).
    """

    seeds: tuple[int, ...]
    out: str

    def __post_init__(self):
        object.__setattr__(self, "seeds", tuple(self.seeds))

    def to_line(self) -> str:
        return json.dumps({"seeds": list(self.seeds), "out": self.out})


def parse_request(line: str) -> int | ChunkRequest | None:
    """What a line of a serving job's stdin asks for: a number of passes, a `ChunkRequest`, or None (anything
    else, which ends the job)."""
    text = line.strip()
    if not text.startswith("{"):
        try:
            return int(text)
        except ValueError:
            return None
    try:
        data = json.loads(text)
    except ValueError:
        return None
    if not isinstance(data, dict) or set(data) != {"seeds", "out"}:
        return None
    seeds, out = data["seeds"], data["out"]
    if not isinstance(seeds, list) or not all(isinstance(s, int) and not isinstance(s, bool) for s in seeds):
        return None
    if not isinstance(out, str) or not out:
        return None
    return ChunkRequest(tuple(seeds), out)


# -- verdicts and exit codes ---------------------------------------------------------------------------------


#: What each verdict (by its label) means where the two sides should converge to the same image: the status of a
#: suite case, a matrix cell or a JUnit test, and the exit code of the process. The one table of it.
VERDICTS = {
    "biased": ("failed", Exit.BIASED),
    "equivalent": ("passed", Exit.OK),
    "no_evidence": ("passed", Exit.OK),
    "inconclusive": ("inconclusive", Exit.INCONCLUSIVE),
}


#: The statuses of a suite case that count against the suite (a JUnit failure, exit code 3 unless a case is biased):
#: its verdict is not the expected one, it decided nothing, or it could not have found a bias of its tolerance.
FAILING = ("failed", "inconclusive", "underpowered")


def verdict_exit(verdict) -> Exit:
    """The exit code of a `welch_core.Verdict` (or its label)."""
    return VERDICTS[str(verdict)][1]


def verdict_status(verdict) -> str:
    """The status of a `welch_core.Verdict` (or its label) where no difference is expected."""
    return VERDICTS[str(verdict)][0]


def interrupted(code: int | None) -> bool:
    """Whether a process that ended with `code` was interrupted: it exited 130, or a signal (SIGINT, SIGTERM)
    ended it before it could (Popen's negative codes, a shell's 128 + signal)."""
    signals = (signal.SIGINT, signal.SIGTERM)
    return code is not None and (code == Exit.INTERRUPTED or -code in signals or code - 128 in signals)


class SigtermAsInterrupt:
    """While active, SIGTERM (a job scheduler's or the add-on's cancel) stops this process as Ctrl-C does: the
    handler raises KeyboardInterrupt in the main thread, so a check saves its state and its sides, a cluster's
    outstanding chunks are cancelled, and the process exits `Exit.INTERRUPTED` saying so. (A render process
    only notes the signal, `batch.blender.run.StopRequest`: there, raising could land inside Blender.)"""

    def __enter__(self) -> SigtermAsInterrupt:
        self._old = None
        try:
            self._old = signal.signal(signal.SIGTERM, self._raise)
        except ValueError:  # not the main thread: leave signals alone
            pass
        return self

    @staticmethod
    def _raise(_signum, _frame) -> None:
        raise KeyboardInterrupt

    def __exit__(self, *_exc) -> bool:
        if self._old is not None:
            signal.signal(signal.SIGTERM, self._old)
        return False
