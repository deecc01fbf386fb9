"""The one driver of a render side: a render job rendered in chunks asked for, in its own serving process
(``render --serve``: the scene stays loaded between chunks) or on a Dask cluster (`distributed.PassPool`), its
progress relayed, its passes counted from the statistics file it writes, and its end turned into the tool's
outcome: `BatchError` for the job's own input, KeyboardInterrupt when it was interrupted (its checkpoint is kept),
`RendererFailed` (a BatchError: one line, exit 2) when the renderer failed otherwise.

``render --blender`` (a whole job in another Blender), ``check`` (both sides, chunk by chunk), ``suite`` (through
``check``, and ``suite bless``), the Dask workers (a chunk of given seeds at a time: `render_chunk`) and the
Blender add-on (a side polled from a timer) all drive their renders through `Side`;
`batch.jobs.distributed.ClusterSide` is a side whose passes render on a Dask cluster.

Nothing here imports bpy or scipy.
"""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError, Exit, RendererFailed
from . import protocol
from .job import RenderJob
from .launch import START_NOTICE, JobProcess, blender_version, bpy_version, job_command, pass_limit
from .protocol import ChunkRequest
from .samples import SceneSamples

#: Seconds to wait for a render process to end once its requests are closed.
FINISH_WAIT = 60.0

#: Seconds a render process may take to start (load Blender and the scene) before it is taken for hung; the
#: environment variable WELCH_START_TIMEOUT overrides it (a production scene on slow storage may need more).
START_TIMEOUT = float(os.environ.get("WELCH_START_TIMEOUT", "900"))

#: Seconds a render process taken for hung has to save what it has before it is killed.
HUNG_WAIT = 5.0


