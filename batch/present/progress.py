"""Progress of a job for people or programs.

For programs (``--json-progress``): every `batch.events` event as one JSON line on stdout. For people: on a
terminal one live line per job (tqdm: passes done, passes per second, time left, and for ``check`` the current
evidence), with warnings and errors printed above it; elsewhere (a log file, a pipe, a CI log) plain lines on
stderr: a line per event, but a job's passes at most one line every `plain_interval` seconds (5), and while a
render process is polled (`Progress.tick`) a line at least that often saying how far each job is, so that a log
neither floods with fast passes nor goes quiet during slow ones. A reader that goes away (``--json-progress |
head -1``) does not stop the job: output stops, work goes on.
"""

from __future__ import annotations

import os
import sys
import threading
import time

from ..jobs import protocol
from . import fmt

#: Recent passes the ETA is estimated from: the first passes include start-up costs.
ETA_WINDOW = 16

#: What a brief plain log shows at once; its passes and looks come at most one line per `plain_interval`.
_BRIEF_EVENTS = (protocol.Warned, protocol.Failed)

#: Seconds between plain lines about passes (a log, not a terminal); WELCH_PROGRESS_SECONDS sets it.
PLAIN_INTERVAL = 5.0

#: A job that was polled within this many seconds is still going: the quiet log's line names it.
_TICKING = 1.0


def plain_interval() -> float:
    """`PLAIN_INTERVAL`, or WELCH_PROGRESS_SECONDS where it is a positive number."""
    try:
        seconds = float(os.environ.get("WELCH_PROGRESS_SECONDS", ""))
    except ValueError:
        return PLAIN_INTERVAL
    return seconds if 0 < seconds < float("inf") else PLAIN_INTERVAL


