"""Run a check (`batch.decide.check`, the engine of ``python -m batch check``) from a timer, without bpy.

The modal operator calls :meth:`CheckRun.poll` on a timer: each call steps the check for a few milliseconds (the
render processes work in the background, so a step never waits for a pass) and turns its events into a progress
fraction, a status line and, after each look, the look itself for a live map. Stop closes the check: its render
processes finish their pass and save, and its state stays in the run folder, so a later run with ``--resume``
continues it, exactly as Ctrl-C and ``--resume`` on the command line.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from . import _siblings
from ._siblings import errors, fmt, protocol, welch_core

RUNNING = "RUNNING"
FINISHED = "FINISHED"
FAILED = "FAILED"
CANCELLED = "CANCELLED"

#: Seconds of stepping per poll: short enough for the UI, long enough to relay a chunk's events.
STEP_SECONDS = 0.02


@dataclass
class SideProgress:
    """What the last events of one side said (its passes saved so far, its speed)."""

    name: str
    done: int = 0
    total: int = 0
    seconds: float = 0.0

    def emit(self, event) -> None:
        match event:
            case protocol.Started(total=total, todo=todo):
                self.total, self.done = total, total - todo
            case protocol.PassDone(done=done, total=total, seconds=seconds):
                self.done, self.total, self.seconds = done, total, seconds


@dataclass
class CheckRun:
    """One check, polled: its state (``RUNNING``, ``FINISHED``, ``FAILED`` or ``CANCELLED``), progress, the last
    look (for a live map) and, when finished, its result: (the final look, both sides' statistics)."""

    job: object  # a batch.decide.check_job.CheckJob
    temporary_files: list[str] = field(default_factory=list)
    env: dict | None = None  # the render processes' environment (default: this process's)
    state: str = RUNNING
    error: str = ""
    warnings: list[str] = field(default_factory=list)
    sides: dict[str, SideProgress] = field(default_factory=dict)
    looked: object = None  # the last protocol.Looked event
    new_look: bool = False  # a look arrived since `take_look` was last called
    result: tuple | None = None

    live = False  # what the check asks of its progress: no terminal lines here

    def __post_init__(self):
        self.check = _siblings.check.Check(self.job, self, side_progress=self._side, env=self.env)
        self._steps = self.check.steps()

    def _side(self, name: str) -> SideProgress:
        self.sides[name] = SideProgress(name)
        return self.sides[name]

    # -- what the check reports to its progress ----------------------------------------------------------------

    def emit(self, event) -> None:
        if isinstance(event, protocol.Looked):
            self.looked, self.new_look = event, True

    def warning(self, message: str) -> None:
        self.warnings.append(fmt.one_line(message))

    # -- polling -----------------------------------------------------------------------------------------------

    def poll(self) -> str:
        if self.state != RUNNING:
            return self.state
        deadline = time.monotonic() + STEP_SECONDS
        try:
            while time.monotonic() < deadline:
                next(self._steps)
                if self.new_look:
                    break  # let the caller show it
        except StopIteration as done:
            self.result, self.state = done.value, FINISHED
            self.remove_temporary_files()
        except KeyboardInterrupt:
            self.state = CANCELLED
        except (errors.BatchError, welch_core.WelchInputError, RuntimeError, OSError) as ex:
            self.state, self.error = FAILED, fmt.one_line(str(ex))
        return self.state

    def take_look(self):
        """The last look and both sides' statistics then, once per look (None: no new one)."""
        if not self.new_look:
            return None
        self.new_look = False
        return self.check.last_look

    def cancel(self) -> None:
        """Stop now: the render processes finish their pass and save, the check's state is kept for a resume."""
        if self.state != RUNNING:
            return
        self._steps.close()
        self.state = CANCELLED

    def wait(self, interval: float = 0.05, timeout: float | None = None) -> str:
        """Poll until the check ends (for scripts and tests; the UI polls from a timer instead)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() == RUNNING:
            if deadline is not None and time.monotonic() > deadline:
                self.cancel()
                break
            time.sleep(interval)
        return self.state

    # -- what the panel shows ----------------------------------------------------------------------------------

    @property
    def budget(self) -> int:
        return self.check.budget or self.job.max_passes or 0

    @property
    def passes(self) -> int:
        """Passes a side saved so far (the slower side's)."""
        return min((s.done for s in self.sides.values()), default=0)

    @property
    def fraction(self) -> float:
        if self.state == FINISHED:
            return 1.0
        return min(self.passes / self.budget, 1.0) if self.budget else 0.0

    def status_text(self) -> str:
        """One line for the status bar and the panel."""
        if self.state != RUNNING:
            return {FINISHED: "Finished", FAILED: f"Failed: {self.error}", CANCELLED: "Stopped"}[self.state]
        if not self.passes:
            return "Starting the renders"
        text = f"pass {self.passes}/{self.budget} a side"
        look = self.looked
        if look is not None:
            bound = f"; a bias beyond {fmt.bound(look.ruled_out)} ruled out" if look.ruled_out else ""
            text += f", smallest p {fmt.p_value(look.p_value)} (stops at {fmt.p_value(look.threshold)}){bound}"
        return text

    def remove_temporary_files(self) -> None:
        for path in self.temporary_files:
            try:
                os.remove(path)
            except FileNotFoundError:
                pass
        self.temporary_files = []


def prune_runs(runs_dir: str | os.PathLike, keep: int, protect: Sequence[str | os.PathLike] = ()) -> list[Path]:
    """Delete all but the ``keep`` newest run folders (by name, which starts with a timestamp)."""
    root = Path(runs_dir)
    if not root.is_dir():
        return []
    protected = {Path(p).resolve() for p in protect}
    folders = sorted((p for p in root.iterdir() if p.is_dir()), key=lambda p: p.name, reverse=True)
    removed = []
    for folder in folders[max(keep, 0) :]:
        if folder.resolve() not in protected:
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed
