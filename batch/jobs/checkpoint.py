"""Checkpoints written by a thread of their own, so that a run's passes go on while its statistics file is written.

A checkpoint is taken on the render loop's thread: `welch_core.formats.stats_arrays` copies what the run changes in
place (its pixel moments: about 7 ms at 1920x1080) into the arrays of the checkpoint written before; the writer's
thread makes the preview and writes the file (`welch_core.formats.write_arrays`: a temporary file, fsynced, read
back, then renamed over the run's file), so the file on disk is always a complete checkpoint, the last one written
or the one before. One is written at a time, and the render loop never waits for one: a checkpoint is `due` only
when none is being written and the writer has been busy at most `BUSY_SHARE` of the time since the last was taken.
Where passes come faster than a checkpoint is written (a GPU's passes at 1920x1080: about 50 ms a pass, 100-300 ms
a checkpoint on 2 shared cores), checkpoints are spaced out in time instead of taking the cores from the passes
every few of them; a crash then loses the passes of about ten times a checkpoint's writing time at most. The
thread is not a daemon: a process that ends while it writes ends after the file is complete (or left as it was).

numpy only, as the render loop runs inside Blender too.
"""

from __future__ import annotations

import math
import threading
import time

from .._siblings import welch_core as wc

#: The most of a run's time its checkpoints' writer may be busy (see the module's docstring).
BUSY_SHARE = 0.1


class Checkpoints:
    """The writer of one run's checkpoints: whether one is `due`, `write` one, `wait` for it (raising what it failed
    with). `clock`: seconds, monotonic (tests give their own)."""

    def __init__(self, clock=time.monotonic):
        self._clock = clock
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._written: dict | None = None  # the arrays of the last checkpoint: the next one's copies go into them
        self._taken = -math.inf  # when the last checkpoint was taken
        self._seconds = 0.0  # how long writing it took

    def due(self) -> bool:
        """Whether a checkpoint may be taken now: none is being written, and writing the last one took at most
        `BUSY_SHARE` of the time since it was taken."""
        if self._thread is not None and self._thread.is_alive():
            return False
        return self._clock() - self._taken >= self._seconds / BUSY_SHARE

    def write(self, path: str, stats: wc.TileStats, layers: dict) -> None:
        """Write `stats` and `layers` to `path` on the writer's thread, after the checkpoint before it; raises what
        that one failed with (a full disk), without writing this one."""
        self.wait()
        self._taken = self._clock()
        arrays = self._written = wc.formats.stats_arrays(stats, layers, into=self._written)
        self._thread = threading.Thread(target=self._write, args=(path, arrays), name="welch-checkpoint")
        self._thread.start()

    def _write(self, path: str, arrays: dict) -> None:
        try:
            wc.formats.write_arrays(path, wc.formats.with_preview(arrays))
        except BaseException as exc:  # raised on the render loop's thread, by the next `write` or `wait`
            self._error = exc
        finally:
            self._seconds = self._clock() - self._taken

    def wait(self) -> None:
        """Wait until the checkpoint being written is on disk; raise what it failed with."""
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._error is not None:
            error, self._error = self._error, None
            raise error