class Side:
    """One render side of a run: `start`, then `request` passes (up to a count) and `wait` (or `poll`) until they
    are saved, and `finish`; `stop` ends it at once, keeping what it saved.

    `progress` receives the side's events (a `batch.present.progress.Progress`, or anything with its methods);
    `warn` the warnings, prefixed with the side's name (None: a lone render, whose messages need no name);
    `env` is the render process's environment (default: this process's). `batch.jobs.distributed.ClusterSide`
    is the same side rendered on a Dask cluster.
    """

    def __init__(self, name: str | None, job: RenderJob, progress=None, warn=None, env: dict[str, str] | None = None):
        self.name = name
        self.env = env
        self.job = job
        self.progress = progress
        self.warn = warn
        self.passes = 0  # in the statistics file
        self._started_at, self._alive = time.monotonic(), False  # since when, and whether it has said anything
        self._noticed = False  # whether the wait at start-up was said
        self._last_pass = time.monotonic()  # when the last pass ended
        self._slowest: float | None = None  # seconds of the slowest pass here (None: none yet)
        self.render_seconds = 0.0  # the seconds of the passes rendered here (their own, start-up not counted)
        self.pass_seconds: list[float] = []  # each of them
        self.process: JobProcess | None = None
        self._asked = 0  # passes the current request waits for (0: none outstanding)
        self._rendering_since: float | None = None  # when the render process said it starts rendering
        self.ended = False  # `end_pass` ended it: no more requests, nothing to finish

    # -- start and stop --------------------------------------------------------------------------------------

    def start(self) -> None:
        """Count the passes already in the statistics file (a resumed run) and start the serving process (a
        `--blender` is checked to be Blender first)."""
        if self.job.blender:
            blender_version(self.job.blender, self._warn)
        if self.job.python:
            bpy_version(self.job.python, self._warn)
        if Path(self.job.out).exists():
            self.passes = wc.load_stats(self.job.out, pixels=False).n
        command = job_command(self.job, base_env=self.env, serve=True)
        with protocol.Interrupts.held():  # started and recorded at once: `stop` reaches whatever was started
            self.process = JobProcess(command, requests=True)
        self._started_at, self._alive = time.monotonic(), False

    def ask_to_stop(self) -> None:
        """Tell the side's process to stop after its current pass (and save), without waiting: `stop` waits. A run
        that stops several sides tells them all first, so that none renders on whatever cuts its waiting short."""
        if self.process is not None and not self.ended:
            self.process.ask_to_stop()

    def stop(self) -> None:
        """End the side now: its process finishes its current pass and saves (or is killed)."""
        if self.process is not None and not self.ended:
            self.process.stop()

    def end_pass(self) -> None:
        """End the side in the middle of its pass (its time budget is spent): its process stops (the passes it
        finished are saved; a command's pass ends at once), and is killed with its whole process group after
        `HUNG_WAIT` seconds; the passes in its statistics file are counted, and the side takes no more requests."""
        if self.process is None or self.ended:
            return
        self.process.stop(HUNG_WAIT)
        self._relay()  # the passes that ended meanwhile
        self.passes = wc.load_stats(self.job.out, pixels=False).n if Path(self.job.out).exists() else 0
        self._asked, self.ended = 0, True

    def finish(self) -> None:
        """No more passes: the serving process saves, ends and is checked."""
        if self.process is None or self.ended:
            return
        self.process.close_requests()
        code = self.process.wait(FINISH_WAIT)
        self._relay()
        if code != 0:
            self._failed(code)

    # -- what the scene asks of the passes -------------------------------------------------------------------

    def start_probe(self) -> None:
        """Start a process of the side's build that opens its scene and reads what it asks of the passes, without
        rendering (``render --probe``); `probed` waits for the answer."""
        if self.job.blender:
            blender_version(self.job.blender, self._warn)
        if self.job.python:
            bpy_version(self.job.python, self._warn)
        self.process = JobProcess(job_command(self.job, base_env=self.env, probe=True))

    def probed(self) -> SceneSamples:
        """The scene's own samples and sample-dependent settings (`batch.jobs.samples`), once the probe ends;
        raises as a render does when it can't open the scene."""
        try:
            code = self.process.wait(START_TIMEOUT)
        except subprocess.TimeoutExpired:
            self.process.stop(HUNG_WAIT)
            raise RendererFailed(self._named(f"{self._who} did not open the scene in {START_TIMEOUT:g} s")) from None
        found = None
        for event in self.process.drain():
            if isinstance(event, protocol.Probed):
                found = SceneSamples(event.samples, event.settings)
            elif isinstance(event, protocol.Warned):
                self._warn(event.message)
        if code == 0 and found is None:
            raise BatchError(self._named(f"{self._who} exited without reading the scene"))
        if code != 0:
            self._failed(code)
        return found

    # -- passes ----------------------------------------------------------------------------------------------

    def request(self, passes: int) -> None:
        """Ask for the job's next passes until the file holds `passes` (no more than its seeds); returns at once."""
        passes = min(passes, len(self.job.seeds))
        if passes <= self.passes:
            return
        self._asked, self._last_pass = passes, time.monotonic()  # the pass clock counts from the request
        self.process.request(passes - self.passes)

    def poll(self) -> bool:
        """Relay what the side did; True once the passes asked for are saved (or none are outstanding). Never
        blocks. Raises KeyboardInterrupt where this process was interrupted and went on (a library swallowed it)."""
        if protocol.Interrupts.pending():
            raise KeyboardInterrupt
        if not self._asked:
            return True
        saved = self._relay()
        if saved is not None:
            self.passes, self._asked = saved, 0
            return True
        code = self.process.popen.poll()
        if code is not None:
            self._relay()
            self._failed(code)
        tick = getattr(self.progress, "tick", None)
        if tick is not None:
            tick()  # a log that is not a terminal hears how far the side is while a pass takes long
        waited = time.monotonic() - self._started_at
        if not self._alive and waited > START_NOTICE and not self._noticed:
            self._noticed = True
            self._warn(f"waiting for {self._who} to start "
                       f"rendering ({waited:.0f} s so far; stopped at {START_TIMEOUT:.0f} s, WELCH_START_TIMEOUT sets "
                       "it; Ctrl-C stops it now)")  # fmt: skip
        self._check_pass_time()
        if not self._alive and waited > START_TIMEOUT:
            self.stop()
            raise BatchError(self._named(f"{self._who} did not start rendering within {START_TIMEOUT:.0f} s "
                                         "(WELCH_START_TIMEOUT sets the limit)"))  # fmt: skip
        return False

    def running_seconds(self) -> float:
        """Seconds the pass rendering now has run: since the last pass ended, the request, or the render process
        said it starts rendering, whichever came last; 0 while no passes are asked for, and while the process
        starts (loading its renderer and the scene is no pass's time, `START_TIMEOUT` bounds it)."""
        if not self._asked or self._rendering_since is None:
            return 0.0
        return time.monotonic() - max(self._last_pass, self._rendering_since)

    def _check_pass_time(self) -> None:
        """Stop the side when no pass has ended for longer than `launch.pass_limit` (a hung renderer), once one
        has (before, `START_TIMEOUT` waits for it)."""
        if self._slowest is None:
            return
        limit, why = pass_limit(self._slowest)
        if time.monotonic() - self._last_pass > limit:
            self.process.stop(HUNG_WAIT)  # a hung pass will not end: a short chance to save, then killed
            raise RendererFailed(self._named(f"{self._who} finished no pass in {limit:g} s and was stopped ({why})"))

    def wait(self) -> None:
        """Block until the passes asked for are saved."""
        while not self.poll():
            time.sleep(0.005)

    def render_chunk(self, seeds, out: str, on_event=None) -> list[protocol.Event]:
        """Render exactly `seeds` (of the job) into a new statistics file `out` in the serving process, blocking;
        return the chunk's events, each also handed to `on_event` as it comes (a Dask worker's task). The
        process's end before the chunk is saved raises."""
        events: list[protocol.Event] = []
        self.process.request_chunk(ChunkRequest(tuple(seeds), out))
        while True:
            for event in self.process.drain():
                events.append(event)
                if on_event is not None:
                    on_event(event)
                if isinstance(event, protocol.Saved) and event.out == out:
                    return events
            code = self.process.poll()
            if code is not None and self.process.events.empty():
                self._failed(code)
            time.sleep(0.005)

    # -- events and failures ---------------------------------------------------------------------------------

    def _relay(self) -> int | None:
        """Show the side's events; the pass count of its last `Saved` event, if one arrived."""
        saved = None
        for event in self.process.drain():
            self._alive = True
            if isinstance(event, protocol.Saved):
                saved = event.passes if event.out == self.job.out else saved
            elif isinstance(event, protocol.Warned):
                self._warn(event.message)
            elif isinstance(event, protocol.Failed):
                continue  # reported once, by whoever handles the exit
            else:
                if isinstance(event, protocol.Started):
                    self._rendering_since = time.monotonic()
                if isinstance(event, protocol.PassDone):
                    self.render_seconds += event.seconds
                    self.pass_seconds.append(event.seconds)
                    self._last_pass, self._slowest = time.monotonic(), max(self._slowest or 0.0, event.seconds)
                if self.progress is not None:
                    self.progress.emit(event)
        return saved

    def _warn(self, message: str) -> None:
        if self.warn is not None:
            self.warn(f"{self.name}: {message}" if self.name else message)

    @property
    def _who(self) -> str:
        """What renders this side, for messages: its Blender, its Python, else the render process."""
        return self.job.blender or self.job.python or "the render process"

    def _named(self, message: str) -> str:
        return f"{self.name} side: {message}" if self.name else message

    def _failed(self, code: int):
        reason = self.process.error_message() or "no error message"
        who = self._who
        if code == 0:  # ended well without saving what was asked for: not a render process of this tool
            raise BatchError(self._named(f"{who} exited without rendering the passes asked for ({reason})"))
        if code == Exit.USAGE:
            raise BatchError(self._named(reason))
        if protocol.interrupted(code):
            raise KeyboardInterrupt
        whose = f"the {self.name} side's render" if self.name else "the render"
        raise RendererFailed(f"{whose} failed: {who} exited with code {code}: {reason}")


def probe_scenes(jobs: list[tuple[str | None, RenderJob]]) -> list[SceneSamples]:
    """What each job's scene asks of the passes (`Side.probed`), read by processes of their builds at once; each
    is (a side's name for errors, its job)."""
    sides = [Side(name, job) for name, job in jobs]
    try:
        for side in sides:
            side.start_probe()
        return [side.probed() for side in sides]
    finally:
        for side in sides:
            side.stop()


def run_job(job: RenderJob, progress, name: str | None = None) -> None:
    """Render all of `job` in another process (its Blender binary, or this Python) through a `Side`, relaying its
    progress to `progress`; raise as `Side` does. A process that exits 0 without having saved the passes asked
    for (a `--blender` that is not Blender) is an error, not a success."""
    side = Side(name, job, progress, warn=progress.warning)
    try:
        side.start()
        side.request(len(job.seeds))
        side.wait()
        side.finish()
    except BaseException:
        side.stop()
        raise
    if not os.path.exists(job.out):
        raise BatchError(f"{job.blender or 'the render process'} ended without rendering: {job.out} was not written")
