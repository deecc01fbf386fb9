"""Render a job's passes on a Dask cluster: worker processes on this machine (``--workers N``) or an existing
cluster (``--scheduler ADDRESS``), into the same statistics file one process writes.

The client splits the seeds into chunks and submits one Dask task per chunk (`PassPool`). A task renders its chunk
in a worker through the render-job contract: each worker thread keeps one serving render process per pool
(``render --serve`` with the bpy module, or ``blender -b`` with ``--blender``), started on its first chunk, so the
scene stays loaded (persistent data) from chunk to chunk. The task hands the process the chunk's seeds
(`batch.jobs.protocol.ChunkRequest`); the process saves exactly those passes into a worker-local chunk file, and the
task returns their per-pass tile sums and pixel sum (`ChunkResult`). The client accumulates the chunks into one
`TileStats`, refusing a worker whose renderer or settings differ, checkpoints as they arrive, and reports the
events of a single process (`render_distributed`).

Failures: a render process that dies in the middle of a chunk fails the task and Dask runs it once more
(``retries=1``); a worker that dies loses its chunk, which the scheduler gives to another worker (a cluster
started here allows that once per chunk). A job error (a .blend a worker can't open, a NaN pass with ``--on-nan
stop``) is not retried: it stops the run. A seed is counted once: a chunk whose seeds have arrived already is
dropped. Ctrl-C or SIGTERM cancels the outstanding chunks, stops the job's render processes and keeps (saves)
everything that arrived; ``--resume`` continues.

Needs the ``workers`` extra (``dask[distributed]``). Nothing here imports bpy: the client may be a laptop
without Blender.

The modules by role: `chunks` (what crosses from a worker to the client), `worker` (what runs in a Dask worker:
the serving render processes), `clusters` (where: a LocalCluster, an existing scheduler, SLURM), `pool` (the
client's queue of chunks), `runs` (a whole run and a render-until-decided side, through the one render loop,
`batch.jobs.loop`).
"""

from .chunks import ChunkError, ChunkResult
from .clusters import Cluster, check_scheduler, cluster, local_cluster, local_threads, slurm_gpu_cluster
from .pool import MAX_CHUNK, ChunkFailed, PassPool, default_chunk
from .runs import ClusterSide, render_distributed
from .worker import RenderProcessDied, close_servers, render_chunk, server_status

__all__ = [
    "MAX_CHUNK",
    "ChunkError",
    "ChunkFailed",
    "ChunkResult",
    "Cluster",
    "ClusterSide",
    "PassPool",
    "RenderProcessDied",
    "check_scheduler",
    "close_servers",
    "cluster",
    "default_chunk",
    "local_cluster",
    "local_threads",
    "render_chunk",
    "render_distributed",
    "server_status",
    "slurm_gpu_cluster",
]
