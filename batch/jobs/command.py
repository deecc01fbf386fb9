"""Passes rendered by a command: any renderer that can write one independent pass for a given seed into an EXR.

A job with a `command` (``render --command``, a suite case's ``command`` key) renders each pass by running its
command template with the placeholders filled in:

- ``{seed}``: the pass's seed (a non-negative integer; every pass has its own);
- ``{out}``: the EXR file the pass must be written to (R, G, B, scene-linear; it is read, then deleted);
- ``{spp}``: the job's samples per pixel (optional);
- ``{set}``: the job's overrides, each as one argument ``KEY=VALUE`` (optional, but a job with overrides needs
  it: an override the command never sees would make two sides that differ in name only);
- ``{python}``: this Python interpreter (optional: a render script runs where the tool runs).

The template is split like a shell line (``shlex``) and run without a shell in `cwd` (a suite's folder, else
the current one); placeholders may sit inside a word (``--seed={seed}``) except ``{set}``, which is a word of
its own. What the command prints goes to the run's error output only when it fails. Nothing here imports bpy.
"""

from __future__ import annotations

import hashlib
import os
import shlex
import signal
import string
import subprocess
import sys
import tempfile
import time

from .._siblings import welch_core as wc
from ..errors import BatchError

PLACEHOLDERS = ("seed", "out", "spp", "set", "python")
REQUIRED = ("seed", "out")

#: The run record's renderer for passes of a command (the template's hash is the run's `scene_id`: `scene_id`).
RENDERER = "command"

#: The end of a failed command's output shown in the error (its last lines say why, as a rule).
ERROR_TAIL = 600


def words(template: str) -> list[str]:
    """The template's words, checked: it splits like a shell line, names only `PLACEHOLDERS`, has ``{seed}``
    and ``{out}``, and ``{set}`` only as a word of its own. Raises BatchError naming the problem."""
    try:
        split = shlex.split(template)
    except ValueError as exc:
        raise BatchError(f"--command {template!r}: {exc}") from None
    if not split:
        raise BatchError("--command is empty: give the command that renders one pass, e.g. "
                         "'{python} render.py --seed {seed} --out {out}'")  # fmt: skip
    seen = set()
    for word in split:
        try:
            fields = [field for _, field, _, _ in string.Formatter().parse(word) if field is not None]
        except ValueError as exc:
            raise BatchError(f"--command {template!r}: {exc} (write {{{{ and }}}} for a literal brace)") from None
        for field in fields:
            if field not in PLACEHOLDERS:
                raise BatchError(f"--command {template!r}: unknown placeholder {{{field}}} (it takes "
                                 f"{', '.join('{' + p + '}' for p in PLACEHOLDERS)})")  # fmt: skip
            if field == "set" and word != "{set}":
                raise BatchError(f"--command {template!r}: {{set}} must be a word of its own, not in {word!r}")
        seen.update(fields)
    missing = [p for p in REQUIRED if p not in seen]
    if missing:
        raise BatchError(f"--command {template!r} has no {{{missing[0]}}}: each pass needs its own seed and file")
    return split


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


class CommandRenderer:
    """Renders passes by running a job's command (see the module docstring); a context manager that owns the
    folder the passes are written to."""

    def __init__(self, job):
        self.job = job
        self.cwd = job.command_dir or os.getcwd()
        self._folder: tempfile.TemporaryDirectory | None = None
        self._probed: tuple[int, object, float] | None = None  # (seed, image, seconds) rendered to learn the size
        self.replayed_seconds = 0.0  # the render seconds of the last pass `render` returned from the probe
        self._channels: list[str] | None = None  # the channel names of the first pass this process read

    def __enter__(self) -> CommandRenderer:
        self._folder = tempfile.TemporaryDirectory(prefix="welch-command-")
        return self

    def __exit__(self, *exc) -> bool:
        if self._folder is not None:
            self._folder.cleanup()
        return False

    def size(self, seed: int) -> tuple[int, int]:
        """(width, height) of the command's images, learnt by rendering the pass of `seed` (kept for `render`)."""
        start = time.perf_counter()
        image = self.render(seed)
        self._probed = (seed, image, time.perf_counter() - start)
        return image.shape[1], image.shape[0]

    def render(self, seed: int):
        """Run the command for `seed` and read its EXR: H×W×3 float32, top row first."""
        if self._probed is not None and self._probed[0] == seed:
            (_, image, self.replayed_seconds), self._probed = self._probed, None
            return image
        self.replayed_seconds = 0.0
        assert self._folder is not None, "use the renderer as a context manager"
        out = os.path.join(self._folder.name, f"pass-{seed}.exr")
        line = argv(self.job.command, seed, out, self.job.spp, self.job.overrides)
        try:
            done = subprocess.run(line, cwd=self.cwd, capture_output=True, text=True, errors="replace")
        except OSError as exc:
            raise BatchError(f"--command: can't run {line[0]!r} in {self.cwd}: {exc.strerror or exc}") from None
        if done.returncode in (-signal.SIGINT, -signal.SIGTERM, 130):
            # A stop (Ctrl-C, a cancel) that reached the command reached this process too: its handler runs at the
            # next instruction (the pause lets a signal still on its way arrive) and raises the interrupt here.
            # Past it, nobody stopped the tool: the exit code is the command's own, a failure like any other.
            time.sleep(0.05)
        said = (done.stderr.strip() or done.stdout.strip())[-ERROR_TAIL:]
        if done.returncode != 0:
            raise BatchError(f"--command failed for seed {seed} (exit code {done.returncode}): "
                             f"{' '.join(said.split()) or 'no output'}")  # fmt: skip
        if not os.path.exists(out):
            raise BatchError(f"--command exited 0 for seed {seed} without writing {{out}} ({out})")
        try:
            channels = wc.read_exr_channels(out)
            names = sorted(channels)
            if self._channels is None:
                self._channels = names
            elif names != self._channels:  # another layer written by mistake: its colour is not the image's
                raise BatchError(
                    f"--command wrote channels {names} for seed {seed}, its first pass {self._channels}: every pass "
                    "must hold the same channels"
                )
            return wc.exr.colour_of(channels, out)
        finally:
            os.remove(out)
