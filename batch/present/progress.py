"""Progress of a job for people or programs.

For programs (``--json-progress``): every `batch.events` event as one JSON line on stdout. For people: on a
terminal one live line per job (tqdm: passes done, passes per second, time left, and for ``check`` the current
evidence), with warnings and errors printed above it; elsewhere (a log file, a pipe) a plain line per event on
stderr. A reader that goes away (``--json-progress | head -1``) does not stop the job: output stops, work goes on.
"""

from __future__ import annotations

import sys

from ..jobs import protocol
from . import fmt

#: Recent passes the ETA is estimated from: the first passes include start-up costs.
ETA_WINDOW = 16

#: What a brief plain log shows.
_BRIEF_EVENTS = (protocol.Warned, protocol.Failed)


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

    def emit(self, event: protocol.Event) -> None:
        """Write one event: a JSON line on stdout, the live line, or a line for people on stderr."""
        if self._silent:
            return
        if self.brief and not (self.json_lines or self.live) and not isinstance(event, _BRIEF_EVENTS):
            return
        try:
            if self.json_lines:
                print(protocol.to_line(event), flush=True)
            elif self.live:
                self._show(event)
            else:
                print(self.describe(event), file=sys.stderr, flush=True)
        except BrokenPipeError:
            self._silent = True  # nobody reads any more; the job itself goes on

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
                if self._bar is None:
                    self._bar = tqdm(desc=self.label, unit="look", file=sys.stderr, dynamic_ncols=True, leave=True)
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
                return f"{label}: {todo} of {total} passes to render into {out}"
            case protocol.PassDone(done=done, total=total, seed=seed, seconds=seconds, eta=eta):
                return f"{label}: pass {done}/{total} (seed {seed}) {seconds:.2f} s, ETA {fmt.duration(eta)}"
            case protocol.Warned(message=message):
                return f"warning: {message}"
            case protocol.Failed(message=message):
                return f"error: {message}"
            case protocol.Looked(passes=passes, p_value=p, threshold=threshold, ruled_out=bound, verdict=verdict):
                evidence = f"smallest p {fmt.p_value(p)} (stops at {fmt.p_value(threshold)})"
                bias = "no bound yet" if bound is None else f"a bias beyond {fmt.percent(bound).lstrip('+')} ruled out"
                state = verdict if verdict is not None else f"{event.left} looks left"
                return f"{label}: {passes} passes a side, {fmt.duration(event.seconds)}: {evidence}; {bias}; {state}"
            case protocol.Saved(out=out, passes=passes):
                return f"{label}: saved {passes} passes in {out}"
            case protocol.Finished(out=out, passes=passes):
                return f"{label}: {passes} passes in {out}"
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
