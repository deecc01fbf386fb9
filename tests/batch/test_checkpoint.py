"""Checkpoints written by a thread of their own (`batch.jobs.checkpoint`, through `batch.jobs.loop.render_loop`):
the passes go on while a checkpoint is written, each checkpoint holds exactly the passes it was taken at (the
moments copied), the file at the end holds every pass, and a failed write is raised, not lost."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import welch_core as wc
from batch.jobs import checkpoint
from batch.jobs.checkpoint import Checkpoints
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
    """A checkpoint due while the one before is still being written is put off, not waited for: the loop goes on
    adding passes, and the file at the end holds them all."""
    images = _passes(10)
    out = tmp_path / "run.npz"
    stats = wc.TileStats(24, 40, 8, 3, keep_pixel_moments=True)
    started, released, written, checkpoint = threading.Event(), threading.Event(), [], {}
    write = wc.formats.write_arrays

    def slow(path, arrays):
        written.append((threading.current_thread().name, len(arrays["seeds"])))
        if len(written) == 1:
            started.set()
            assert released.wait(10)  # the loop adds every other pass meanwhile
        write(path, arrays)
        if len(written) == 1:
            checkpoint["run"] = wc.load_stats(path)

    monkeypatch.setattr(wc.formats, "write_arrays", slow)

    def arrivals():
        for seed, image in enumerate(images):
            stats.add_pass(image, seed)  # a pass rendered here goes straight into the run
            yield Arrival((seed,))
            if seed == 3:
                assert started.wait(10)
        assert written == [("welch-checkpoint", 4)] and stats.n == 10  # the 8th pass's checkpoint put off
        released.set()

    render_loop(arrivals(), Run(str(out), (), stats), _Quiet(), 4)
    assert written == [("welch-checkpoint", 4), ("MainThread", 10)]
    first = checkpoint["run"]  # the moments as they were at 4 passes, though 6 more were added while it was written
    assert first.seeds == [0, 1, 2, 3]
    np.testing.assert_allclose(first.pixels.m2, wc.PixelMoments.of_passes(images[:4]).m2, rtol=1e-10)
    final = wc.load_stats(out)
    assert final.seeds == list(range(10))
    np.testing.assert_array_equal(final.pixels.m2, stats.pixels.m2)


class _Clock:
    """Seconds that pass only when a test says so."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_checkpoints_keep_their_writer_busy_a_tenth_of_the_time_at_most(tmp_path, monkeypatch):
    """Passes that come faster than a checkpoint is written: checkpoints are spaced so that writing them takes at
    most `BUSY_SHARE` of the time, `checkpoint_every` passes being the closest."""
    images = _passes(40)
    stats = wc.TileStats(24, 40, 8, 3, keep_pixel_moments=True)
    clock, written = _Clock(), []
    write = wc.formats.write_arrays

    def timed(path, arrays):
        clock.now += 0.5  # writing a checkpoint takes 0.5 s of the clock
        written.append(len(arrays["seeds"]))
        write(path, arrays)

    monkeypatch.setattr(wc.formats, "write_arrays", timed)

    def arrivals():
        for seed, image in enumerate(images):
            stats.add_pass(image, seed)
            yield Arrival((seed,))
            checkpoints.wait()  # a checkpoint taken is written before the clock goes on: 0.5 s exactly
            clock.now += 0.25  # a pass every 0.25 s

    checkpoints = Checkpoints(clock)
    render_loop(arrivals(), Run(str(tmp_path / "run.npz"), (), stats), _Quiet(), 4, checkpoints)
    # The first after 4 passes (at 0.75 s); writing it took 0.5 s, so the next is due 5 s after it was taken, at
    # 5.75 s: after 22 passes (18 since, not 4), and the next at 10.75 s, after the 40th. Nothing left to save.
    assert checkpoint.BUSY_SHARE == 0.1
    assert written == [4, 22, 40]
    assert not checkpoints.due()
    clock.now += 5.0
    assert checkpoints.due()


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
