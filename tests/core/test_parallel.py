"""A pass's per-pixel work on threads (`welch_core.parallel`): the same results bit for bit however many cores
share the rows, errors raised once every chunk has ended."""

import threading

import numpy as np
import pytest

import welch_core as wc
from welch_core import parallel


@pytest.fixture
def many_cores(monkeypatch):
    """Seven cores and threads for passes of any size: chunks of odd sizes, whatever the machine has."""
    monkeypatch.setattr(parallel, "cores", lambda: 7)
    monkeypatch.setattr(parallel, "MIN_ELEMENTS", 0)


def test_row_chunks_cover_the_rows_once_in_whole_steps():
    for rows, step, parts in [(1080, 10, 2), (1080, 10, 16), (7, 3, 4), (5, 8, 3), (1, 1, 16), (100, 1, 7)]:
        chunks = parallel.row_chunks(rows, step, parts)
        assert len(chunks) <= parts
        assert [chunk.start for chunk in chunks] == [0, *(chunk.stop for chunk in chunks[:-1])]
        assert chunks[-1].stop == rows
        assert all(chunk.start % step == 0 for chunk in chunks)


def _passes(height, width, n=5, seed=3):
    rng = np.random.default_rng(seed)
    return rng.gamma(0.3, 2.0, (n, height, width, 4)).astype(np.float32)


@pytest.mark.parametrize(("height", "width", "tile"), [(97, 61, 8), (64, 64, 16), (33, 200, 32)])
def test_threads_give_the_one_core_results_bit_for_bit(monkeypatch, height, width, tile):
    images = _passes(height, width)
    found = {}
    for cores in (1, 7):
        monkeypatch.setattr(parallel, "cores", lambda cores=cores: cores)
        monkeypatch.setattr(parallel, "MIN_ELEMENTS", 0)
        moments = wc.PixelMoments(height, width)
        for image in images:
            moments.add(image)
        found[cores] = (moments.mean, moments.m2, [wc.tile_sums(image, tile) for image in images])
    one, many = found[1], found[7]
    assert np.array_equal(one[0], many[0]) and np.array_equal(one[1], many[1])
    assert all(np.array_equal(a, b) for a, b in zip(one[2], many[2], strict=True))
    oracle = wc.PixelMoments.of_passes(images)  # and both are the batch moments (to float64 rounding)
    np.testing.assert_allclose(many[0], oracle.mean, rtol=1e-12)
    np.testing.assert_allclose(many[1], oracle.m2, rtol=1e-9)


def test_tile_sums_on_threads_equal_a_float64_oracle(many_cores):
    image = _passes(70, 90, n=1)[0]
    sums = wc.tile_sums(image, 16)
    oracle = np.zeros((5, 6, 3))
    for i in range(5):
        for j in range(6):
            oracle[i, j] = image[16 * i : 16 * i + 16, 16 * j : 16 * j + 16, :3].astype(np.float64).sum(axis=(0, 1))
    np.testing.assert_allclose(sums, oracle, rtol=1e-6)


def test_a_failing_chunk_raises_after_every_chunk_has_ended(many_cores):
    ended, lock = [], threading.Lock()

    def work(rows):
        if rows.start == 0:
            raise ValueError("chunk 0 failed")
        with lock:
            ended.append(rows.start)

    with pytest.raises(ValueError, match="^chunk 0 failed$"):
        parallel.by_rows(work, 70, 10, 10**9)
    assert sorted(ended) == [10, 20, 30, 40, 50, 60]


def test_small_passes_stay_on_the_calling_thread(monkeypatch):
    monkeypatch.setattr(parallel, "cores", lambda: 7)
    threads = []
    parallel.by_rows(lambda rows: threads.append(threading.current_thread()), 64, 1, parallel.MIN_ELEMENTS - 1)
    assert threads == [threading.current_thread()]


@pytest.mark.parametrize("cores", [1, 7])
def test_absorbing_a_chunks_moments_in_place_is_merging_them(monkeypatch, cores):
    monkeypatch.setattr(parallel, "cores", lambda: cores)
    monkeypatch.setattr(parallel, "MIN_ELEMENTS", 0)
    images = _passes(41, 23, n=9).astype(np.float64)
    run, chunk = wc.PixelMoments.of_passes(images[:5]), wc.PixelMoments.of_passes(images[5:])
    merged = run.merged(chunk)
    run.absorb(chunk)
    assert run.n == 9 and np.array_equal(run.mean, merged.mean) and np.array_equal(run.m2, merged.m2)
    np.testing.assert_allclose(run.m2, wc.PixelMoments.of_passes(images).m2, rtol=1e-9)  # and the batch moments
    empty = wc.PixelMoments(41, 23)
    empty.absorb(chunk)
    assert empty.n == 4 and np.array_equal(empty.m2, chunk.m2) and empty.m2 is not chunk.m2
    with pytest.raises(wc.WelchInputError, match=r"^pixel moments of different images: \(41, 23, 3\) and \(4, 4, 3\)$"):
        run.absorb(wc.PixelMoments(4, 4))


def test_one_ahead_works_on_the_next_item_while_the_caller_has_the_last():
    """The next item's work starts before the caller takes it (it waits here for the caller's signal), the
    results come in order, and an item's error is raised when its turn comes, after the items before it."""
    taken, log = threading.Event(), []

    def work(item):
        if item == 1:
            assert taken.wait(10)  # started while the caller still holds item 0's result
        if item == 3:
            raise ValueError("no item 3")
        log.append(item)
        return item * 10

    results = parallel.one_ahead(work, range(5))
    assert next(results) == 0
    taken.set()
    assert next(results) == 10 and next(results) == 20
    with pytest.raises(ValueError, match="no item 3"):
        next(results)
    assert log == [0, 1, 2]
    assert list(parallel.one_ahead(work, [])) == []
