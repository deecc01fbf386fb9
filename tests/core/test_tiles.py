"""Tile sums and the mergeable per-tile statistics (welch_core.tiles)."""

import dataclasses
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from welch_core import (
    GridMismatchError,
    Reason,
    RunInfo,
    RunMismatchError,
    TileStats,
    WelchInputError,
    compare,
    tile_sums,
)


def naive_tile_sums(image, tile, channels=3, edges="partial"):
    """The obvious float64 reference: pad with zeros to whole tiles (or crop to them), reshape, sum."""
    if edges == "dropped":
        ty, tx = image.shape[0] // tile, image.shape[1] // tile
        img = image[: ty * tile, : tx * tile, :channels].astype(np.float64)
    else:
        ty, tx = -(-image.shape[0] // tile), -(-image.shape[1] // tile)
        img = np.zeros((ty * tile, tx * tile, channels))
        img[: image.shape[0], : image.shape[1]] = image[..., :channels]
    return img.reshape(ty, tile, tx, tile, channels).sum(axis=(1, 3))


def make_passes(rng, n, height, width, channels=4, dtype=np.float32):
    return [rng.exponential(1.0, size=(height, width, channels)).astype(dtype) for _ in range(n)]


def accumulate(passes, seeds, height, width, tile, **kwargs):
    run = TileStats(height, width, tile, **kwargs)
    for img, seed in zip(passes, seeds, strict=True):
        run.add_pass(img, seed)
    return run


def snapshot(run):
    return (
        run.count,
        run.mean.copy(),
        run.m2.copy(),
        list(run.seeds),
        run.sums.copy(),
        None if run.mean_image is None else run.mean_image.copy(),
    )


def assert_same_snapshot(a, b):
    assert a[0] == b[0]
    assert_array_equal(a[1], b[1])
    assert_array_equal(a[2], b[2])
    assert a[3] == b[3]
    assert_array_equal(a[4], b[4])
    if a[5] is None:
        assert b[5] is None
    else:
        assert_array_equal(a[5], b[5])


# -- tile_sums ---------------------------------------------------------------------------------------------


def test_tile_sums_float32_matches_float64_reference():
    """float32 input: the row partial sums of 32 values stay float32, so the result agrees with a float64 sum to
    about 1e-6 of the tile sum (32 float32 roundings of ~6e-8 each, measured ~1e-7); far below the pass-to-pass
    spread of a tile sum (a few percent)."""
    rng = np.random.default_rng(1)
    img = rng.lognormal(0.0, 1.5, size=(200, 300, 4)).astype(np.float32)
    got = tile_sums(img, 32)
    ref = naive_tile_sums(img, 32)
    assert got.dtype == np.float64 and got.shape == (7, 10, 3)  # partial tiles at the right and bottom
    assert_allclose(got, ref, rtol=1e-6, atol=0)


def test_tile_sums_float64_is_exact_to_rounding():
    rng = np.random.default_rng(2)
    img = rng.normal(size=(64, 96, 3))
    assert_allclose(tile_sums(img, 16), naive_tile_sums(img, 16), rtol=1e-13)


def test_tile_sums_partial_edge_tiles():
    """A tile that does not divide the image: the right and bottom tiles are partial, so every pixel is in a tile
    (the paper drops them; a strip left untested without a word hid a bias of +20 % in 16 rows of 48)."""
    rng = np.random.default_rng(3)
    img = rng.uniform(size=(70, 100, 3)).astype(np.float32)
    got = tile_sums(img, 32)
    assert got.shape == (3, 4, 3)
    assert_allclose(got, naive_tile_sums(img, 32), rtol=1e-6)
    assert_allclose(got.sum(axis=(0, 1)), img.astype(np.float64).sum(axis=(0, 1)), rtol=1e-6)
    assert_allclose(got[2, 3], img[64:, 96:].astype(np.float64).sum(axis=(0, 1)), rtol=1e-6)  # the 4x6 corner
    run = TileStats(70, 100, 32)
    assert run.grid_shape == (3, 4, 3) and run.dropped_pixels == 0 and run.covered == (70, 100)
    assert run.tile_box(2, 3) == (96, 64, 4, 6) and run.tile_box(0, 0) == (0, 0, 32, 32)


def test_tile_sums_dropped_edges_as_files_of_earlier_versions():
    rng = np.random.default_rng(3)
    img = rng.uniform(size=(70, 100, 3)).astype(np.float32)
    img[64:, :, :] = 1e6  # bottom rows outside complete tiles
    img[:, 96:, :] = 1e6  # right columns outside complete tiles
    got = tile_sums(img, 32, edges="dropped")
    assert got.shape == (2, 3, 3)
    assert got.max() < 1024  # nothing from the dropped edge
    assert_allclose(got, naive_tile_sums(img, 32, edges="dropped"), rtol=1e-6)
    run = TileStats(70, 100, 32, edges="dropped")
    assert run.grid_shape == (2, 3, 3)
    assert run.dropped_pixels == 70 * 100 - 6 * 32 * 32
    assert TileStats(64, 96, 32, edges="dropped").dropped_pixels == 0


def test_tile_sums_ignore_alpha():
    rng = np.random.default_rng(4)
    rgb = rng.uniform(size=(32, 48, 3)).astype(np.float32)
    rgba = np.concatenate([rgb, np.full((32, 48, 1), np.nan, dtype=np.float32)], axis=-1)
    assert_array_equal(tile_sums(rgba, 16), tile_sums(rgb, 16))
    run = TileStats(32, 48, 16)
    run.add_pass(rgba, 1)  # a NaN alpha is not a non-finite colour value
    assert np.isfinite(run.mean).all()
    assert run.mean_image.shape == (32, 48, 3)


def test_tile_sums_non_contiguous_input():
    rng = np.random.default_rng(5)
    big = rng.uniform(size=(64, 64, 4))
    view = big[::2, ::2]  # strided view
    assert_allclose(tile_sums(view, 8), naive_tile_sums(np.ascontiguousarray(view), 8), rtol=1e-13)


@pytest.mark.parametrize(
    "image, tile, msg",
    [
        ([[[1.0, 2.0, 3.0]]], 1, "`image` must be a numpy array, got list"),
        (np.zeros((4, 4)), 2, "`image` must have shape (height, width, channels), got shape (4, 4)"),
        (np.zeros((4, 4, 3), dtype=np.uint16), 2, "`image` must hold floating-point values, got dtype uint16"),
        (np.zeros((4, 4, 2)), 2, "`image` must have at least 3 channels, got 2"),
        (np.zeros((4, 4, 3)), 0, "`tile` must be an integer >= 1, got 0"),
        (np.zeros((4, 4, 3)), 2.0, "`tile` must be an integer >= 1, got 2.0"),
        (np.zeros((4, 6, 3)), 5, "`tile` must not exceed the image size 6x4, got 5"),
    ],
)
def test_tile_sums_bad_input(image, tile, msg):
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        tile_sums(image, tile)


# -- TileStats: construction -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        ({"height": 0, "width": 8}, "`height` must be an integer >= 1, got 0"),
        ({"height": 8, "width": -3}, "`width` must be an integer >= 1, got -3"),
        ({"height": 8, "width": 8, "tile": True}, "`tile` must be an integer >= 1, got True"),
        ({"height": 8, "width": 8, "tile": 0}, "`tile` must be an integer >= 1, got 0"),
        ({"height": 8, "width": 16, "tile": 9}, "`tile` must not exceed the image size 16x8, got 9"),
        ({"height": 8, "width": 8, "channels": 0}, "`channels` must be an integer >= 1, got 0"),
    ],
)
def test_tilestats_bad_arguments(kwargs, msg):
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        TileStats(**kwargs)


