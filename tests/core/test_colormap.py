"""The p-value colour map, upscaling, overlay, tone mapping and the histogram (welch_core.colormap)."""

import re

import matplotlib
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import welch_core as wc
from welch_core import (
    MAP_MODES,
    TileStats,
    WelchInputError,
    colorize,
    compare,
    histogram,
    map_values,
    overlay,
    pvalue_rgb,
    tonemap,
    upscale_tiles,
)
from welch_core.colormap import EXCLUDED_GREY

VIRIDIS = matplotlib.colormaps["viridis"]


def test_colorize_matches_matplotlib_viridis():
    """Within 0.01 of matplotlib's viridis at its 256 table entries (v = i / 255 returns entry i exactly) and of
    the table interpolated linearly anywhere (matplotlib's own lookup is a step function between entries)."""
    v = np.arange(256) / 255.0
    rgb = colorize(v)
    assert rgb.dtype == np.float32 and rgb.shape == (256, 3)
    assert_array_equal(VIRIDIS(v)[:, :3], VIRIDIS.colors)
    assert np.abs(rgb - VIRIDIS(v)[:, :3]).max() < 0.01
    fine = np.linspace(0.0, 1.0, 20001)
    table = np.asarray(VIRIDIS.colors)
    continuous = np.stack([np.interp(fine, v, table[:, i]) for i in range(3)], axis=-1)
    assert np.abs(colorize(fine) - continuous).max() < 0.01


def test_large_p_violet_small_p_yellow():
    p = np.array([[[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]])
    rgb = colorize(map_values(p, "min"))
    assert_allclose(rgb[0, 0], VIRIDIS(0.0)[:3], atol=1e-6)  # violet
    assert_allclose(rgb[0, 1], VIRIDIS(1.0)[:3], atol=1e-6)  # yellow
    assert rgb[0, 0, 2] > rgb[0, 0, 1] and rgb[0, 1, 0] > rgb[0, 1, 2]


def test_nan_is_grey_and_values_are_clipped():
    rgb = colorize([np.nan, -0.5, 1.5])
    assert_array_equal(rgb[0], [EXCLUDED_GREY] * 3)
    assert_allclose(rgb[1], VIRIDIS(0.0)[:3], atol=1e-6)
    assert_allclose(rgb[2], VIRIDIS(1.0)[:3], atol=1e-6)


def test_map_modes():
    p = np.array([[[0.04, 0.25, 0.5], [np.nan, 0.01, np.nan], [np.nan, np.nan, np.nan]]])
    q = np.array([[0.3, 0.02, np.nan]])
    assert MAP_MODES == ("min", "channel", "sqrt", "log10", "q")
    assert_allclose(map_values(p, "min"), [[0.96, 0.99, np.nan]])
    assert_allclose(map_values(p, "channel", channel=1), [[0.75, 0.99, np.nan]])
    assert_allclose(map_values(p, "sqrt"), [[0.8, 0.9, np.nan]])
    assert_allclose(map_values(p, "log10"), [[-np.log10(0.04) / 8, 2 / 8, np.nan]])
    assert_allclose(map_values(p, "q", qvalues=q), [[0.7, 0.98, np.nan]])
    assert map_values(np.full((1, 1, 3), 1e-300), "log10")[0, 0] == 1.0  # saturates at p = 1e-8
    assert map_values(np.zeros((1, 1, 3)), "log10")[0, 0] == 1.0


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        ({"mode": "max"}, "`mode` must be one of ('min', 'channel', 'sqrt', 'log10', 'q'), got 'max'"),
        ({"mode": "channel"}, "`channel` must be in 0..2 for mode 'channel', got None"),
        ({"mode": "channel", "channel": 3}, "`channel` must be in 0..2 for mode 'channel', got 3"),
        ({"mode": "q"}, "`qvalues` are needed for mode 'q'"),
    ],
)
def test_map_values_bad_arguments(kwargs, msg):
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        map_values(np.full((2, 2, 3), 0.5), **kwargs)


def test_pvalue_rgb_of_a_comparison():
    rng = np.random.default_rng(71)
    ref = TileStats.from_sums(rng.normal(100, 5, size=(10, 3, 4, 3)), range(10), 24, 32, 8)
    test = TileStats.from_sums(rng.normal(100, 5, size=(10, 3, 4, 3)), range(10, 20), 24, 32, 8)
    c = compare(ref, test)
    rgb = pvalue_rgb(c)
    assert rgb.shape == (3, 4, 3)
    assert_allclose(rgb, colorize(1.0 - np.nanmin(c.pvalues, axis=-1)), atol=1e-7)
    assert pvalue_rgb(c, "q").shape == (3, 4, 3)
    assert_allclose(pvalue_rgb(c, "channel", 2), colorize(1.0 - c.pvalues[..., 2]), atol=1e-7)


def test_upscale_tiles_shape_and_edge_fill():
    tiles = np.arange(6, dtype=np.float32).reshape(2, 3)
    big = upscale_tiles(tiles, 4, 10, 14, fill=-1.0)
    assert big.shape == (10, 14) and big.dtype == np.float32
    assert_array_equal(big[:8, :12], np.kron(tiles, np.ones((4, 4))))
    assert (big[8:] == -1).all() and (big[:, 12:] == -1).all()
    rgb = upscale_tiles(colorize(tiles / 5), 4, 10, 14)
    assert rgb.shape == (10, 14, 3)
    assert_array_equal(rgb[5, 9], colorize(tiles / 5)[1, 2])
    assert (rgb[9, 13] == 0).all()


