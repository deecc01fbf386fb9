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
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import shutil
import signal
import socket
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from .._siblings import welch_core as wc
from ..errors import BatchError, RendererFailed
from . import protocol
from .job import RenderJob
from .launch import THREADS_ENV
from .lock import OutputLock, output_folder, process_alive
from .seeds import format_seeds
from .side import Side

#: Chunks per worker thread when no chunk size is given: enough to even out workers of unequal speed and to lose
#: at most about a quarter of a worker's share when it dies; and at most `MAX_CHUNK` passes, so checkpoints come
#: regularly in a long run.
CHUNKS_PER_WORKER = 4
MAX_CHUNK = 64

#: Runs of a chunk after its first fails (its render process died: Dask's `retries`; its worker died: the
#: scheduler's `allowed_failures`, for a cluster started here).
RETRIES = 1

#: How long to wait for the scheduler of an existing cluster to answer: a TCP connection first, then Dask's
#: handshake (a port that accepts connections and never answers fails after the second).
CONNECT_SECONDS = 5.0
CONNECT_TIMEOUT = "20s"
HANDSHAKE_SECONDS = 25.0

#: Worker-local folders of the serving render processes (chunk files), named by the worker's PID so a later
#: worker can remove those of dead ones.
WORK_PREFIX = "welch-worker-"
SHM = "/dev/shm"
SHM_ROOM = 1 << 30  # chunk files go to memory when it has this much room (a 4K chunk's pixel sum is 100 MB)

#: Seconds a worker waits for a render process it ends before killing it.
CLOSE_WAIT = 5.0


class ChunkFailed(RendererFailed):
    """A chunk failed again when it was run once more (its render process or its worker died twice)."""


class RenderProcessDied(RuntimeError):
    """A worker's render process ended in the middle of a chunk (killed, crashed, out of memory): the chunk is
    lost, and Dask runs it again."""


# -- what crosses from a worker to the client -----------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ChunkResult:
    """The passes of one chunk as a worker sends them back (by Dask's pickling): per-pass tile sums, shape
    (n, tiles_y, tiles_x, channels) in the order of `seeds`; the per-pixel sum over these passes (None when not
    kept); the grid and the `RunInfo` (as JSON) of the run; each pass's render seconds; the chunk's seconds in
    the worker, request to result; its warnings; and which worker rendered it. One way out (`from_stats`), one
    way in (`stats`)."""

    seeds: tuple[int, ...]
    sums: np.ndarray
    pixel_sum: np.ndarray | None
    height: int
    width: int
    tile: int
    info: dict
    seconds: tuple[float, ...] = ()
    wall_seconds: float = 0.0
    warnings: tuple[str, ...] = ()
    worker: str = ""

    @classmethod
    def from_stats(cls, stats: wc.TileStats, seconds=(), wall_seconds=0.0, warnings=(), worker="") -> ChunkResult:
        return cls(
            seeds=tuple(int(s) for s in stats.seeds),
            sums=np.ascontiguousarray(stats.sums),
            pixel_sum=None if stats.pixel_sum is None else np.ascontiguousarray(stats.pixel_sum),
            height=stats.height,
            width=stats.width,
            tile=stats.tile,
            info=stats.info.to_json(),
            seconds=tuple(float(s) for s in seconds),
            wall_seconds=float(wall_seconds),
            warnings=tuple(warnings),
            worker=worker,
        )

    def stats(self) -> wc.TileStats:
        info = wc.RunInfo.from_json(self.info)
        return wc.TileStats.from_sums(
            self.sums, self.seeds, self.height, self.width, self.tile, info, pixel_sum=self.pixel_sum
        )


@dataclass(frozen=True)
class ChunkError:
    """A chunk a worker could not render because of the job itself (a .blend it can't open, a NaN pass with
    ``--on-nan stop``): sent back as a result, not raised, so that Dask does not run it again."""

    seeds: tuple[int, ...]
    message: str
    worker: str


# -- the worker's side ----------------------------------------------------------------------------------------