@pytest.mark.parametrize("spp", [0, -4, 1.5])
def test_runinfo_bad_spp(spp):
    with pytest.raises(WelchInputError, match=re.escape(f"`spp` must be an integer >= 1, got {spp!r}")):
        RunInfo(spp=spp)


def test_runinfo_json_round_trip():
    info = RunInfo(
        spp=4,
        renderer="cycles",
        renderer_version="5.0.1",
        device="CPU",
        sampling_pattern="sobol_burley",
        scene="corner",
        settings={"max_bounces": 8, "clamp": 0.0},
        settings_hash="abc",
        overrides=["max_bounces=8"],
    )
    assert info.overrides == ("max_bounces=8",)
    data = info.to_json()
    assert data["overrides"] == ["max_bounces=8"]
    assert RunInfo.from_json(data | {"unknown_future_field": 1}) == info


def test_empty_run():
    run = TileStats(64, 64, 32)
    assert run.n == 0 and run.sums.shape == (0, 2, 2, 3)
    assert run.mean_image is None
    assert np.isnan(run.variance).all()
    assert "n=0" in repr(run)


# -- accumulation ------------------------------------------------------------------------------------------


def test_streaming_equals_batch():
    rng = np.random.default_rng(6)
    passes = make_passes(rng, 17, 48, 80)
    run = accumulate(passes, range(100, 117), 48, 80, 16)
    stacked = np.stack([naive_tile_sums(p, 16) for p in passes])
    assert run.n == 17 and run.seeds == list(range(100, 117))
    assert_allclose(run.sums, stacked, rtol=1e-6)
    # The derived mean and variance against numpy on the same stacked tile sums.
    assert_allclose(run.mean, run.sums.mean(axis=0), rtol=1e-12)
    assert_allclose(run.variance, run.sums.var(axis=0, ddof=1), rtol=1e-12)
    assert_allclose(run.m2, ((run.sums - run.sums.mean(axis=0)) ** 2).sum(axis=0), rtol=1e-12)
    assert_allclose(run.mean_image, np.mean([p[..., :3] for p in passes], axis=0), rtol=1e-6)


