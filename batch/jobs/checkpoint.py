"""Checkpoints written by a thread of their own, so that a run's passes go on while its statistics file is written.

A checkpoint is taken on the render loop's thread: `welch_core.formats.stats_arrays` copies what the run changes in
place (its pixel moments: about 7 ms at 1920x1080) into the arrays of the checkpoint written before; the writer's
thread makes the preview and writes the file (`welch_core.formats.write_arrays`: a temporary file, fsynced, read
back, then renamed over the run's file), so the file on disk is always a complete checkpoint, the last one written
or the one before. One is written at a time: a checkpoint due while the previous one is still being written waits
for it, so the file never goes back to older passes and the checkpoints keep their spacing. The thread is not a
daemon: a process that ends while it writes ends after the file is complete (or left as it was).

numpy only, as the render loop runs inside Blender too.
"""

from __future__ import annotations

import threading

from .._siblings import welch_core as wc


class Checkpoints:
    """The writer of one run's checkpoints: `write` one, `wait` for it (raising what it failed with)."""

    def __init__(self):
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self._written: dict | None = None  # the arrays of the last checkpoint: the next one's copies go into them

    def write(self, path: str, stats: wc.TileStats, layers: dict) -> None:
        """Write `stats` and `layers` to `path` on the writer's thread, after the checkpoint before it; raises what
        that one failed with (a full disk), without writing this one."""
        self.wait()
        arrays = self._written = wc.formats.stats_arrays(stats, layers, into=self._written)
        self._thread = threading.Thread(target=self._write, args=(path, arrays), name="welch-checkpoint")
        self._thread.start()

    def _write(self, path: str, arrays: dict) -> None:
        try:
            wc.formats.write_arrays(path, wc.formats.with_preview(arrays))
        except BaseException as exc:  # raised on the render loop's thread, by the next `write` or `wait`
            self._error = exc

    def wait(self) -> None:
        """Wait until the checkpoint being written is on disk; raise what it failed with."""
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._error is not None:
            error, self._error = self._error, None
            raise error
