"""A whole run on a Dask cluster (`render_distributed`) and a side of render-until-decided whose passes render on
one (`ClusterSide`), both through the one render loop (`batch.jobs.loop`)."""

from __future__ import annotations

import math
import os

from ..._siblings import welch_core as wc
from ...errors import BatchError
from ..job import RenderJob
from ..lock import OutputLock, output_folder
from ..loop import Run, render_loop, resumed
from ..side import Side
from .clusters import Cluster
from .pool import PassPool, default_chunk


class ClusterSide(Side):
    """A render side (`batch.jobs.side.Side`) whose passes render on a Dask cluster: each request becomes chunks
    of a `PassPool`, collected (blocking) as they arrive and saved in seed order, as one process saves them."""

    def __init__(self, name: str, job: RenderJob, cluster: Cluster, progress=None, warn=None):
        super().__init__(name, job, progress, warn)
        self.cluster = cluster
        self.pool: PassPool | None = None

    def start(self) -> None:
        if os.path.exists(self.job.out):
            self.passes = wc.load_stats(self.job.out, pixels=False).n
        self.pool = PassPool(self.job, self.cluster)
        if self.progress is not None:
            self.progress.start(self.passes, self.job.out)

    def stop(self) -> None:
        if self.pool is not None:
            self.pool.close()
            self.pool = None

    finish = stop

    def request(self, passes: int) -> None:
        passes = min(passes, len(self.job.seeds))
        if passes <= self.passes:
            return
        self._asked = passes
        seeds = list(self.job.seeds[self.passes : passes])
        size = default_chunk(len(seeds), self.pool.parallelism() or 1)
        for first in range(0, len(seeds), size):
            self.pool.submit(seeds[first : first + size])

    def poll(self) -> bool:
        """Collect the chunks asked for as they arrive (blocking until the last) and save them."""
        if not self._asked:
            return True
        run = Run.of(self.job, *resumed(self.job.replace(resume=True)))
        render_loop(self._arrivals(), run, _SideEvents(self), math.inf)  # saves once, at the end
        if run.stats is not None and not os.path.exists(self.job.out):
            run.save()  # every pass skipped (--on-nan skip): the file still answers
        if run.stats is not None:
            self.passes = run.stats.n
        self._asked = 0
        return True

    def _arrivals(self):
        for result in self.pool:
            finite = [s for s in result.seconds if math.isfinite(s)]
            self.render_seconds += sum(finite)
            self.pass_seconds += finite
            yield result.arrival()


class _SideEvents:
    """What the render loop reports, to a side's warnings and its progress (where it has one)."""

    def __init__(self, side: Side):
        self.side = side

    def warning(self, message: str) -> None:
        self.side._warn(message)

    def pass_done(self, seed: int, seconds: float) -> None:
        if self.side.progress is not None:
            self.side.progress.pass_done(seed, seconds)


def render_distributed(
    job: RenderJob,
    progress,  # a batch.present.progress.Progress, or anything with its methods
    cluster: Cluster,
    chunk: int | None = None,
    resources: dict | None = None,
) -> wc.TileStats | None:
    """Render every seed of `job` not yet in its statistics file on a Dask cluster, as `batch.run.render_run`
    does in one process: the same file (passes in the order of `job.seeds`), the same progress events (a pass's
    `seconds` is the wall time per pass of its chunk's arrival, so the ETA holds however many workers there are),
    checkpoints every `job.checkpoint_every` passes as chunks arrive, and on Ctrl-C or SIGTERM the passes that
    arrived are saved and KeyboardInterrupt is raised.

    `cluster` and `resources` are those of `PassPool`; `chunk` is the passes per chunk (default `default_chunk`).
    Returns the statistics (None when every pass was skipped).
    """
    if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1):
        raise BatchError(f"--chunk must be a positive integer, got {chunk!r}")
    output_folder(job.out)
    with OutputLock(job.out):
        run = Run.of(job, *resumed(job))
        done = set(run.stats.seeds) if run.stats is not None else set()
        todo = [seed for seed in job.seeds if seed not in done]
        progress.start(len(job.seeds) - len(todo), job.out)
        if todo:
            with PassPool(job, cluster, resources) as pool:
                size = chunk or default_chunk(len(todo), pool.parallelism() or 1)
                for start in range(0, len(todo), size):
                    pool.submit(todo[start : start + size])
                render_loop((result.arrival() for result in pool), run, progress, job.checkpoint_every)
    progress.finished(job.out, run.stats.n if run.stats is not None else 0)
    return run.stats