def test_moments_are_stable_with_a_large_offset():
    """Sum-of-squares cancellation (sum x^2 - (sum x)^2 / n) fails here; the shifted two-pass M2 does not."""
    rng = np.random.default_rng(7)
    sums = 1e9 + rng.normal(0.0, 1.0, size=(50, 1, 1, 3))
    run = TileStats(8, 8, 8, keep_mean_image=False)
    for i, s in enumerate(sums):
        run.add_pass(np.broadcast_to(s / 64, (8, 8, 3)).copy(), i)
    assert_allclose(run.variance, sums.var(axis=0, ddof=1), rtol=1e-5)
    assert (run.m2 > 0).all()


def test_constant_tiles_have_exactly_zero_variance():
    run = TileStats(8, 16, 8)
    for seed in range(5):
        run.add_pass(np.full((8, 16, 3), 0.1, dtype=np.float32), seed)
    assert (run.m2 == 0).all()
    sums = np.full((7, 1, 2, 3), 0.1)  # numpy's mean of seven 0.1 is not 0.1
    built = TileStats.from_sums(sums, range(7), 8, 16, 8)
    assert (built.m2 == 0).all() and (built.mean == 0.1).all()


def test_merge_equals_accumulating_all_passes():
    rng = np.random.default_rng(8)
    passes = make_passes(rng, 25, 40, 72)
    a = accumulate(passes[:10], range(10), 40, 72, 8)
    b = accumulate(passes[10:], range(10, 25), 40, 72, 8)
    both = accumulate(passes, range(25), 40, 72, 8)
    ab = a.merge(b)
    assert ab.n == 25 and ab.seeds == list(range(25))
    assert_allclose(ab.mean, both.mean, rtol=1e-12)
    assert_allclose(ab.m2, both.m2, rtol=1e-12)
    assert_array_equal(ab.sums, both.sums)
    assert_allclose(ab.mean_image, both.mean_image, rtol=1e-6)


def test_merge_order_does_not_matter():
    rng = np.random.default_rng(9)
    passes = make_passes(rng, 13, 32, 32)
    a = accumulate(passes[:4], [40, 41, 42, 43], 32, 32, 8)
    b = accumulate(passes[4:], range(9), 32, 32, 8)
    ab, ba = a.merge(b), b.merge(a)
    assert_allclose(ab.mean, ba.mean, rtol=1e-12)
    assert_allclose(ab.m2, ba.m2, rtol=1e-12)
    assert set(ab.seeds) == set(ba.seeds) and len(ab.seeds) == 13
    # each pass's sums stay with its seed
    for seed, s in zip(ab.seeds, ab.sums, strict=True):
        assert_array_equal(s, ba.sums[ba.seeds.index(seed)])
    # three-way, associativity
    c = accumulate(make_passes(rng, 3, 32, 32), [100, 101, 102], 32, 32, 8)
    assert_allclose(ab.merge(c).m2, a.merge(b.merge(c)).m2, rtol=1e-12)


