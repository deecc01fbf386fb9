"""Render the sides of a comparison as background jobs and follow their progress, without bpy.

The modal operator calls these on a timer: :class:`Session` runs the reference side, then the test side, each
a `batch.jobs.job.RenderJob` started through `batch.jobs.launch` (its ``--json-progress`` events read by threads, so the
UI never blocks on a pipe), and turns their events into one progress fraction, a status line and, on failure,
a one-line error.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ._siblings import errors, fmt, job, launch, protocol, seeds

MAX_SEED = seeds.MAX_SEED  # Cycles' seed is a non-negative 32-bit int
MAX_FIRST_SEED = 2**30  # leaves room for two sides of up to 2**29 passes

RUNNING = "RUNNING"
FINISHED = "FINISHED"
FAILED = "FAILED"
CANCELLED = "CANCELLED"


def seed_ranges(first: int, passes: int, paired: bool) -> tuple[range, range]:
    """Seeds of the reference and test sides.

    Unpaired runs need disjoint seeds because the same seed renders the same image; a paired run uses the same
    seeds on purpose so per-pass differences cancel the shared noise.
    """
    if first < 0 or passes < 1:
        raise ValueError(f"seeds need first >= 0 and passes >= 1, got first={first}, passes={passes}")
    if first + 2 * passes - 1 > MAX_SEED:
        raise ValueError(f"seeds must stay below {MAX_SEED + 1}, got first={first}, passes={passes}")
    reference = range(first, first + passes)
    test = reference if paired else range(first + passes, first + 2 * passes)
    return reference, test


@dataclass(frozen=True)
class Side:
    """One side of the comparison: its name for people and its render job."""

    label: str
    job: job.RenderJob


@dataclass
class Progress:
    """What the last progress event of the running side said."""

    done: int = 0
    total: int = 0
    seconds: float = 0.0
    eta: float | None = None


def overall_fraction(step: int, steps: int, done: int, total: int) -> float:
    """Progress over all sides in [0, 1]; each side counts the same (they render the same number of passes)."""
    if steps <= 0:
        return 1.0
    within = min(max(done / total, 0.0), 1.0) if total > 0 else 0.0
    return min((min(step, steps) + within) / steps, 1.0)


@dataclass
class Session:
    """The sides of one comparison, rendered one after the other.

    Call :meth:`poll` regularly (from a timer or a loop): it starts the next side when one finishes and returns
    the state, one of ``RUNNING``, ``FINISHED``, ``FAILED`` or ``CANCELLED``. `commands` default to
    `batch.jobs.launch.job_command` of each side's job. `temporary_files` are deleted when the session finishes.
    """

    sides: list[Side]
    commands: list[launch.Command] = field(default_factory=list)
    temporary_files: list[str] = field(default_factory=list)
    launcher: Callable[[launch.Command], launch.JobProcess] = launch.JobProcess
    state: str = RUNNING
    step: int = 0
    progress: Progress = field(default_factory=Progress)
    error: str = ""
    warnings: list[str] = field(default_factory=list)
    process: launch.JobProcess | None = None

    def __post_init__(self):
        if not self.sides:
            raise ValueError("a session needs at least one side")
        if not self.commands:
            self.commands = [launch.job_command(side.job) for side in self.sides]
        if len(self.commands) != len(self.sides):
            raise ValueError("a session needs one command per side")

    @property
    def fraction(self) -> float:
        if self.state == FINISHED:
            return 1.0
        return overall_fraction(self.step, len(self.sides), self.progress.done, self.progress.total)

    @property
    def label(self) -> str:
        return self.sides[min(self.step, len(self.sides) - 1)].label

    def status_text(self) -> str:
        """One line for the status bar and the panel."""
        if self.state != RUNNING:
            return {FINISHED: "Finished", FAILED: f"Failed: {self.error}", CANCELLED: "Cancelled"}[self.state]
        p = self.progress
        if p.total <= 0:
            return f"{self.label}: starting"
        return f"{self.label}: pass {p.done}/{p.total}, {fmt.duration(p.eta)} left for this side"

    def poll(self) -> str:
        if self.state != RUNNING:
            return self.state
        if self.process is None:
            self._start_step()
            if self.state != RUNNING:
                return self.state
        for event in self.process.drain():
            self._apply(event)
        code = self.process.poll()
        if code is not None:
            for event in self.process.drain():
                self._apply(event)
            self._step_ended(code)
        return self.state

    def _start_step(self) -> None:
        self.progress = Progress()
        try:
            self.process = self.launcher(self.commands[self.step])
        except (OSError, errors.BatchError) as ex:
            self._fail(f"{self.label} run could not start: {ex}")

    def _apply(self, event: protocol.Event) -> None:
        match event:
            case protocol.Started(total=total, todo=todo):
                # A resumed run starts with the passes already in its statistics file.
                self.progress.total, self.progress.done = total, total - todo
            case protocol.PassDone(done=done, total=total, seconds=seconds, eta=eta):
                self.progress.done, self.progress.total = done, total
                self.progress.seconds, self.progress.eta = seconds, eta
            case protocol.Finished(passes=passes):
                self.progress.done = self.progress.total = max(passes, self.progress.total)
            case protocol.Warned(message=message):
                self.warnings.append(fmt.one_line(f"{self.label}: {message}"))

    def _step_ended(self, code: int) -> None:
        side = self.sides[self.step]
        if code != 0:
            reason = self.process.error_message() or "no error message"
            self._fail(f"{side.label} run failed (exit code {code}): {reason}")
            return
        if not Path(side.job.out).is_file():
            self._fail(f"{side.label} run ended without writing {side.job.out}")
            return
        self.process = None
        self.progress = Progress()
        self.step += 1
        if self.step == len(self.sides):
            self.state = FINISHED
            self.remove_temporary_files()

    def _fail(self, message: str) -> None:
        # The temporary files stay: a failed run may be resumed, with the very scene it started from.
        self.state = FAILED
        self.error = fmt.one_line(message)

    def cancel(self) -> None:
        """Stop the running side after its current pass; its statistics (and the temporary files it renders
        from) stay, so the run can be resumed."""
        if self.state != RUNNING:
            return
        if self.process is not None:
            self.process.stop()
        self.state = CANCELLED

    def wait(self, interval: float = 0.1, timeout: float | None = None) -> str:
        """Poll until the session ends (for scripts and tests; the UI polls from a timer instead)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() == RUNNING:
            if deadline is not None and time.monotonic() > deadline:
                self.cancel()
                break
            time.sleep(interval)
        return self.state

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
