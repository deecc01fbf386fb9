"""What runs in a Dask worker: each worker thread keeps one serving render process per pool (`render_chunk`, the
Dask task), which renders a chunk's seeds into a worker-local chunk file and hands back its passes; the status and
the end of those processes (`server_status`, `close_servers`); and `dask_setup`, the preload of a LocalCluster's
workers."""

from __future__ import annotations

import logging
import math
import os
import shutil
import signal
import socket
import tempfile
import threading
import time

from ..._siblings import welch_core as wc
from ...errors import BatchError, RendererFailed
from .. import protocol
from ..job import RenderJob
from ..launch import THREADS_ENV
from ..lock import process_alive
from ..seeds import format_seeds
from ..side import Side
from .chunks import ChunkError, ChunkResult, remove_file

#: Worker-local folders of the serving render processes (chunk files), named by the worker's PID so a later
#: worker can remove those of dead ones.
WORK_PREFIX = "welch-worker-"
SHM = "/dev/shm"
SHM_ROOM = 1 << 30  # chunk files go to memory when it has this much room (a 4K chunk's pixel sum is 100 MB)

#: Seconds a worker waits for a render process it ends before killing it.
CLOSE_WAIT = 5.0


class RenderProcessDied(RuntimeError):
    """A worker's render process ended in the middle of a chunk (killed, crashed, out of memory): the chunk is
    lost, and Dask runs it again."""


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

    def render(self, seeds: tuple[int, ...], worker: str, handoff: bool = False) -> ChunkResult | ChunkError:
        """Render exactly `seeds`; raise RenderProcessDied if the process ends before it has saved them. With
        `handoff` (the client shares this machine) the chunk file is left for the client to read (`ChunkResult`'s
        `path`): the result carries its tile sums alone."""
        self._chunks += 1
        out = os.path.join(self.folder, f"chunk-{self._chunks}.npz")
        start = time.perf_counter()
        self.chunk, self.rendered = seeds, 0
        try:
            events = self.side.render_chunk(seeds, out, self._count)
        except (RendererFailed, RuntimeError, KeyboardInterrupt) as exc:  # a crash may be this machine's (memory)
            remove_file(out)  # the passes saved before a failure: the chunk is rendered again, or the run stops
            if self.closed:  # the pool ended it (a cancel, Ctrl-C): nobody waits for the chunk, nothing to log
                return ChunkError(seeds, "the pool was closed", worker)
            raise RenderProcessDied(
                f"the render process (PID {self.process.popen.pid}) on {worker} ended after {self.rendered} of the "
                f"{len(seeds)} passes of seeds {format_seeds(seeds)}: {exc}"
            ) from None
        except BatchError as exc:  # the job stopped on its input: not worth a retry
            remove_file(out)
            return ChunkError(seeds, str(exc).removeprefix("worker side: "), worker)
        finally:
            self.chunk = ()
        try:
            stats, layers = wc.load_stats(out, not handoff, not handoff), wc.load_layers(out, not handoff)
        except BaseException:
            remove_file(out)
            raise
        if not handoff:
            remove_file(out)
        seconds = {e.seed: e.seconds for e in events if isinstance(e, protocol.PassDone)}
        warnings = [e.message for e in events if isinstance(e, protocol.Warned)]
        passes = [seconds.get(seed, math.nan) for seed in stats.seeds]
        return ChunkResult.from_stats(stats, passes, time.perf_counter() - start, warnings, worker, layers,
                                      out if handoff else None)  # fmt: skip

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


def render_chunk(pool: str, job: RenderJob, seeds: tuple[int, ...], threads: int | None = None, handoff: bool = False):
    """The Dask task: render exactly `seeds` of `job` in this worker thread's serving render process for `pool`
    (started on the first chunk, and again if it has died), with `threads` Cycles CPU threads (None: Cycles'
    choice). Returns a `ChunkResult` (with `handoff`, which a client on this machine asks for: its chunk file left
    for the client), or a `ChunkError` for a job error; raises RenderProcessDied if the process dies during the
    chunk."""
    key = (pool, threading.get_ident())
    with _SERVERS_LOCK:
        server = _SERVERS.get(key)
        if server is None or not server.alive():
            if server is not None:
                server.close()
            server = _SERVERS[key] = _Server(pool, job, threads)
    with server.lock:
        try:
            return server.render(tuple(seeds), _worker_name(), handoff)
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
