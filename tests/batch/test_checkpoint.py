"""Checkpoints written by a thread of their own (`batch.jobs.checkpoint`, through `batch.jobs.loop.render_loop`):
the passes go on while a checkpoint is written, each checkpoint holds exactly the passes it was taken at (the
moments copied), the file at the end holds every pass, and a failed write is raised, not lost."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import welch_core as wc
from batch.jobs.loop import Arrival, Run, render_loop


class _Quiet:
    def pass_done(self, seed, seconds) -> None:
        pass

    def warning(self, message) -> None:
        raise AssertionError(message)


def _passes(n):
    rng = np.random.default_rng(30)
    return rng.gamma(2.0, 0.5, (n, 24, 40, 3)).astype(np.float32)


def test_the_passes_go_on_while_a_checkpoint_is_written(tmp_path, monkeypatch):
    images = _passes(10)
    out = tmp_path / "run.npz"
    stats = wc.TileStats(24, 40, 8, 3, keep_pixel_moments=True)
    started, released, written, checkpoint = threading.Event(), threading.Event(), [], {}
    write = wc.formats.write_arrays

    def slow(path, arrays):
        written.append((threading.current_thread().name, len(arrays["seeds"])))
        if len(written) == 1:
            started.set()
            assert released.wait(10)  # the loop adds passes meanwhile
        write(path, arrays)
        if len(written) == 1:
            checkpoint["run"] = wc.load_stats(path)

    monkeypatch.setattr(wc.formats, "write_arrays", slow)

    def arrivals():
        for seed, image in enumerate(images):
            stats.add_pass(image, seed)  # a pass rendered here goes straight into the run
            if seed == 7:  # 4 passes past the checkpoint, which can't have been written yet
                assert started.wait(10) and written == [("welch-checkpoint", 4)] and stats.n == 8
                released.set()
            yield Arrival((seed,))

    render_loop(arrivals(), Run(str(out), (), stats), _Quiet(), 4)
    assert written == [("welch-checkpoint", 4), ("welch-checkpoint", 8), ("MainThread", 10)]
    first = checkpoint["run"]  # the moments as they were at 4 passes, though 4 more were added while it was written
    assert first.seeds == [0, 1, 2, 3]
    np.testing.assert_allclose(first.pixels.m2, wc.PixelMoments.of_passes(images[:4]).m2, rtol=1e-10)
    final = wc.load_stats(out)
    assert final.seeds == list(range(10))
    np.testing.assert_array_equal(final.pixels.m2, stats.pixels.m2)


def test_a_checkpoint_that_fails_is_raised_by_the_loop(tmp_path):
    images = _passes(3)
    stats = wc.TileStats(24, 40, 8, 3, keep_pixel_moments=True)
    out = tmp_path / "no such folder" / "run.npz"

    def arrivals():
        for seed, image in enumerate(images):
            stats.add_pass(image, seed)
            yield Arrival((seed,))

    with pytest.raises(wc.WelchInputError, match="can't write statistics file"):
        render_loop(arrivals(), Run(str(out), (), stats), _Quiet(), 1)
