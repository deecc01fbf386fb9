"""Normality of the Welch samples and the A/A split (welch_core.diagnostics)."""

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
from scipy import stats

from welch_core import Normality, TileStats, compare, normality, split_halves
from welch_core.diagnostics import MIN_PASSES_FOR_NORMALITY, NORMALITY_ALPHA, SHAPE_LIMIT


def run_from(sums, first_seed=0, tile=8):
    ty, tx = sums.shape[1:3]
    return TileStats.from_sums(sums, range(first_seed, first_seed + len(sums)), ty * tile, tx * tile, tile)


def test_normality_flags_a_firefly_tile_not_normal_ones():
    """Tile (1, 2) gets a rare, very bright contribution (a firefly: one pass in 25 is 40 sd too bright)."""
    rng = np.random.default_rng(51)
    n = 64
    sums = rng.normal(1000.0, 10.0, size=(n, 3, 4, 3))
    sums[:, 1, 2, :] += (rng.uniform(size=(n, 1)) < 0.04) * 400.0
    sums[[5, 40], 1, 2, :] += 400.0  # at least two fireflies, whatever the draw
    result = normality(run_from(sums))
    assert isinstance(result, Normality) and result.checked
    assert result.suspect[1, 2].all()
    assert result.suspect.sum() == 3  # the three channels of that tile and nothing else
    assert (result.skewness[1, 2] > 2).all() and (result.excess_kurtosis[1, 2] > 3).all()


def test_normality_statistics_match_scipy():
    rng = np.random.default_rng(52)
    sums = rng.gamma(4.0, size=(30, 2, 2, 3))
    result = normality(run_from(sums))
    assert_allclose(result.skewness, stats.skew(sums, axis=0), rtol=1e-12)
    assert_allclose(result.excess_kurtosis, stats.kurtosis(sums, axis=0), rtol=1e-12)
    jb = stats.jarque_bera(sums[:, 0, 1, 2])
    assert_allclose(result.pvalue[0, 1, 2], jb.pvalue, rtol=1e-10)


def test_normality_rarely_flags_normal_samples():
    """On normal Welch samples the check drops few tile-channels (Jarque-Bera's tail is heavier than its chi²
    limit at small n: at n = 40 about 0.4 % fall below 1e-4, measured); well below the inconclusive share."""
    rng = np.random.default_rng(53)
    sums = rng.normal(500.0, 20.0, size=(40, 40, 50, 3))
    share = normality(run_from(sums)).suspect.mean()
    assert share < 0.01
    assert NORMALITY_ALPHA == 1e-4


def test_normality_unchecked_with_few_passes():
    rng = np.random.default_rng(54)
    few = normality(run_from(rng.normal(size=(MIN_PASSES_FOR_NORMALITY - 1, 2, 2, 3))))
    assert not few.checked
    assert np.isnan(few.pvalue).all() and not few.suspect.any()
    assert np.isfinite(few.skewness).all()  # reported, not used
    two = normality(run_from(rng.normal(size=(2, 2, 2, 3))))
    assert np.isnan(two.skewness).all() and not two.checked


def test_normality_of_constant_tiles_is_nan_without_warnings(recwarn):
    sums = np.zeros((20, 2, 2, 3))
    sums[:, 1, 1, :] = 0.1 * 1024  # a constant emitter: scipy's skew warns about such data
    sums[:, 0, 0, :] = np.random.default_rng(55).normal(size=(20, 3))
    result = normality(run_from(sums))
    assert np.isnan(result.pvalue[1:]).all() and not result.suspect.any()
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


def test_split_halves_are_disjoint_alternating_halves():
    rng = np.random.default_rng(56)
    seeds = [17, 3, 99, 4, 12, 8, 61]
    run = TileStats.from_sums(rng.normal(size=(7, 2, 3, 3)), seeds, 16, 24, 8)
    first, second = split_halves(run)
    assert first.seeds == [17, 99, 12] and second.seeds == [3, 4, 8]
    assert set(first.seeds).isdisjoint(second.seeds)
    assert first.n == second.n == 3
    assert_array_equal(first.sums, run.sums[[0, 2, 4]])
    assert_array_equal(second.sums, run.sums[[1, 3, 5]])
    assert (first.width, first.height, first.tile) == (24, 16, 8)


def test_a_a_test_passes_on_one_unbiased_run():
    rng = np.random.default_rng(57)
    sums = rng.gamma(400.0, size=(60, 6, 8, 3))
    sums += np.linspace(0.0, 1.0, 60)[:, None, None, None]  # a slow drift over the run falls on both halves
    first, second = split_halves(run_from(sums))
    result = compare(first, second)
    assert result.test == "welch"
    assert result.verdict == "no_evidence"


def test_skewed_tiles_are_trusted_again_once_their_mean_is_close_to_normal():
    """Strongly skewed samples (lognormal, sigma 1.5) at n = 48 are flagged; exponential samples (skewness 2,
    excess kurtosis 6) fail Jarque-Bera at n = 1000 too, but their shape measure (g1² + |g2|) / n is then far below
    SHAPE_LIMIT: the mean of so many is close to normal, so the tiles are trusted."""
    rng = np.random.default_rng(53)
    few = normality(run_from(rng.lognormal(0.0, 1.5, size=(48, 4, 4, 3))))
    many = normality(run_from(rng.exponential(1.0, size=(1000, 4, 4, 3))))
    assert few.suspect.mean() > 0.9
    assert (many.pvalue < NORMALITY_ALPHA).all() and (many.shape < SHAPE_LIMIT).all() and not many.suspect.any()
