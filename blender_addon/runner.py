"""Run the batch tool as subprocesses and follow their progress, without bpy.

The modal operator calls these on a timer: :class:`Session` runs the reference side, then the test side, reads
the ``--json-progress`` lines of each through a reader thread (so the UI never blocks on a pipe), and turns them
into one progress fraction, a status line and, on failure, a one-line error.
"""

from __future__ import annotations

import collections
import json
import os
import queue
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ._siblings import batch

MAX_SEED = batch.seeds.MAX_SEED  # Cycles' seed is a non-negative 32-bit int

RUNNING = "RUNNING"
FINISHED = "FINISHED"
FAILED = "FAILED"
CANCELLED = "CANCELLED"

EVENTS = ("start", "pass", "warning", "done", "error")
MAX_FIRST_SEED = 2**30  # leaves room for two sides of up to 2**29 passes
ERROR_LENGTH = 200  # characters kept of an error line: one line in the status bar and in a report
TAIL_LINES = 20  # output lines kept per stream for error messages


def seed_ranges(first: int, passes: int, paired: bool) -> tuple[str, str]:
    """``--seeds`` values (half-open ``A:B``) of the reference and test sides.

    Unpaired runs need disjoint seeds because the same seed renders the same image; a paired run uses the same
    seeds on purpose so per-pass differences cancel the shared noise.
    """
    if first < 0 or passes < 1:
        raise ValueError(f"seeds need first >= 0 and passes >= 1, got first={first}, passes={passes}")
    if first + 2 * passes - 1 > MAX_SEED:
        raise ValueError(f"seeds must stay below {MAX_SEED + 1}, got first={first}, passes={passes}")
    reference = f"{first}:{first + passes}"
    test = reference if paired else f"{first + passes}:{first + 2 * passes}"
    return reference, test


@dataclass(frozen=True)
class RunSpec:
    """One side of the comparison: which file to render, how, and where its statistics go."""

    label: str
    blend: str
    out: str
    seeds: str
    spp: int = 1
    tile: int = 32
    overrides: tuple[str, ...] = ()
    resume: bool = False
    blend_scene: str = ""
    device: str = "CPU"


@dataclass(frozen=True)
class Command:
    argv: list[str]
    cwd: str
    env: dict[str, str]


def render_arguments(spec: RunSpec) -> list[str]:
    """Arguments of ``batch render`` after the .blend file."""
    args = ["--json-progress", "--seeds", spec.seeds, "--spp", str(spec.spp), "--tile", str(spec.tile)]
    args += ["--device", spec.device]
    if spec.blend_scene:
        args += ["--blend-scene", spec.blend_scene]
    for override in spec.overrides:
        args += ["--set", override]
    if spec.resume:
        args.append("--resume")
    return [*args, "--out", spec.out]


def command_for(
    spec: RunSpec,
    extension_root: str | os.PathLike,
    blender_binary: str = "",
    python: str = sys.executable,
    python_paths: Sequence[str] = (),
    base_env: dict[str, str] | None = None,
) -> Command:
    """The command line of one side.

    With a Blender binary: ``blender -b COPY.blend --python-exit-code 1 --python batch/blender_entry.py -- render
    ...`` (the file Blender opened is the one rendered). With the bpy module (no binary): ``python -m batch render
    COPY.blend ...`` from the extension root, which holds the ``batch`` package.
    """
    root = str(Path(extension_root).resolve())
    env = dict(os.environ if base_env is None else base_env)
    # Progress lines must arrive as they are printed, not when a pipe buffer fills.
    env["PYTHONUNBUFFERED"] = "1"
    if blender_binary:
        entry = str(Path(root) / "batch" / "blender_entry.py")
        argv = [blender_binary, "-b", spec.blend, "--python-exit-code", "1", "--python", entry, "--", "render"]
        return Command([*argv, *render_arguments(spec)], root, env)
    paths = [root, *python_paths, *filter(None, env.get("PYTHONPATH", "").split(os.pathsep))]
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    return Command([python, "-m", "batch", "render", spec.blend, *render_arguments(spec)], root, env)


def parse_progress_line(line: str) -> dict | None:
    """The progress event on a line of output, or None for anything else (Cycles and Blender print too)."""
    text = line.strip()
    if not text.startswith("{"):
        return None
    try:
        event = json.loads(text)
    except ValueError:
        return None
    if not isinstance(event, dict) or event.get("event") not in EVENTS:
        return None
    return event