def test_merge_leaves_inputs_unchanged():
    rng = np.random.default_rng(10)
    passes = make_passes(rng, 8, 16, 16)
    a = accumulate(passes[:5], range(5), 16, 16, 8)
    b = accumulate(passes[5:], range(5, 8), 16, 16, 8)
    before_a, before_b = snapshot(a), snapshot(b)
    merged = a.merge(b)
    merged.add_pass(passes[0] * 2, 99)  # the merged run is independent of its inputs
    assert_same_snapshot(snapshot(a), before_a)
    assert_same_snapshot(snapshot(b), before_b)


def test_merge_with_empty_run():
    rng = np.random.default_rng(11)
    a = accumulate(make_passes(rng, 4, 16, 16), range(4), 16, 16, 8)
    empty = TileStats(16, 16, 8)
    for merged in (a.merge(empty), empty.merge(a)):
        assert merged.n == 4
        assert_allclose(merged.mean, a.mean, rtol=1e-15)
        assert_allclose(merged.m2, a.m2, rtol=1e-15)


def test_merge_refusals():
    rng = np.random.default_rng(12)
    passes = make_passes(rng, 4, 16, 16)
    a = accumulate(passes[:2], [1, 2], 16, 16, 8)
    b = accumulate(passes[2:], [2, 3], 16, 16, 8)
    with pytest.raises(WelchInputError, match=re.escape("seed 2 is already in this run: passes must have")):
        a.merge(b)
    other_grid = TileStats(16, 16, 4)
    msg = "statistics have different grids (width, height, tile, channels): (16, 16, 8, 3) against (16, 16, 4, 3)"
    with pytest.raises(GridMismatchError, match=re.escape(msg)):
        a.merge(other_grid)
    with pytest.raises(RunMismatchError, match=re.escape("can't merge runs that differ in spp: 1 and 4")):
        a.merge(TileStats(16, 16, 8, info=RunInfo(spp=4)))


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"scene": "glossy", "scene_id": "builtin:glossy:1"}, "differ in scene: 'corner' and 'glossy'"),
        ({"scene_id": "sha256:ff"}, "differ in scene_id: 'builtin:corner:1' and 'sha256:ff'"),
        ({"renderer": "unknown"}, "differ in renderer: 'Cycles' and 'unknown'"),
        ({"renderer_version": "3.4.1"}, "differ in renderer_version: '5.0.1' and '3.4.1'"),
        ({"build_hash": "Unknown"}, "differ in build_hash: 'a3db93c5b259' and 'Unknown'"),
        ({"device": "GPU"}, "differ in device: 'CPU' and 'GPU'"),
        ({"sampling_pattern": "BLUE_NOISE"}, "differ in sampling_pattern: 'TABULATED_SOBOL' and 'BLUE_NOISE'"),
        (
            {"settings": {"cycles.max_bounces": 3}, "settings_hash": "other"},
            "differ in the setting cycles.max_bounces: 1024 and 3",
        ),
        ({"overrides": ("cycles.blur_glossy=1",)}, "differ in overrides: [] and ['cycles.blur_glossy=1']"),
    ],
)
def test_merge_refuses_runs_of_another_configuration(changes, message):
    """A run is one configuration: anything that changes the expected image (or must match) is part of it."""
    base = RunInfo(
        spp=1,
        renderer="Cycles",
        renderer_version="5.0.1",
        build_hash="a3db93c5b259",
        device="CPU",
        sampling_pattern="TABULATED_SOBOL",
        scene="corner",
        scene_id="builtin:corner:1",
        settings={"cycles.max_bounces": 1024},
        settings_hash="abc",
    )
    a = TileStats(16, 16, 8, info=base)
    b = TileStats(16, 16, 8, info=dataclasses.replace(base, **changes))
    with pytest.raises(RunMismatchError, match=re.escape(f"can't merge runs that {message}")):
        a.merge(b)
    with pytest.raises(RunMismatchError, match=re.escape(f"can't resume runs that {message}")):
        a.same_run(b, "resume")


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("renderer", 3, "`renderer` must be a string, got int 3"),
        ("settings", [1], "`settings` must be a dict, got list"),
        ("overrides", "x=1", "`overrides` must be a list of strings, got 'x=1'"),
        ("overrides", [1], "`overrides` must be a list of strings, got [1]"),
        ("spp", 2**24 + 1, "`spp` must be an integer <= 16777216, got 16777217"),
    ],
)
def test_runinfo_checks_types(field, value, message):
    with pytest.raises(WelchInputError, match=re.escape(message)):
        RunInfo(**{field: value})