class _Server:
    """A worker thread's render side (`batch.jobs.side.Side`, serving) for one pool's job, with its folder for
    chunk files. `chunk` and `rendered` say what it is doing (`server_status`)."""

    def __init__(self, pool: str, job: RenderJob, threads: int | None):
        self.pool = pool
        self.folder = _work_folder()
        env = dict(os.environ)
        if threads:
            env[THREADS_ENV] = str(threads)
        served = job.replace(out=os.path.join(self.folder, "served.npz"), resume=False)
        self.side = Side("worker", served, env=env)
        self.side.start()
        self.process = self.side.process
        self.lock = threading.Lock()
        self.chunk: tuple[int, ...] = ()
        self.rendered = 0
        self._chunks = 0
        self.closed = False  # ended by `close`: a chunk it was rendering is not a failure

    def alive(self) -> bool:
        return self.process.popen.poll() is None

    def _count(self, event) -> None:
        if isinstance(event, protocol.PassDone):
            self.rendered += 1

    def render(self, seeds: tuple[int, ...], worker: str) -> ChunkResult | ChunkError:
        """Render exactly `seeds`; raise RenderProcessDied if the process ends before it has saved them."""
        self._chunks += 1
        out = os.path.join(self.folder, f"chunk-{self._chunks}.npz")
        start = time.perf_counter()
        self.chunk, self.rendered = seeds, 0
        try:
            events = self.side.render_chunk(seeds, out, self._count)
        except (RendererFailed, RuntimeError, KeyboardInterrupt) as exc:  # a crash may be this machine's (memory)
            _remove(out)  # the passes saved before a failure: the chunk is rendered again, or the run stops
            if self.closed:  # the pool ended it (a cancel, Ctrl-C): nobody waits for the chunk, nothing to log
                return ChunkError(seeds, "the pool was closed", worker)
            raise RenderProcessDied(
                f"the render process (PID {self.process.popen.pid}) on {worker} ended after {self.rendered} of the "
                f"{len(seeds)} passes of seeds {format_seeds(seeds)}: {exc}"
            ) from None
        except BatchError as exc:  # the job stopped on its input: not worth a retry
            _remove(out)
            return ChunkError(seeds, str(exc).removeprefix("worker side: "), worker)
        finally:
            self.chunk = ()
        try:
            stats = wc.load_stats(out)
        finally:
            _remove(out)
        seconds = {e.seed: e.seconds for e in events if isinstance(e, protocol.PassDone)}
        warnings = [e.message for e in events if isinstance(e, protocol.Warned)]
        passes = [seconds.get(seed, math.nan) for seed in stats.seeds]
        return ChunkResult.from_stats(stats, passes, time.perf_counter() - start, warnings, worker)

    def close(self, kill: bool = False, wait: float = CLOSE_WAIT) -> None:
        """End the process and remove its folder. With `kill` it gets SIGTERM (it stops after its current pass);
        else its requests end (it exits once idle). Killed if it has not ended after `wait` seconds."""
        self.closed = True
        if kill and self.alive():
            self.process.signal(signal.SIGTERM)
        self.process.close_requests()
        self.process.end(wait)
        shutil.rmtree(self.folder, ignore_errors=True)


#: The worker's serving processes by (pool, worker thread): one chunk at a time each.
_SERVERS: dict[tuple[str, int], _Server] = {}
_SERVERS_LOCK = threading.Lock()


def render_chunk(pool: str, job: RenderJob, seeds: tuple[int, ...], threads: int | None = None):
    """The Dask task: render exactly `seeds` of `job` in this worker thread's serving render process for `pool`
    (started on the first chunk, and again if it has died), with `threads` Cycles CPU threads (None: Cycles'
    choice). Returns a `ChunkResult`, or a `ChunkError` for a job error; raises RenderProcessDied if the process
    dies during the chunk."""
    key = (pool, threading.get_ident())
    with _SERVERS_LOCK:
        server = _SERVERS.get(key)
        if server is None or not server.alive():
            if server is not None:
                server.close()
            server = _SERVERS[key] = _Server(pool, job, threads)
    with server.lock:
        try:
            return server.render(tuple(seeds), _worker_name())
        except RenderProcessDied:
            with _SERVERS_LOCK:
                if _SERVERS.get(key) is server:
                    del _SERVERS[key]
            server.close()
            raise