def one_line(text: str, limit: int = ERROR_LENGTH) -> str:
    """Whitespace collapsed to single spaces and cut to ``limit`` characters."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


class BatchProcess:
    """A subprocess whose stdout and stderr are read by threads, so polling never blocks."""

    def __init__(self, command: Command):
        self.events: queue.Queue[dict] = queue.Queue()
        self.stdout_tail: collections.deque[str] = collections.deque(maxlen=TAIL_LINES)
        self.stderr_tail: collections.deque[str] = collections.deque(maxlen=TAIL_LINES)
        self.popen = subprocess.Popen(
            command.argv,
            cwd=command.cwd,
            env=command.env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            encoding="utf-8",
            errors="replace",
            bufsize=1,
        )
        self._threads = [
            threading.Thread(target=self._read_stdout, daemon=True),
            threading.Thread(target=self._read, args=(self.popen.stderr, self.stderr_tail), daemon=True),
        ]
        for thread in self._threads:
            thread.start()

    def _read_stdout(self) -> None:
        for line in self.popen.stdout:
            event = parse_progress_line(line)
            if event is None:
                if line.strip():
                    self.stdout_tail.append(line.rstrip())
            else:
                self.events.put(event)

    @staticmethod
    def _read(stream, tail: collections.deque) -> None:
        for line in stream:
            if line.strip():
                tail.append(line.rstrip())

    def drain(self) -> list[dict]:
        """Progress events received since the last call."""
        events = []
        while True:
            try:
                events.append(self.events.get_nowait())
            except queue.Empty:
                return events

    def poll(self) -> int | None:
        """The exit code once the process has ended and its output has been read, else None."""
        code = self.popen.poll()
        if code is None or any(t.is_alive() for t in self._threads):
            return None
        return code

    def wait(self, timeout: float | None = None) -> int:
        code = self.popen.wait(timeout)
        for thread in self._threads:
            thread.join(timeout)
        return code

    def terminate(self, timeout: float = 5.0) -> None:
        """Stop the process (killing it if it ignores the request) and wait for it."""
        if self.popen.poll() is None:
            self.popen.terminate()
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.popen.kill()
        self.wait(timeout)

    def output_error(self) -> str:
        """The most telling line of output for a failure: stderr's last line, else stdout's."""
        for tail in (self.stderr_tail, self.stdout_tail):
            if tail:
                return tail[-1]
        return ""


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


def format_seconds(seconds: float | None) -> str:
    if seconds is None or seconds != seconds or seconds < 0:
        return "?"
    seconds = round(seconds)
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"


@dataclass
class Session:
    """The sides of one comparison, rendered one after the other.

    Call :meth:`poll` regularly (from a timer or a loop): it starts the next side when one finishes and returns
    the state, one of ``RUNNING``, ``FINISHED``, ``FAILED`` or ``CANCELLED``.
    """

    specs: list[RunSpec]
    commands: list[Command]
    temporary_files: list[str] = field(default_factory=list)
    launcher: Callable[[Command], BatchProcess] = BatchProcess
    state: str = RUNNING
    step: int = 0
    progress: Progress = field(default_factory=Progress)
    error: str = ""
    warnings: list[str] = field(default_factory=list)
    process: BatchProcess | None = None
    _last_error_event: str = ""

    def __post_init__(self):
        if len(self.specs) != len(self.commands) or not self.specs:
            raise ValueError("a session needs one command per side and at least one side")

    @property
    def fraction(self) -> float:
        if self.state == FINISHED:
            return 1.0
        return overall_fraction(self.step, len(self.specs), self.progress.done, self.progress.total)

    @property
    def label(self) -> str:
        return self.specs[min(self.step, len(self.specs) - 1)].label

    def status_text(self) -> str:
        """One line for the status bar and the panel."""
        if self.state != RUNNING:
            return {FINISHED: "Finished", FAILED: f"Failed: {self.error}", CANCELLED: "Cancelled"}[self.state]
        p = self.progress
        if p.total <= 0:
            return f"{self.label}: starting"
        return f"{self.label}: pass {p.done}/{p.total}, {format_seconds(p.eta)} left for this side"

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
        self._last_error_event = ""
        try:
            self.process = self.launcher(self.commands[self.step])
        except OSError as ex:
            self._fail(f"{self.label} run could not start: {ex}")

    def _apply(self, event: dict) -> None:
        kind = event.get("event")
        if kind == "start":
            self.progress.total = int(event.get("total") or 0)
            # A resumed run starts with the passes already in its statistics file.
            self.progress.done = self.progress.total - int(event.get("todo", self.progress.total) or 0)
        elif kind == "pass":
            self.progress.done = int(event.get("done") or 0)
            self.progress.total = int(event.get("total") or self.progress.total)
            self.progress.seconds = float(event.get("seconds") or 0.0)
            eta = event.get("eta")
            self.progress.eta = None if eta is None else float(eta)
        elif kind == "done":
            self.progress.done = self.progress.total = max(int(event.get("passes") or 0), self.progress.total)
        elif kind == "warning":
            self.warnings.append(one_line(f"{self.label}: {event.get('message', '')}"))
        elif kind == "error":
            self._last_error_event = str(event.get("message") or "")

    def _step_ended(self, code: int) -> None:
        spec = self.specs[self.step]
        if code != 0:
            reason = self._last_error_event or self.process.output_error() or "no error message"
            self._fail(f"{spec.label} run failed (exit code {code}): {reason}")
            return
        if not Path(spec.out).is_file():
            self._fail(f"{spec.label} run ended without writing {spec.out}")
            return
        self.process = None
        self.progress = Progress()
        self.step += 1
        if self.step == len(self.specs):
            self.state = FINISHED
            self.remove_temporary_files()

    def _fail(self, message: str) -> None:
        self.state = FAILED
        self.error = one_line(message)
        self.remove_temporary_files()

    def cancel(self) -> None:
        """Terminate the running side; its statistics written so far stay as a checkpoint for ``--resume``."""
        if self.state != RUNNING:
            return
        if self.process is not None:
            self.process.terminate()
        self.state = CANCELLED
        self.remove_temporary_files()

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
