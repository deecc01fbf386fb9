"""Passes rendered by a command: any renderer that can write one independent pass for a given seed into an EXR.

A job with a `command` (``render --command``, a suite case's ``command`` key) renders each pass by running its
command template with the placeholders filled in:

- ``{seed}``: the pass's seed (a non-negative integer; every pass has its own);
- ``{out}``: the EXR file the pass must be written to (R, G, B, scene-linear; it is read, then deleted, or kept
  as a paired check's pass image: `batch.jobs.pairs`);
- ``{spp}``: the job's samples per pixel (optional);
- ``{set}``: the job's overrides, each as one argument ``KEY=VALUE`` (optional, but a job with overrides needs
  it: an override the command never sees would make two sides that differ in name only);
- ``{python}``: this Python interpreter (optional: a render script runs where the tool runs).

The template is split like a shell line (``shlex``) and run without a shell in `cwd` (a suite's folder, else
the current one); placeholders may sit inside a word (``--seed={seed}``) except ``{set}``, which is a word of
its own. What the command prints goes to the run's error output only when it fails. Nothing here imports bpy.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time

from .._siblings import welch_core as wc
from ..errors import BatchError
from .launch import pass_limit
from .template import words

#: The run record's renderer for passes of a command (the template's hash is the run's `scene_id`: `scene_id`).
RENDERER = "command"

#: The end of a failed command's output shown in the error (its last lines say why, as a rule).
ERROR_TAIL = 600

#: Seconds a stopped command has to end after SIGTERM before it is killed.
STOP_GRACE = 2.0


def argv(template: str, seed: int, out: str, spp: int, overrides: tuple[str, ...] = ()) -> list[str]:
    """The command line of one pass (a job with overrides has a ``{set}``: `batch.jobs.job.RenderJob` checks)."""
    values = {"seed": seed, "out": out, "spp": spp, "python": sys.executable}
    line: list[str] = []
    for word in words(template):
        line += list(overrides) if word == "{set}" else [word.format(**values)]
    return line


def scene_id(template: str) -> str:
    """What fixes a command run's content in a run record: the template's hash (the files it runs are the
    renderer under test, so they are not part of it)."""
    return "command:" + hashlib.sha256(template.encode()).hexdigest()[:16]


def run_info(job) -> wc.RunInfo:
    """The run record of a command job (`batch.jobs.job.RenderJob`)."""
    settings = {"command": job.command, "spp": job.spp}
    return wc.RunInfo(
        spp=job.spp,
        renderer=RENDERER,
        scene=job.command,
        scene_id=scene_id(job.command),
        settings=settings,
        settings_hash=hashlib.sha256(repr([settings, list(job.overrides)]).encode()).hexdigest()[:16],
        overrides=job.overrides,
    )


class _Cancelled(Exception):
    """A pass started ahead that nobody will take (the run ended first)."""


class _Ahead:
    """The pass of `seed` rendering on a thread of its own (`CommandRenderer.start_next`)."""

    def __init__(self, seed: int, render):
        self.seed = seed
        self.result: tuple | None = None  # (image, its file)
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, args=(render,), name=f"welch-pass-{seed}", daemon=True)
        self.thread.start()

    def _run(self, render) -> None:
        try:
            self.result = render(self.seed)
        except BaseException as exc:  # raised on the render loop's thread, when it takes the pass
            self.error = exc

    def take(self) -> tuple:
        self.thread.join()
        if self.error is not None:
            raise self.error
        return self.result


class CommandRenderer:
    """Renders passes by running a job's command (see the module docstring); a context manager that owns the
    folder the passes are written to.

    `start_next(seed)` runs the next pass's command while this process adds the pass before it (reading the EXR
    and running a process release the GIL): on a GPU the tool's work on a pass hides behind the next render, and
    with a renderer that costs nothing the pass's copy and decoding overlap its accumulation. One pass is ahead at
    most; a pass started ahead and not taken is ended with the run."""

    def __init__(self, job):
        self.job = job
        self.cwd = job.command_dir or os.getcwd()
        self._folder: tempfile.TemporaryDirectory | None = None
        self._probed: tuple[int, object, float] | None = None  # (seed, image, seconds) rendered to learn the size
        self.replayed_seconds = 0.0  # the render seconds of the last pass `render` returned from the probe
        self._channels: list[str] | None = None  # the channel names of the first pass this process read
        self.stop = None  # a `batch.blender.run.StopRequest`: a stop ends the command's pass at once
        self._slowest = 0.0  # seconds of the slowest pass so far
        self.pass_file: str | None = None  # the EXR of the last pass, deleted when the next one renders
        self._ahead: _Ahead | None = None  # the pass rendering on a thread of its own
        self._closing = threading.Event()  # the run has ended: a pass started ahead stops

    def __enter__(self) -> CommandRenderer:
        # A paired check's side keeps its passes' files as its pass images: written on their file system, a rename
        # moves them (`batch.jobs.pairs`).
        if self.job.pass_images is not None:
            os.makedirs(self.job.pass_images, exist_ok=True)
        self._folder = tempfile.TemporaryDirectory(prefix="welch-command-", dir=self.job.pass_images)
        return self

    def __exit__(self, *exc) -> bool:
        self._closing.set()
        if self._ahead is not None:
            self._ahead.thread.join()
            self._ahead = None
        self._forget()
        if self._folder is not None:
            self._folder.cleanup()
        return False

    def _run(self, line: list[str], seed: int) -> tuple[int, str, str]:
        """Run one pass's command in a session of its own: (exit code, stdout, stderr). A stop of this process
        (Ctrl-C, SIGTERM) ends it at once and raises KeyboardInterrupt; a pass past `launch.pass_limit` is ended
        and refused in one line."""
        (limit, why), start = pass_limit(self._slowest), time.monotonic()
        try:
            process = subprocess.Popen(line, cwd=self.cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                       errors="replace", start_new_session=True)  # fmt: skip
        except OSError as exc:
            raise BatchError(f"--command: can't run {line[0]!r} in {self.cwd}: {exc.strerror or exc}") from None
        try:
            while True:
                try:
                    stdout, stderr = process.communicate(timeout=0.1)
                    self._slowest = max(self._slowest, time.monotonic() - start)
                    return process.returncode, stdout, stderr
                except subprocess.TimeoutExpired:
                    pass
                if self.stop is not None and self.stop.requested:
                    raise KeyboardInterrupt
                if self._closing.is_set():
                    raise _Cancelled
                if time.monotonic() - start > limit:
                    raise BatchError(f"--command's pass for seed {seed} ran past {limit:g} s and was stopped ({why})")
        finally:
            if process.poll() is None:
                _end(process)

    def size(self, seed: int) -> tuple[int, int]:
        """(width, height) of the command's images, learnt by rendering the pass of `seed` (kept for `render`)."""
        start = time.perf_counter()
        image = self.render(seed)
        self._probed = (seed, image, time.perf_counter() - start)
        return image.shape[1], image.shape[0]

    def render(self, seed: int):
        """Run the command for `seed` and read its EXR: H×W×3 float32, top row first (the pass started ahead, where
        it is this seed's)."""
        if self._probed is not None and self._probed[0] == seed:
            (_, image, self.replayed_seconds), self._probed = self._probed, None
            return image
        self.replayed_seconds = 0.0
        assert self._folder is not None, "use the renderer as a context manager"
        self._forget()
        ahead, self._ahead = self._ahead, None
        if ahead is not None and ahead.seed != seed:  # not asked for after all: ended, its file with the folder
            self._closing.set()
            ahead.thread.join()
            self._closing.clear()
            ahead = None
        image, self.pass_file = ahead.take() if ahead is not None else self._render(seed)
        return image

    def start_next(self, seed: int) -> None:
        """Start the pass of `seed` on a thread of its own: the next `render(seed)` takes it."""
        assert self._ahead is None, "one pass ahead at most"
        self._ahead = _Ahead(seed, self._render)

    def _render(self, seed: int) -> tuple:
        """Run the command for `seed` and read its EXR: (image, the EXR's path)."""
        out = os.path.join(self._folder.name, f"pass-{seed}.exr")
        line = argv(self.job.command, seed, out, self.job.spp, self.job.overrides)
        code, stdout, stderr = self._run(line, seed)
        said = (stderr.strip() or stdout.strip())[-ERROR_TAIL:]
        if code != 0:  # the command's own exit code, 130 too: a stop of this tool ends its pass in `_run`
            raise BatchError(f"--command failed for seed {seed} (exit code {code}): "
                             f"{' '.join(said.split()) or 'no output'}")  # fmt: skip
        if not os.path.exists(out):
            raise BatchError(f"--command exited 0 for seed {seed} without writing {{out}} ({out})")
        image, names = wc.read_exr_colour(out)  # a file left by a failure goes with the folder
        if self._channels is None:
            self._channels = names
        elif names != self._channels:  # another layer written by mistake: its colour is not the image's
            raise BatchError(
                f"--command wrote channels {names} for seed {seed}, its first pass {self._channels}: every pass "
                "must hold the same channels"
            )
        return image, out

    def _forget(self) -> None:
        """Delete the last pass's file, unless it was kept (moved away)."""
        if self.pass_file is not None:
            with contextlib.suppress(FileNotFoundError):
                os.remove(self.pass_file)
            self.pass_file = None


def _end(process: subprocess.Popen) -> None:
    """End a command's session: SIGTERM, then SIGKILL after `STOP_GRACE` seconds."""
    for sig, wait in ((signal.SIGTERM, STOP_GRACE), (signal.SIGKILL, None)):
        try:
            os.killpg(process.pid, sig)
        except (ProcessLookupError, PermissionError):
            break
        try:
            process.communicate(timeout=wait)
            return
        except subprocess.TimeoutExpired:
            continue