def server_status(pool: str | None = None) -> list[dict]:
    """What this worker's render processes (of `pool`, or all) are doing: PID, alive, the chunk's seeds and the
    passes of it rendered so far. Run on every worker by `PassPool.status`."""
    with _SERVERS_LOCK:
        servers = [s for s in _SERVERS.values() if pool is None or s.pool == pool]
    return [
        {"pool": s.pool, "pid": s.process.popen.pid, "alive": s.alive(), "chunk": list(s.chunk), "rendered": s.rendered}
        for s in servers
    ]


def close_servers(pool: str, kill: bool = False) -> int:
    """End this worker's render processes of `pool` (see `_Server.close`); return how many there were."""
    with _SERVERS_LOCK:
        keys = [key for key in _SERVERS if key[0] == pool]
        servers = [_SERVERS.pop(key) for key in keys]
    for server in servers:
        server.close(kill)
    return len(servers)


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return f"worker {get_worker().address}"
    except (ImportError, ValueError):  # not in a Dask worker (a direct call)
        return f"{socket.gethostname()} (PID {os.getpid()})"


def _work_folder() -> str:
    """A new folder for this worker's chunk files: in memory where there is room, else the temporary folder.
    Folders of workers that no longer run are removed first."""
    base = tempfile.gettempdir()
    if os.path.isdir(SHM) and os.access(SHM, os.W_OK):
        stat = os.statvfs(SHM)
        if stat.f_bavail * stat.f_frsize >= SHM_ROOM:
            base = SHM
    for entry in os.scandir(base):
        pid = entry.name.removeprefix(WORK_PREFIX).split("-", 1)[0]
        if entry.name.startswith(WORK_PREFIX) and pid.isdigit() and not process_alive(int(pid)):
            shutil.rmtree(entry.path, ignore_errors=True)
    return tempfile.mkdtemp(prefix=f"{WORK_PREFIX}{os.getpid()}-", dir=base)


def _remove(path: str) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


# -- the client's side ----------------------------------------------------------------------------------------


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


def _client(distributed, address: str):
    """A Dask client of the scheduler at `address`, or BatchError in one line. Made in a thread with a deadline:
    a port that accepts connections and never answers made Dask's own connect wait past its timeout, and Ctrl-C
    could not end it."""
    made: dict = {}

    def connect() -> None:
        try:
            made["client"] = distributed.Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False)
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
        preload=[__name__],  # `dask_setup` in each worker process
    )


