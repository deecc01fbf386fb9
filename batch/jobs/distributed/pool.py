"""The client's queue of chunks on a Dask cluster (`PassPool`): submit chunks of a job's seeds at any time, take
each chunk's passes as it finishes."""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Iterator, Sequence

from ...errors import BatchError, RendererFailed
from ..job import RenderJob
from ..seeds import format_seeds
from .chunks import ChunkError, ChunkResult
from .clusters import RETRIES, Cluster, _client, _distributed
from .worker import close_servers, render_chunk, server_status

#: Chunks per worker thread when no chunk size is given: enough to even out workers of unequal speed and to lose
#: at most about a quarter of a worker's share when it dies; and at most `MAX_CHUNK` passes, so checkpoints come
#: regularly in a long run.
CHUNKS_PER_WORKER = 4
MAX_CHUNK = 64


class ChunkFailed(RendererFailed):
    """A chunk failed again when it was run once more (its render process or its worker died twice)."""


def default_chunk(passes: int, parallelism: int) -> int:
    """Passes per chunk when none is given: `CHUNKS_PER_WORKER` chunks per worker thread, 1 to `MAX_CHUNK`."""
    return max(1, min(MAX_CHUNK, math.ceil(passes / (CHUNKS_PER_WORKER * max(parallelism, 1)))))


class PassPool:
    """Render chunks of one job's seeds on a Dask cluster and hand back each chunk's passes as it finishes.

    ``PassPool(job, cluster)`` renders on `cluster` (a `batch.jobs.side.Cluster`: the address of a scheduler,
    of a LocalCluster ``batch.jobs.side.cluster`` started or of a running cluster). `submit` queues a chunk of
    seeds, at any time, also while iterating (render-until-decided adds chunks as it looks at the data).
    Iterating yields a `ChunkResult` for each finished chunk in the order they finish, every seed at most once,
    and ends when no chunk is outstanding. A chunk whose render process or worker dies is run once more; a job
    error raises BatchError naming the worker; a chunk that fails twice raises ChunkFailed. `cancel` drops the
    outstanding chunks and stops the job's render processes; `close` (or the end of a ``with``) ends the render
    processes and the client.

    Parameters
    ----------
    job : RenderJob
        The job whose seeds are rendered (`submit` takes only seeds of `job.seeds`); `job.out` is not written. A
        relative .blend (or Blender) path is made absolute: every worker must reach the file at that path.
    cluster : Cluster
        Where: the scheduler's address and the Cycles CPU threads of each render process (None: Cycles' own
        choice, all cores).
    resources : dict, optional
        Dask worker resources a chunk needs, e.g. ``{"GPU": 1}`` on a cluster whose GPU workers were started with
        ``--resources GPU=1`` (then only they render).
    """

    def __init__(self, job: RenderJob, cluster: Cluster, resources: dict | None = None):
        distributed = _distributed()
        # Paths as the workers must find them: a worker's folder is not the client's.
        if job.blend is not None:
            job = job.replace(blend=os.path.abspath(job.blend))
        if job.blender is not None and os.sep in job.blender:
            job = job.replace(blender=os.path.abspath(job.blender))
        self.job = job
        self.token = uuid.uuid4().hex[:12]
        self.resources = resources
        self.threads = cluster.threads
        self.handoff = cluster.local  # the workers share this machine: chunk files are read here, not sent
        self.client = _client(distributed, cluster.address, True if cluster.local else None)
        self._as_completed = distributed.as_completed(loop=self.client.loop)
        self._pending: dict = {}  # future -> its seeds
        self._submitted: set[int] = set()
        self._counted: set[int] = set()
        self._allowed = set(job.seeds)
        self._closed = False

    def __enter__(self) -> PassPool:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    def parallelism(self) -> int:
        """Worker threads the cluster has now (an existing cluster may still be starting its workers: 0)."""
        return sum(self.client.nthreads().values())

    @property
    def pending(self) -> int:
        """Chunks submitted and not yet handed back."""
        return len(self._pending)

    def submit(self, seeds: Sequence[int]) -> None:
        """Queue a chunk: render exactly `seeds` (seeds of the job, none submitted before) on some worker."""
        seeds = tuple(int(s) for s in seeds)
        if not seeds:
            raise BatchError("a chunk needs at least one seed")
        unknown = [s for s in seeds if s not in self._allowed]
        if unknown:
            raise BatchError(f"seed {unknown[0]} is not among the job's seeds")
        seen = set(self._submitted)
        for seed in seeds:
            if seed in seen:
                raise BatchError(f"seed {seed} was submitted already: every seed renders once")
            seen.add(seed)
        self._submitted = seen
        future = self.client.submit(
            render_chunk,
            self.token,
            self.job,
            seeds,
            self.threads,
            self.handoff,
            key=f"welch-chunk-{self.token}-{seeds[0]}",
            retries=RETRIES,
            resources=self.resources,
            pure=False,
        )
        self._pending[future] = seeds
        self._as_completed.add(future)

    def __iter__(self) -> Iterator[ChunkResult]:
        for future in self._as_completed:
            seeds = self._pending.pop(future, None)
            if seeds is None:
                continue  # cancelled
            try:
                result = future.result()
            except Exception as exc:
                raise ChunkFailed(f"the chunk of seeds {format_seeds(seeds)} failed twice: {exc}") from exc
            finally:
                future.release()
            if isinstance(result, ChunkError):
                raise BatchError(f"{result.worker}: {result.message}")
            fresh = [s for s in result.seeds if s not in self._counted]
            if result.seeds and not fresh:
                result.discard()
                continue  # these seeds arrived already: count them once (an empty chunk: all skipped, warnings)
            if len(fresh) != len(result.seeds):  # chunks are disjoint: impossible unless a worker misbehaves
                result.discard()
                raise ChunkFailed(f"{result.worker} sent back seeds of more than one chunk: {result.seeds}")
            self._counted.update(fresh)
            yield result

    def status(self) -> dict[str, list[dict]]:
        """Each worker's render processes of this pool (`server_status`), by worker address."""
        return self.client.run(server_status, self.token, on_error="ignore")

    def cancel(self) -> None:
        """Drop the outstanding chunks and stop this pool's render processes (each saves and exits at once)."""
        futures = list(self._pending)
        self._pending.clear()
        self._as_completed.clear()
        if futures:
            self.client.cancel(futures)
        self.client.run(close_servers, self.token, True, on_error="ignore")

    def close(self) -> None:
        """Cancel what is outstanding, end the render processes and shut down what the pool started."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._pending:
                self.cancel()
            else:
                self.client.run(close_servers, self.token, on_error="ignore")
        finally:
            self.client.close()