def test_overlay():
    rng = np.random.default_rng(72)
    base = rng.uniform(size=(6, 8, 3)).astype(np.float32)
    top = rng.uniform(size=(6, 8, 3)).astype(np.float32)
    assert_array_equal(overlay(base, top, 0.0), base)
    assert_allclose(overlay(base, top, 1.0), top, atol=1e-7)
    assert_allclose(overlay(base, top, 0.25), 0.75 * base + 0.25 * top, atol=1e-6)
    mask = np.zeros((6, 8), dtype=bool)
    mask[2:4, 3:6] = True
    out = overlay(base, top, 1.0, mask)
    assert_allclose(out[mask], top[mask], atol=1e-7)
    assert_array_equal(out[~mask], base[~mask])


def test_overlay_bad_arguments():
    base = np.zeros((2, 2, 3))
    for opacity in (-0.1, 1.5, float("nan")):
        with pytest.raises(WelchInputError, match=re.escape(f"`opacity` must be in [0, 1], got {opacity!r}")):
            overlay(base, base, opacity)
    msg = "`base_rgb` and `map_rgb` must have the same shape, got (2, 2, 3) and (2, 3, 3)"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        overlay(base, np.zeros((2, 3, 3)), 0.5)


def test_tonemap():
    rng = np.random.default_rng(73)
    hdr = rng.lognormal(0.0, 2.0, size=(16, 16, 4))
    hdr[0, 0, 0] = np.nan
    hdr[0, 1, 1] = np.inf
    hdr[0, 2, 2] = -5.0
    out = tonemap(hdr)
    assert out.shape == (16, 16, 3) and out.dtype == np.float32
    assert np.isfinite(out).all() and (out >= 0).all() and (out < 1).all()
    assert_array_equal(tonemap(np.zeros((4, 4, 3))), np.zeros((4, 4, 3)))
    # monotone in the input
    ramp = np.linspace(0.0, 10.0, 50)[None, :, None].repeat(3, axis=2)
    assert (np.diff(tonemap(ramp)[0, :, 0]) > 0).all()


def test_histogram_counts_and_expected_level():
    p = np.array([0.0, 0.01, 0.02, 0.5, 0.999, 1.0, np.nan, np.nan])
    counts, edges, expected = histogram(p, bins=10)
    assert_array_equal(counts, [3, 0, 0, 0, 0, 1, 0, 0, 0, 2])
    assert_allclose(edges, np.linspace(0, 1, 11))
    assert expected == 6 / 10
    rng = np.random.default_rng(74)
    counts, edges, expected = histogram(rng.uniform(size=3000))
    assert len(counts) == 30 and expected == 100.0 and counts.sum() == 3000
    counts, _, expected = histogram(rng.uniform(size=(10, 10, 3)), bins=3)
    assert counts.sum() == 300 and expected == 100.0


@pytest.mark.parametrize("bins", [0, -3, 2.5, True])
def test_histogram_bad_bins(bins):
    with pytest.raises(WelchInputError, match=re.escape(f"`bins` must be a positive integer, got {bins!r}")):
        histogram([0.5], bins=bins)


def test_difference_picture_is_signed_and_scaled_to_the_reference():
    ref = np.full((4, 6, 3), 2.0)
    test = ref.copy()
    test[0, 0] = 2.2  # brighter by 10 % of the mean
    test[3, 5] = 1.8  # darker by as much
    test[2, 2] = 2.05  # a quarter as much brighter: a quarter of the way to the end
    levels, limit = wc.difference_picture(ref, test, share=1.0)
    assert limit == pytest.approx(0.1)  # the ends stand for +-0.2, a tenth of the mean brightness 2
    assert levels.dtype == np.uint8 and levels.shape == (4, 6)
    rgb = wc.colormap.DIFFERENCE_PALETTE[levels]
    np.testing.assert_allclose(rgb[0, 0], [0.7, 0.1, 0.1], atol=1e-6)  # red: the test side brighter
    np.testing.assert_allclose(rgb[3, 5], [0.1, 0.25, 0.7], atol=1e-6)  # blue: darker
    np.testing.assert_array_equal(rgb[1, 1], [1.0, 1.0, 1.0])  # white: equal
    steps = wc.colormap.DIFFERENCE_STEPS
    assert (levels[0, 0], levels[3, 5], levels[1, 1], levels[2, 2]) == (2 * steps, 0, steps, steps + 32)  # 31.75 up
    np.testing.assert_allclose(rgb[2, 2], 1.0 + (np.array([0.7, 0.1, 0.1]) - 1.0) * 32 / steps, atol=1e-6)
    equal, none = wc.difference_picture(ref, ref)
    assert none == 0.0 and np.all(equal == steps)
    assert wc.difference_picture(ref, ref[:2]) == (None, 0.0)


def test_difference_picture_ignores_what_is_not_finite():
    ref = np.full((2, 3, 3), 1.0)
    test = ref + np.array([0.0, 0.5, -0.5])[None, :, None]
    test[1, 0] = np.inf
    ref[1, 1] = np.nan
    levels, limit = wc.difference_picture(ref, test, share=1.0)
    steps = wc.colormap.DIFFERENCE_STEPS
    np.testing.assert_array_equal(levels, [[steps, 2 * steps, 0], [steps, steps, 0]])
    assert limit == pytest.approx(0.5)  # of the mean of the finite reference pixels, 1
