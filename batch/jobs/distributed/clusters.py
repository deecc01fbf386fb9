"""Where chunks render: a Dask LocalCluster of this machine (``--workers N``), the scheduler of a running cluster
(``--scheduler ADDRESS``, checked before anything renders) or a SLURM cluster of GPU workers."""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import threading
from dataclasses import dataclass

from ...errors import BatchError
from . import worker

#: Runs of a chunk after its first fails (its render process died: Dask's `retries`; its worker died: the
#: scheduler's `allowed_failures`, for a cluster started here).
RETRIES = 1

#: How long to wait for the scheduler of an existing cluster to answer: a TCP connection first, then Dask's
#: handshake (a port that accepts connections and never answers fails after the second).
CONNECT_SECONDS = 5.0
CONNECT_TIMEOUT = "20s"
HANDSHAKE_SECONDS = 25.0


def _distributed():
    try:
        import distributed
    except ImportError:
        raise BatchError(
            "--workers and --scheduler need Dask: pip install 'dask[distributed]' (the project's `workers` extra)"
        ) from None
    return distributed


def local_threads(workers: int) -> int:
    """Cycles threads per render process when `workers` of them share this machine: its cores split evenly."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return max(1, cores // workers)


def _client(distributed, address: str, direct: bool | None = None):
    """A Dask client of the scheduler at `address`, or BatchError in one line. Made in a thread with a deadline:
    a port that accepts connections and never answers made Dask's own connect wait past its timeout, and Ctrl-C
    could not end it. `direct`: results are fetched from the workers themselves (None: as Dask's configuration
    ``distributed.client.direct-to-workers`` says; Dask's default is through the scheduler)."""
    made: dict = {}

    def connect() -> None:
        try:
            made["client"] = distributed.Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False,
                                                direct_to_workers=direct)  # fmt: skip
        except Exception as exc:  # reported in the caller's thread
            made["error"] = exc

    thread = threading.Thread(target=connect, daemon=True, name="dask-connect")
    thread.start()
    thread.join(HANDSHAKE_SECONDS)
    if "client" in made:
        return made["client"]
    if thread.is_alive():
        raise BatchError(f"the Dask scheduler at {address} accepts connections but does not answer (waited "
                         f"{HANDSHAKE_SECONDS:.0f} s): is it a Dask scheduler of the same version?")  # fmt: skip
    raise BatchError(f"can't reach the Dask scheduler at {address}: {made.get('error')}")


def check_scheduler(address: str) -> str:
    """`address` of a Dask scheduler that answers, or BatchError in one line: a scheme Dask does not speak
    (``http://``, the dashboard's), no port, or nothing listening there (within `CONNECT_SECONDS`)."""
    text = address.strip()
    scheme, _, rest = text.rpartition("://")
    if scheme and scheme not in ("tcp", "tls"):
        raise BatchError(f"--scheduler {address}: Dask schedulers speak tcp:// or tls://, not {scheme}://")
    host, _, port = rest.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise BatchError(f"--scheduler {address}: give HOST:PORT, e.g. tcp://head:8786")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_SECONDS):
            pass
    except OSError as exc:
        raise BatchError(f"--scheduler {address}: nothing answers there ({exc.strerror or exc})") from None
    return text if scheme else f"tcp://{text}"


def local_cluster(workers: int):
    """A Dask LocalCluster of `workers` processes of one thread each on this machine, as ``--workers`` starts it
    (``check`` can give both sides' pools its address, with ``threads=local_threads(workers)``)."""
    return _distributed().LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,  # no port to collide with; a cluster of one's own has its dashboard
        silence_logs=logging.ERROR,  # a render process's death is still logged (an error), not cancellations
        scheduler_kwargs={"allowed_failures": RETRIES},
        preload=[worker.__name__],  # `dask_setup` in each worker process
    )


@dataclass(frozen=True)
class Cluster:
    """Where passes render on Dask: a scheduler's address, the Cycles threads of each render process there
    (None: Cycles' own choice), and whether its workers are this machine's (started here, ``--workers``).

    The client fetches a chunk's passes from the worker itself where the workers are this machine's. Dask's
    default is through the scheduler, whose connections pickle with protocol 4: the chunk's arrays are then
    copied into the pickle and sent twice (at 1920x1080, a chunk's 100 MB of pixel moments took 250-400 ms,
    directly 50-110 ms). A cluster elsewhere keeps the default (the client may not reach its workers), unless
    Dask's configuration ``distributed.client.direct-to-workers`` says otherwise."""

    address: str
    threads: int | None = None
    local: bool = False


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
    if scheduler:
        yield Cluster(check_scheduler(scheduler))
        return
    workers = min(workers, work) if work else workers  # a process a pass at most: 1000 workers for 4 passes start 4
    with local_cluster(workers) as local:
        try:
            yield Cluster(local.scheduler_address, local_threads(workers), local=True)
        except KeyboardInterrupt:
            _quiet()  # the scheduler here logs the tasks the shutdown cancels: not news to whoever pressed Ctrl-C
            raise


def _quiet() -> None:
    """Silence Dask's loggers in this process (the local cluster's scheduler and nannies), for a shutdown."""
    for name in list(logging.root.manager.loggerDict):
        if name == "distributed" or name.startswith("distributed."):
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def slurm_gpu_cluster(
    queue: str,
    cores: int = 8,
    memory: str = "32GB",
    walltime: str = "04:00:00",
    gres: str = "gpu:1",
    **kwargs,
):
    """A dask-jobqueue ``SLURMCluster`` for a GPU partition: each SLURM job is one Dask worker of one thread (one
    render process, the only user of its GPU) with `cores` CPUs for Cycles' host side, `gres` GPUs and the Dask
    resource ``GPU=1``. Nothing is submitted until ``cluster.scale(jobs=N)``; pass ``cluster.scheduler_address``
    as ``--scheduler`` (or to `PassPool`). `kwargs` go to ``SLURMCluster`` (``account``, ``python``,
    ``job_script_prologue`` to load modules or activate the environment, ...)."""
    try:
        from dask_jobqueue import SLURMCluster
    except ImportError:
        raise BatchError(
            "a SLURM cluster needs dask-jobqueue: pip install dask-jobqueue (the `workers` extra)"
        ) from None
    return SLURMCluster(
        queue=queue,
        cores=1,  # Dask threads per worker: one chunk at a time, one render process per GPU
        processes=1,
        job_cpu=cores,  # what SLURM allocates: Cycles' threads for scene sync and the host side of the GPU
        memory=memory,
        walltime=walltime,
        job_extra_directives=[f"--gres={gres}", *kwargs.pop("job_extra_directives", [])],
        worker_extra_args=["--resources", "GPU=1", *kwargs.pop("worker_extra_args", [])],
        **kwargs,
    )
