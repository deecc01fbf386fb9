"""The one driver of a render side: a render job rendered in chunks asked for, in its own serving process
(``render --serve``: the scene stays loaded between chunks) or on a Dask cluster (`distributed.PassPool`), its
progress relayed, its passes counted from the statistics file it writes, and its end turned into the tool's
outcome: `BatchError` for the job's own input, KeyboardInterrupt when it was interrupted (its checkpoint is kept),
RuntimeError otherwise.

``render --blender`` (a whole job in another Blender), ``check`` (both sides, chunk by chunk), ``suite`` (through
``check``, and ``suite bless``), the Dask workers (a chunk of given seeds at a time) and the Blender add-on (a
side polled from a timer) all drive their renders through `Side`; `cluster` is the one place a Dask cluster is
started or reached for them.

Nothing here imports bpy or scipy.
"""

from __future__ import annotations

import contextlib
import os
import time
from dataclasses import dataclass
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError
from . import protocol
from .job import RenderJob
from .launch import JobProcess, job_command
from .protocol import ChunkRequest, Exit

#: Seconds to wait for a render process to end once its requests are closed.
FINISH_WAIT = 60.0


@dataclass(frozen=True)
class Cluster:
    """Where passes render on Dask: a scheduler's address, and the Cycles threads of each render process there
    (None: Cycles' own choice)."""

    address: str
    threads: int | None = None


@contextlib.contextmanager
def cluster(workers: int | None, scheduler: str | None, work: int | None = None):
    """A `Cluster` for ``--workers N`` (a LocalCluster of N processes on this machine, started here and shut
    down at the end; no more of them than the `work` there is, in passes) or ``--scheduler ADDRESS`` (reached,
    and refused in one line if nothing answers), or None for neither: the passes then render in processes of
    their own."""
    if workers and scheduler:
        raise BatchError("give --workers or --scheduler, not both")
    if not (workers or scheduler):
        yield None
        return
    from . import distributed

    if scheduler:
        yield Cluster(distributed.check_scheduler(scheduler))
        return
    workers = min(workers, work) if work else workers  # a process a pass at most: 1000 workers for 4 passes start 4
    with distributed.local_cluster(workers) as local:
        yield Cluster(local.scheduler_address, distributed.local_threads(workers))