# -- derived runs ------------------------------------------------------------------------------------------


def test_subset_equals_reaccumulation():
    rng = np.random.default_rng(13)
    passes = make_passes(rng, 9, 24, 40)
    seeds = [7, 3, 11, 5, 2, 8, 1, 0, 4]
    run = accumulate(passes, seeds, 24, 40, 8, info=RunInfo(spp=2, renderer="x"))
    picked = [6, 0, 3, 8]
    sub = run.subset(picked)
    direct = accumulate([passes[i] for i in picked], [seeds[i] for i in picked], 24, 40, 8)
    assert sub.seeds == [1, 7, 5, 4]
    assert sub.info == run.info
    assert_allclose(sub.mean, direct.mean, rtol=1e-12)
    assert_allclose(sub.m2, direct.m2, rtol=1e-12)
    assert sub.mean_image is None


@pytest.mark.parametrize("indices", [[0, 0], [5], [-1]])
def test_subset_bad_indices(indices):
    rng = np.random.default_rng(14)
    run = accumulate(make_passes(rng, 3, 8, 8), range(3), 8, 8, 4)
    with pytest.raises(WelchInputError, match=re.escape("`indices` must be distinct positions in 0..2")):
        run.subset(indices)


def test_retile_equals_accumulation_at_the_larger_tile():
    rng = np.random.default_rng(15)
    passes = make_passes(rng, 6, 80, 112, dtype=np.float64)  # 5x7 tiles of 16, 3x4 tiles of 32 (partial edges)
    run = accumulate(passes, range(6), 80, 112, 16)
    big = run.retile(2)
    direct = accumulate(passes, range(6), 80, 112, 32)
    assert big.tile == 32 and big.grid_shape == direct.grid_shape == (3, 4, 3)
    assert big.dropped_pixels == direct.dropped_pixels == 0
    assert_allclose(big.sums, direct.sums, rtol=1e-12)
    assert_allclose(big.mean, direct.mean, rtol=1e-12)
    assert_allclose(big.m2, direct.m2, rtol=1e-10)
    assert big.seeds == direct.seeds
    assert_array_equal(run.retile(1).sums, run.sums)


def test_retile_bad_factor():
    run = TileStats(32, 64, 8)
    with pytest.raises(WelchInputError, match=re.escape("`factor` must be an integer >= 1, got 0")):
        run.retile(0)
    assert run.retile(8).grid_shape == (1, 1, 3)  # one partial tile: the whole image
    with pytest.raises(WelchInputError, match=re.escape("`factor` 16 makes tiles larger than the image")):
        run.retile(16)


def test_from_sums_checks():
    with pytest.raises(
        WelchInputError, match=re.escape("`sums` must have shape (n_seeds, (2, 2, 3)), got (3, 2, 3, 3)")
    ):
        TileStats.from_sums(np.zeros((3, 2, 3, 3)), range(3), 16, 16, 8)
    with pytest.raises(
        WelchInputError, match=re.escape("`sums` must have shape (n_seeds, (2, 2, 3)), got (3, 2, 2, 3)")
    ):
        TileStats.from_sums(np.zeros((3, 2, 2, 3)), range(4), 16, 16, 8)
    msg = "seed 4 is already in this run: passes must have distinct seeds"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        TileStats.from_sums(np.zeros((3, 2, 2, 3)), [4, 5, 4], 16, 16, 8)
    with pytest.raises(WelchInputError, match=re.escape("`seed` must be an integer, got 1.5")):
        TileStats.from_sums(np.zeros((2, 2, 2, 3)), [1, 1.5], 16, 16, 8)


# -- rejected passes ---------------------------------------------------------------------------------------