def dask_setup(worker) -> None:
    """Run by each worker process of a `local_cluster` as it starts. Ctrl-C at a terminal reaches every process
    of its group; the client stops the run, keeps what was rendered and closes the cluster, so a worker ignores
    it instead of printing the traceback of its own interrupt, and does not log that the scheduler (which lives
    in the client's process) has gone: a local cluster's scheduler only goes with the client."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the process's main thread: leave it
        pass
    logging.getLogger("distributed").addFilter(_scheduler_gone_filter)
    for name in list(logging.root.manager.loggerDict):
        if name.startswith("distributed."):
            logging.getLogger(name).addFilter(_scheduler_gone_filter)


def _scheduler_gone_filter(record: logging.LogRecord) -> bool:
    """False for a log record about a closed connection (the scheduler gone)."""
    error = record.exc_info[1] if record.exc_info else None
    while error is not None:
        if type(error).__name__ in ("CommClosedError", "StreamClosedError"):
            return False
        error = error.__cause__ or error.__context__
    return "heartbeat" not in record.getMessage().lower()


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
        if getattr(job, "lobes", ()):
            # A chunk would have to carry its layers (batch.blender.run does not render them for a served chunk).
            raise BatchError("--lobes does not go with --workers or --scheduler yet: render the layers in one process")
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
        self.client = _client(distributed, cluster.address)
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
                continue  # these seeds arrived already: count them once (an empty chunk: all skipped, warnings)
            if len(fresh) != len(result.seeds):  # chunks are disjoint: impossible unless a worker misbehaves
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
    if scheduler:
        yield Cluster(check_scheduler(scheduler))
        return
    workers = min(workers, work) if work else workers  # a process a pass at most: 1000 workers for 4 passes start 4
    with local_cluster(workers) as local:
        try:
            yield Cluster(local.scheduler_address, local_threads(workers))
        except KeyboardInterrupt:
            _quiet()  # the scheduler here logs the tasks the shutdown cancels: not news to whoever pressed Ctrl-C
            raise


def _quiet() -> None:
    """Silence Dask's loggers in this process (the local cluster's scheduler and nannies), for a shutdown."""
    for name in list(logging.root.manager.loggerDict):
        if name == "distributed" or name.startswith("distributed."):
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)


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
        stats = wc.load_stats(self.job.out) if os.path.exists(self.job.out) else None
        for result in self.pool:
            stats = accumulate(stats, result, self.job)
            self.render_seconds += sum(s for s in result.seconds if math.isfinite(s))
            self.pass_seconds += [s for s in result.seconds if math.isfinite(s)]
            for message in result.warnings:
                self._warn(f"{result.worker}: {message}")
            if self.progress is not None:
                for seed in result.seeds:
                    self.progress.pass_done(seed, result.wall_seconds / max(len(result.seeds), 1))
        if stats is not None:
            self.passes = save_in_seed_order(self.job, stats).n
        self._asked = 0
        return True


# -- a whole run ----------------------------------------------------------------------------------------------


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
        stats = _resumed(job)
        done = set(stats.seeds) if stats is not None else set()
        todo = [seed for seed in job.seeds if seed not in done]
        progress.start(len(job.seeds) - len(todo), job.out)
        if todo:
            stats = _render(job, todo, stats, progress, cluster, chunk, resources)
    progress.finished(job.out, stats.n if stats is not None else 0)
    return stats


def _resumed(job: RenderJob) -> wc.TileStats | None:
    """The checkpoint in `job.out` when resuming (its configuration is checked when the first chunk arrives)."""
    if not os.path.exists(job.out):
        return None
    if not job.resume:
        raise BatchError(f"{job.out} already exists: pass --resume to continue it, or choose another --out")
    stats = wc.load_stats(job.out)
    extra = sorted(set(stats.seeds) - set(job.seeds))
    if extra:
        raise BatchError(f"can't resume {job.out}: it holds seed {extra[0]}, which is not in --seeds")
    return stats


def _render(job, todo, stats, progress, cluster, chunk, resources) -> wc.TileStats | None:
    with PassPool(job, cluster, resources) as pool:
        size = chunk or default_chunk(len(todo), pool.parallelism() or 1)
        for start in range(0, len(todo), size):
            pool.submit(todo[start : start + size])
        unsaved = 0
        last = time.perf_counter()
        try:
            for result in pool:
                stats = accumulate(stats, result, job)
                unsaved += len(result.seeds)
                for message in result.warnings:
                    progress.warning(f"{result.worker}: {message}")
                now = time.perf_counter()
                per_pass, last = (now - last) / max(len(result.seeds), 1), now
                for seed in result.seeds:
                    progress.pass_done(seed, per_pass)
                if unsaved >= job.checkpoint_every:
                    stats, unsaved = save_in_seed_order(job, stats), 0
        finally:
            if unsaved:  # also on Ctrl-C or a failure: nothing that arrived is lost
                stats = save_in_seed_order(job, stats)
    return stats


def accumulate(stats: wc.TileStats | None, result: ChunkResult, job: RenderJob) -> wc.TileStats:
    """`stats` with the passes of a finished chunk added (the chunk's statistics when `stats` is None)."""
    chunk = result.stats()
    if stats is None:
        return chunk
    try:
        stats.same_run(chunk, "merge")
    except wc.WelchInputError as exc:
        # A worker with another Blender build, or a resumed file of another configuration.
        raise BatchError(f"{result.worker} rendered another configuration than {job.out} holds: {exc}") from None
    stats.add_sums(chunk.sums, chunk.seeds, chunk.pixel_sum)
    return stats


def save_in_seed_order(job: RenderJob, stats: wc.TileStats) -> wc.TileStats:
    """Save `stats` with its passes in the order of `job.seeds` (what one process writes); return that order."""
    position = {seed: i for i, seed in enumerate(job.seeds)}
    order = sorted(range(stats.n), key=lambda i: position[stats.seeds[i]])
    if order != list(range(stats.n)):
        stats = wc.TileStats.from_sums(
            stats.sums[order],
            [stats.seeds[i] for i in order],
            stats.height,
            stats.width,
            stats.tile,
            stats.info,
            pixel_sum=stats.pixel_sum,
        )
    wc.save_stats(job.out, stats)
    return stats


# -- clusters of a job scheduler ------------------------------------------------------------------------------


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