class Side:
    """One render side of a run: `start`, then `request` passes (up to a count) and `wait` (or `poll`) until they
    are saved, and `finish`; `stop` ends it at once, keeping what it saved.

    `progress` receives the side's events (a `batch.present.progress.Progress`, or anything with its methods);
    `warn` the warnings, prefixed with the side's name. With `cluster` the passes render there instead.
    """

    def __init__(self, name: str, job: RenderJob, progress=None, warn=None, cluster: Cluster | None = None,
                 env: dict[str, str] | None = None):  # fmt: skip
        self.name = name
        self.env = env  # the render process's environment (default: this process's)
        self.job = job
        self.progress = progress
        self.warn = warn
        self.cluster = cluster
        self.passes = 0  # in the statistics file
        self.process: JobProcess | None = None
        self.pool = None
        self._asked = 0  # passes the current request waits for (0: none outstanding)

    # -- start and stop --------------------------------------------------------------------------------------

    def start(self) -> None:
        """Count the passes already in the statistics file (a resumed run) and start rendering: the serving
        process, or the pool on the cluster."""
        if Path(self.job.out).exists():
            self.passes = wc.load_stats(self.job.out, pixels=False).n
        if self.cluster is not None:
            from .distributed import PassPool

            self.pool = PassPool(self.job, scheduler=self.cluster.address, threads=self.cluster.threads)
            if self.progress is not None:
                self.progress.start(self.passes, self.job.out)
        else:
            self.process = JobProcess(job_command(self.job, base_env=self.env, serve=True), requests=True)

    def stop(self) -> None:
        """End the side now: its process finishes its current pass and saves (or is killed), its pool's
        outstanding chunks are cancelled."""
        if self.process is not None:
            self.process.stop()
        if self.pool is not None:
            self.pool.close()
            self.pool = None

    def finish(self) -> None:
        """No more passes: the serving process saves, ends and is checked; the pool is shut down."""
        if self.pool is not None:
            self.pool.close()
            self.pool = None
        if self.process is None:
            return
        self.process.close_requests()
        code = self.process.wait(FINISH_WAIT)
        self._relay()
        if code != 0:
            self._failed(code)

    # -- passes ----------------------------------------------------------------------------------------------

    def request(self, passes: int) -> None:
        """Ask for the job's next passes until the file holds `passes` (no more than its seeds); returns at once."""
        passes = min(passes, len(self.job.seeds))
        if passes <= self.passes:
            return
        self._asked = passes
        if self.pool is not None:
            from .distributed import default_chunk

            seeds = [s for s in self.job.seeds[self.passes : passes]]
            size = default_chunk(len(seeds), self.pool.parallelism() or 1)
            for first in range(0, len(seeds), size):
                self.pool.submit(seeds[first : first + size])
        else:
            self.process.request(passes - self.passes)

    def poll(self) -> bool:
        """Relay what the side did; True once the passes asked for are saved (or none are outstanding).
        Never blocks for a process; a pool's chunks are collected as they come (blocking until the last)."""
        if not self._asked:
            return True
        if self.pool is not None:
            self._collect()
            return True
        saved = self._relay()
        if saved is not None:
            self.passes, self._asked = saved, 0
            return True
        code = self.process.popen.poll()
        if code is not None:
            self._relay()
            self._failed(code)
        return False

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

    def _collect(self) -> None:
        from .distributed import accumulate, save_in_seed_order

        stats = wc.load_stats(self.job.out) if Path(self.job.out).exists() else None
        for result in self.pool:
            stats = accumulate(stats, result, self.job)
            for message in result.warnings:
                self._warn(f"{result.worker}: {message}")
            if self.progress is not None:
                for seed in result.seeds:
                    self.progress.pass_done(seed, result.wall_seconds / max(len(result.seeds), 1))
        if stats is not None:
            self.passes = save_in_seed_order(self.job, stats).n
        self._asked = 0

    # -- events and failures ---------------------------------------------------------------------------------

    def _relay(self) -> int | None:
        """Show the side's events; the pass count of its last `Saved` event, if one arrived."""
        saved = None
        for event in self.process.drain():
            if isinstance(event, protocol.Saved):
                saved = event.passes if event.out == self.job.out else saved
            elif isinstance(event, protocol.Warned):
                self._warn(event.message)
            elif isinstance(event, protocol.Failed):
                continue  # reported once, by whoever handles the exit
            elif self.progress is not None:
                self.progress.emit(event)
        return saved

    def _warn(self, message: str) -> None:
        if self.warn is not None:
            self.warn(f"{self.name}: {message}")

    def _failed(self, code: int):
        reason = self.process.error_message() or "no error message"
        who = self.job.blender or "the render process"
        if code == 0:  # ended well without saving what was asked for: not a render process of this tool
            raise BatchError(f"{self.name} side: {who} exited without rendering the passes asked for ({reason})")
        if code == Exit.USAGE:
            raise BatchError(f"{self.name} side: {reason}")
        if protocol.interrupted(code):
            raise KeyboardInterrupt
        raise RuntimeError(f"the {self.name} side's render failed: {who} exited with code {code}: {reason}")


def run_job(job: RenderJob, progress, name: str = "render") -> None:
    """Render all of `job` in another process (its Blender binary, or this Python) through a `Side`, relaying its
    progress to `progress`; raise as `Side` does. A process that exits 0 without having saved the passes asked
    for (a `--blender` that is not Blender) is an error, not a success."""
    side = Side(name, job, progress, warn=progress.warning)
    side.start()
    try:
        side.request(len(job.seeds))
        side.wait()
        side.finish()
    except BaseException:
        side.stop()
        raise
    if not os.path.exists(job.out):
        raise BatchError(f"{job.blender or 'the render process'} ended without rendering: {job.out} was not written")