def test_rejected_passes_leave_the_statistics_unchanged():
    rng = np.random.default_rng(16)
    run = accumulate(make_passes(rng, 3, 16, 24), [10, 11, 12], 16, 24, 8)
    before = snapshot(run)
    good = rng.uniform(size=(16, 24, 3)).astype(np.float32)
    nan_pass = good.copy()
    nan_pass[3, 4, 1] = np.nan
    nan_pass[9, 20, 0] = np.inf
    bad = [
        (good[:8], 13, "`image` must be 16x24 (height x width) like the run, got 8x24"),
        (good.transpose(1, 0, 2), 13, "`image` must be 16x24 (height x width) like the run, got 24x16"),
        ((good * 100).astype(np.int32), 13, "`image` must hold floating-point values, got dtype int32"),
        (good[..., :2], 13, "`image` must have at least 3 channels, got 2"),
        (list(good), 13, "`image` must be a numpy array, got list"),
        (nan_pass, 13, "pass with seed 13 has 2 non-finite pixel values"),
        (good, 11, "seed 11 is already in this run: passes must have distinct seeds"),
        (good, "13", "`seed` must be an integer, got '13'"),
        (good, True, "`seed` must be an integer, got True"),
    ]
    for image, seed, msg in bad:
        with pytest.raises(WelchInputError, match=re.escape(msg)):
            run.add_pass(image, seed)
        assert_same_snapshot(snapshot(run), before)
    run.add_pass(good, 13)  # and a good pass is still accepted afterwards
    assert run.n == 4 and run.seeds == [10, 11, 12, 13]


def test_nonfinite_pass_allowed_gives_non_finite_reason():
    rng = np.random.default_rng(17)
    ref = accumulate(make_passes(rng, 6, 16, 32), range(6), 16, 32, 8)
    test = accumulate(make_passes(rng, 5, 16, 32), range(10, 15), 16, 32, 8)
    img = rng.exponential(size=(16, 32, 3)).astype(np.float32)
    img[5, 5, 1] = np.nan  # tile (0, 0), green
    img[12, 30, 2] = np.inf  # tile (1, 3), blue
    test.add_pass(img, 15, allow_nonfinite=True)
    assert test.n == 6
    result = compare(ref, test)
    reasons = result.reasons
    assert reasons[0, 0, 1] == Reason.NON_FINITE and reasons[1, 3, 2] == Reason.NON_FINITE
    assert np.isnan(result.pvalues[0, 0, 1]) and np.isnan(result.pvalues[1, 3, 2])
    assert (reasons == Reason.VALID).sum() == reasons.size - 2
    assert result.reason_counts["non_finite"] == 2
    assert np.isfinite(result.tile_pvalues).all()  # the other channels of those tiles still count
    assert result.verdict == "no_evidence"


def test_add_sums_equals_add_pass():
    """Passes that arrive as tile sums (from a worker) give the same run as the images themselves."""
    rng = np.random.default_rng(18)
    passes = make_passes(rng, 6, 24, 40)
    direct = accumulate(passes, range(6), 24, 40, 8)
    sent = TileStats(24, 40, 8)
    for chunk in (range(0, 4), range(4, 6)):
        sums = np.stack([tile_sums(passes[i], 8) for i in chunk])
        pixel_sum = np.sum([passes[i][..., :3] for i in chunk], axis=0, dtype=np.float32)
        sent.add_sums(sums, list(chunk), pixel_sum)
    assert sent.seeds == direct.seeds
    assert_array_equal(sent.sums, direct.sums)
    assert_allclose(sent.mean_image, direct.mean_image, rtol=1e-6)
    with pytest.raises(WelchInputError, match=re.escape("seed 5 is already in this run")):
        sent.add_sums(sums, [5, 6], pixel_sum)
    with pytest.raises(WelchInputError, match=re.escape("`pixel_sum` is needed: this run keeps the mean image")):
        sent.add_sums(sums, [7, 8])
    assert sent.n == 6


def test_sums_are_read_only_and_moments_follow_new_passes():
    rng = np.random.default_rng(19)
    run = accumulate(make_passes(rng, 3, 16, 16), range(3), 16, 16, 8)
    with pytest.raises(ValueError, match="read-only"):
        run.sums[0, 0, 0, 0] = 1.0
    before = run.mean.copy()
    run.add_pass(make_passes(rng, 1, 16, 16)[0] * 10, 3)
    assert not np.array_equal(run.mean, before)
    assert_allclose(run.mean, run.sums.mean(axis=0), rtol=1e-12)
