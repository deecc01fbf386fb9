"""What crosses between the tool's processes, defined once: a render job's progress events, the chunk requests
a serving job takes on stdin, and the exit codes of every process and what each means. Each has one way out
and one way in (`to_line` / `parse`, `ChunkRequest.to_line` / `parse_request`), and every sender and receiver
(the command line, ``check``, the suites, the Dask workers, the Blender add-on) uses them. How every process of the
tool takes Ctrl-C and SIGTERM is here too (`Interrupts`): standard library only, the entry point imports it first.

A job run with ``--json-progress`` writes each event as one JSON object on its own line of stdout, e.g.
``{"event": "pass", "done": 3, "total": 8, "seed": 2, "seconds": 0.21, "eta": 1.05}``; whoever started it reads
the lines back with `parse`, which skips anything else a renderer prints.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import json
import logging
import math
import signal
import sys
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


class CaseStatus(enum.StrEnum):
    """What became of a suite case or a matrix cell (the value is its key in report files, JUnit and the dashboard;
    a member equals it as a string)."""

    PASSED = "passed"  # the verdict the case expects, where it could have failed
    FAILED = "failed"  # another verdict than the case expects
    INCONCLUSIVE = "inconclusive"  # no verdict within the budget
    UNDERPOWERED = "underpowered"  # nothing found, but a bias of the tolerance could hide
    SKIPPED = "skipped"  # not run here (no GPU)
    ERROR = "error"  # could not run


#: What each verdict (by its label) means where the two sides should converge to the same image: the status of a
#: suite case, a matrix cell or a JUnit test, and the exit code of the process. The one table of it.
VERDICTS = {
    "biased": (CaseStatus.FAILED, Exit.BIASED),
    "equivalent": (CaseStatus.PASSED, Exit.OK),
    "no_evidence": (CaseStatus.PASSED, Exit.OK),
    "inconclusive": (CaseStatus.INCONCLUSIVE, Exit.INCONCLUSIVE),
}


#: The statuses of a suite case that count against the suite (a JUnit failure, exit code 3 unless a case is biased):
#: its verdict is not the expected one, it decided nothing, or it could not have found a bias of its tolerance.
FAILING = (CaseStatus.FAILED, CaseStatus.INCONCLUSIVE, CaseStatus.UNDERPOWERED)


def verdict_exit(verdict) -> Exit:
    """The exit code of a `welch_core.Verdict` (or its label)."""
    return VERDICTS[str(verdict)][1]


def verdict_status(verdict) -> CaseStatus:
    """The status of a `welch_core.Verdict` (or its label) where no difference is expected."""
    return VERDICTS[str(verdict)][0]


def interrupted(code: int | None) -> bool:
    """Whether a process that ended with `code` was interrupted: it exited 130, or a signal (SIGINT, SIGTERM)
    ended it before it could (Popen's negative codes, a shell's 128 + signal)."""
    signals = (signal.SIGINT, signal.SIGTERM)
    return code is not None and (code == Exit.INTERRUPTED or -code in signals or code - 128 in signals)


def take_signals(signums, handler, keep=(signal.SIG_IGN,)) -> dict:
    """Handle `signums` with `handler`, but where a signal's handler now is one of `keep` (one the process was told
    to ignore) and outside the main thread (where Python can't): the handlers replaced, by signal."""
    replaced = {}
    for signum in signums:
        if signal.getsignal(signum) in keep:
            continue
        try:
            replaced[signum] = signal.signal(signum, handler)
        except ValueError:  # not the main thread: leave signals alone
            pass
    return replaced


def give_back_signals(replaced: dict) -> None:
    """Put back the handlers `take_signals` replaced; None (a handler installed from C, such as Blender's, which
    Python can't put back) stays replaced."""
    for signum, old in replaced.items():
        if old is not None:
            signal.signal(signum, old)


class Interrupts:
    """While active, Ctrl-C (SIGINT) and SIGTERM (a job scheduler's or the add-on's cancel) stop this process the
    same way: the handler notes the signal and raises KeyboardInterrupt in the main thread, so a check saves its
    state and stops its sides, a cluster's outstanding chunks are cancelled, and the process exits
    `Exit.INTERRUPTED` saying `batch.errors.INTERRUPTED_LINE`. Wherever the KeyboardInterrupt lands,
    `interrupted` knows an exception for the interrupt's, also one it turned into another (inside an import, an
    extension module raises ImportError; a library wraps what it caught): by the note of the signal, or by the
    KeyboardInterrupt in the exception's chain. Where a library swallowed it, or it landed where Python can't
    raise it (a weakref callback, a ``__del__``: it is not printed), and the tool went on, the waits for a render
    (`batch.jobs.side.Side.poll`, a render loop's `batch.blender.run.StopRequest`) ask `pending` and raise it
    again.

    A signal this process was told to ignore (a background job of a non-interactive shell, a Dask worker's
    render process) stays ignored, and a handler installed from C (Blender's), which Python could not put back,
    is left alone. (A render process only notes the signal while it renders, `batch.blender.run.StopRequest`:
    there, raising could land inside Blender.)"""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    #: The instances now active in this process (nested: the entry point's, then the command line's).
    _active: list[Interrupts] = []
    _holding = 0  # `held` blocks running: a signal then raises at their end
    _deferred = False  # a signal came while held

    def __init__(self):
        self.received: int | None = None  # the first signal that came while active
        self._old: dict = {}
        self._unraisable = None  # the hook this one replaced while active
        self._logging: int | None = None  # the level logging was disabled at before the signal

    @classmethod
    def pending(cls) -> bool:
        """Whether a signal came to an instance that is still active: this process was interrupted."""
        return any(active.received is not None for active in cls._active)

    def __enter__(self) -> Interrupts:
        Interrupts._active.append(self)
        self._unraisable, sys.unraisablehook = sys.unraisablehook, self._ignore_interrupt
        self._old = take_signals(self.SIGNALS, self._raise, keep=(signal.SIG_IGN, None))
        return self

    @classmethod
    @contextlib.contextmanager
    def held(cls):
        """A block that an interrupt does not cut in two (a render process started and recorded, so that it is
        stopped with the others): a signal that comes while it runs raises KeyboardInterrupt at its end."""
        cls._holding += 1
        try:
            yield
        finally:
            cls._holding -= 1
            if not cls._holding and cls._deferred:
                cls._deferred = False
                raise KeyboardInterrupt  # (what the block raised, if anything, is its context)

    def _raise(self, signum, _frame) -> None:
        if self.received is None:
            self.received = signum
            # What stops on the way out (a Dask cluster cancelling its tasks) logs nothing: the process says one line.
            self._logging = logging.root.manager.disable
            logging.disable(logging.CRITICAL)
        if Interrupts._holding:
            Interrupts._deferred = True
            return
        raise KeyboardInterrupt

    def _ignore_interrupt(self, unraisable) -> None:
        """`sys.unraisablehook`: an interrupt where it can't be raised is noted already, and not printed."""
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            self._unraisable(unraisable)

    def __exit__(self, *_exc) -> bool:
        give_back_signals(self._old)
        self._old = {}
        if self._unraisable is not None:
            sys.unraisablehook, self._unraisable = self._unraisable, None
        if self._logging is not None:
            logging.disable(self._logging)
            self._logging = None
        if self in Interrupts._active:
            Interrupts._active.remove(self)
        return False

    def interrupted(self, exc: BaseException | None = None) -> bool:
        """Whether `exc` is the interrupt's: a signal came while active, or a KeyboardInterrupt is `exc` or in the
        chain of exceptions it was raised from or during (``__cause__``, ``__context__``)."""
        if self.received is not None:
            return True
        todo, seen = [exc], set()
        while todo:
            exc = todo.pop()
            if exc is None or id(exc) in seen:
                continue
            if isinstance(exc, KeyboardInterrupt):
                return True
            seen.add(id(exc))
            todo += [exc.__cause__, exc.__context__]
        return False