class _PlainLog:
    """This process's plain progress lines on stderr: when the last one was written, and the jobs polled lately
    by their labels (the quiet log's line is about all of them: the two sides of a check; a suite's next case's
    side takes the place of the last one's)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.last = time.monotonic()
        self.polled: dict[str, tuple[Progress, float]] = {}

    def write(self, line: str) -> None:
        with self.lock:
            print(line, file=sys.stderr, flush=True)
            self.last = time.monotonic()

    def tick(self, progress: Progress) -> None:
        now = time.monotonic()
        with self.lock:
            self.polled[progress.label] = (progress, now)
            self.polled = {k: (p, t) for k, (p, t) in self.polled.items() if now - t < _TICKING}
            if now - self.last < plain_interval():
                return
            line = "; ".join(p.status(now) for p, _ in self.polled.values())
            print(line, file=sys.stderr, flush=True)
            self.last = now


_PLAIN = _PlainLog()


class Progress:
    """Reports a job's events; `start`, `pass_done`, `warning`, `error` and `finished` make the events."""

    def __init__(
        self, total: int, json_lines: bool = False, label: str = "render", live: bool | None = None, brief=False
    ):
        self.total = total
        self.brief = brief  # plain lines only for looks, warnings and errors: a suite's log, not every pass
        self.json_lines = json_lines
        self.label = label
        self.done = 0
        self._times: list[float] = []
        self._silent = False
        # A live line only where someone watches a terminal; `live` overrides the guess (tests).
        self.live = (not json_lines and sys.stderr.isatty()) if live is None else live
        self._bar = None
        self._started = self._last_pass = time.monotonic()  # for the plain log's line about a job in progress
        self._last_line = float("-inf")  # when this job's last plain line about its passes was written

    def emit(self, event: protocol.Event) -> None:
        """Write one event: a JSON line on stdout, the live line, or a line for people on stderr (its passes, and
        a brief log's looks, at most one line per `plain_interval`)."""
        if self._silent:
            return
        if isinstance(event, protocol.PassDone):  # its own passes, or a render process's relayed
            self.done, self.total, self._last_pass = event.done, event.total, time.monotonic()
        try:
            if self.json_lines:
                print(protocol.to_line(event), flush=True)
            elif self.live:
                self._show(event)
            else:
                self._plain(event)
        except BrokenPipeError:
            self._silent = True  # nobody reads any more; the job itself goes on

    def _plain(self, event: protocol.Event) -> None:
        if isinstance(event, protocol.PassDone) or (self.brief and isinstance(event, protocol.Looked)):
            now = time.monotonic()
            if now - self._last_line < plain_interval():
                return  # the next line says how far it got
            self._last_line = now
        elif self.brief and not isinstance(event, _BRIEF_EVENTS):
            return
        _PLAIN.write(self.describe(event))

    def tick(self) -> None:
        """The job is being waited for (its render process polled): on a plain log, a line about how far every
        job polled lately is, where no line was written for `plain_interval` seconds."""
        if not (self.json_lines or self.live or self._silent):
            try:
                _PLAIN.tick(self)
            except BrokenPipeError:
                self._silent = True

    def status(self, now: float) -> str:
        """How far the job is, for the plain log's line when it has been quiet."""
        if self.done:
            since = f"{fmt.duration(now - self._last_pass)} since the last"
        else:
            since = f"{fmt.duration(now - self._started)} since the start"
        return f"{self.label}: {self.done}/{self.total} {'pass' if self.total == 1 else 'passes'}, {since}"

    def _show(self, event: protocol.Event) -> None:
        from tqdm import tqdm  # only for a terminal

        match event:
            case protocol.Started(total=total, todo=todo):
                self._bar = tqdm(total=total, initial=total - todo, desc=self.label, unit="pass", file=sys.stderr,
                                 dynamic_ncols=True, leave=True)  # fmt: skip
            case protocol.PassDone(done=done):
                if self._bar is not None:
                    self._bar.update(done - self._bar.n)
            case protocol.Looked(verdict=verdict):
                if self._bar is None:  # a count of looks and the time, no rate: looks come at the renders' pace
                    self._bar = tqdm(desc=self.label, file=sys.stderr, dynamic_ncols=True, leave=True,
                                     bar_format="{desc}: look {n_fmt} after {elapsed}{postfix}")  # fmt: skip
                self._bar.update(1)
                self._bar.set_postfix_str(self.describe(event).partition(": ")[2], refresh=True)
                if verdict is not None:
                    self._close()
            case protocol.Finished():
                self._close()
                tqdm.write(self.describe(event), file=sys.stderr)
            case protocol.Saved():
                pass
            case _:
                tqdm.write(self.describe(event), file=sys.stderr)

    def _close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def describe(self, event: protocol.Event) -> str:
        label = self.label
        match event:
            case protocol.Started(total=total, todo=todo, out=out):
                return f"{label}: {todo} of {fmt.count(total, 'pass')} to render into {out}"
            case protocol.PassDone(done=done, total=total, seed=seed, seconds=seconds, eta=eta):
                return f"{label}: pass {done}/{total} (seed {seed}) {seconds:.2f} s, ETA {fmt.duration(eta)}"
            case protocol.Warned(message=message):
                return f"warning: {message}"
            case protocol.Failed(message=message):
                return f"error: {message}"
            case protocol.Looked(passes=passes, p_value=p, threshold=threshold, ruled_out=bound, verdict=verdict):
                evidence = f"smallest p {fmt.p_value(p)} (stops at {fmt.p_value(threshold)})"
                bias = "no bound yet" if bound is None else f"a bias beyond {fmt.bound(bound)} ruled out"
                state = verdict if verdict is not None else f"{fmt.count(event.left, 'look')} left"
                rendered = f"rendering {fmt.duration(event.seconds)} (sides summed)"
                return f"{label}: {fmt.count(passes, 'pass')} a side, {rendered}: {evidence}; {bias}; {state}"
            case protocol.Saved(out=out, passes=passes):
                return f"{label}: saved {fmt.count(passes, 'pass')} in {out}"
            case protocol.Finished(out=out, passes=passes):
                return f"{label}: {fmt.count(passes, 'pass')} in {out}"
            case protocol.Probed(samples=samples, settings=settings):
                shown = ", ".join(f"{k.removeprefix('cycles.')} {v}" for k, v in sorted(settings.items()))
                return f"{label}: the scene renders {samples} samples; {shown or 'no settings read'}"
        raise TypeError(f"not a progress event: {event!r}")

    def start(self, done: int, out: str) -> None:
        self.done = done
        self.emit(protocol.Started(total=self.total, todo=self.total - done, out=out))

    def pass_done(self, seed: int, seconds: float) -> None:
        self.done += 1
        self._times.append(seconds)
        recent = self._times[-ETA_WINDOW:]
        eta = sum(recent) / len(recent) * (self.total - self.done)
        self.emit(protocol.PassDone(done=self.done, total=self.total, seed=seed, seconds=seconds, eta=eta))

    def warning(self, message: str) -> None:
        self.emit(protocol.Warned(message=message))

    def error(self, message: str) -> None:
        self._close()
        self.emit(protocol.Failed(message=message))

    def finished(self, out: str, passes: int) -> None:
        self.emit(protocol.Finished(out=out, passes=passes))
