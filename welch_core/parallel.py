"""A pass's per-pixel work on every core: its rows split into one chunk a core, each worked on by a thread (and a
few independent tasks, a report's pictures, each on a thread of its own; and the next of a sequence, a pass's file,
read while the last one is worked on).

numpy's elementwise operations and reductions release the GIL, so threads of one process run them at once: no
copy of the pass to another process, and inside Blender as well. Each element's arithmetic is the same whichever
chunk it falls in, so the results are the same bit for bit on 1 core or 64 (the tests compare them).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor

#: Below this many elements (pixels x channels) a pass is worked on by the calling thread alone: handing chunks to
#: threads costs more than it saves (about 0.1 ms a hand-over; a 512x512 RGB pass's moments take about 2 ms).
MIN_ELEMENTS = 1 << 19

_pool: tuple[int, ThreadPoolExecutor] | None = None  # (the process it was made in, the pool)
_lock = threading.Lock()


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def row_chunks(rows: int, step: int, parts: int) -> list[slice]:
    """At most `parts` slices covering `rows` rows, each a whole number of `step` rows (a tile row, a cache band)
    but the last."""
    steps = -(-rows // step)
    per = -(-steps // max(1, min(parts, steps))) * step
    return [slice(start, min(start + per, rows)) for start in range(0, rows, per)]


def by_rows(work: Callable[[slice], None], rows: int, step: int, elements: int) -> None:
    """Call `work(rows)` on chunks of `rows` rows (whole `step`s), one a core, on threads when the pass has at
    least `MIN_ELEMENTS` `elements`; raises the first chunk's error after every chunk has ended."""
    parts = cores() if elements >= MIN_ELEMENTS else 1
    chunks = row_chunks(rows, step, parts)
    if len(chunks) == 1:
        work(chunks[0])
        return
    futures = [_executor().submit(work, chunk) for chunk in chunks]
    for future in futures:
        future.exception()  # every chunk ends before anything is raised: none still writes into the arrays
    for future in futures:
        future.result()


def at_once(*tasks: Callable[[], object]) -> list:
    """Each of `tasks` called on a thread of its own (a report's pictures: numpy and zlib release the GIL), their
    results in order; raises the first task's error after every task has ended. Threads of their own, not the
    pool's: a task may use `by_rows`, whose chunks would wait behind the tasks in a pool of as many threads."""
    if len(tasks) < 2 or cores() < 2:
        return [task() for task in tasks]
    results: list = [None] * len(tasks)
    errors: list = [None] * len(tasks)

    def run(index: int) -> None:
        try:
            results[index] = tasks[index]()
        except BaseException as exc:  # raised on the caller's thread once every task has ended
            errors[index] = exc

    # Daemon threads: a Ctrl-C while a task is stuck (reading a pipe nobody writes) ends the process, not waits.
    threads = [threading.Thread(target=run, args=(i,), name="welch-tasks", daemon=True) for i in range(len(tasks))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for error in errors:
        if error is not None:
            raise error
    return results


def one_ahead(work: Callable[[object], object], items: Iterable) -> Iterator:
    """`work(item)` of each of `items`, in order, the next item's on a thread of its own while the caller uses the
    last one's (reading a file: the reading releases the GIL); an item's error is raised when its turn comes."""
    items = list(items)
    with ThreadPoolExecutor(1, thread_name_prefix="welch-ahead") as executor:
        upcoming = executor.submit(work, items[0]) if items else None
        for index in range(len(items)):
            done = upcoming.result()
            upcoming = executor.submit(work, items[index + 1]) if index + 1 < len(items) else None
            yield done


def _executor() -> ThreadPoolExecutor:
    """The process's pool (a new one in a forked child: the parent's threads are not there)."""
    global _pool
    with _lock:
        if _pool is None or _pool[0] != os.getpid():
            _pool = (os.getpid(), ThreadPoolExecutor(cores(), thread_name_prefix="welch-rows"))
        return _pool[1]
