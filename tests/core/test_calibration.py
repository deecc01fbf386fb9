"""Calibration under H0: two unbiased sources must give `biased` in at most alpha of the trials.

The false-positive rate is the promise of the verdict, so it is measured on the full `compare` over thousands of
synthetic trials with the difficulties of real renders: non-normal per-pixel samples, sources with different
variances, correlated colour channels and unequal pass counts.

Bound: with T trials at alpha, the number of `biased` verdicts must not exceed the one-sided 99.9 % upper limit
of Binomial(T, alpha), i.e. ``scipy.stats.binom.ppf(0.999, T, alpha)`` (35 for T = 2000, alpha = 0.01). A
calibrated test fails this check with probability at most 0.1 %; the seeds are fixed, so the result is
deterministic.
"""

import numpy as np
import pytest
from scipy import stats

from welch_core import TileStats, compare, welch_from_stats

ALPHA = 0.01
TRIALS = 2000

# Small images keep the trials cheap: 32x48 px in tiles of 8 = 4x6 tiles, 72 tile-channels a trial.
HEIGHT, WIDTH, TILE = 32, 48, 8
TY, TX = HEIGHT // TILE, WIDTH // TILE


def pixel_means():
    """A per-pixel mean image with structure in every channel (the expected render)."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    return np.stack([0.3 + x / WIDTH, 0.5 + 0.5 * np.sin(y / 5.0) ** 2, 1.5 - (x / WIDTH) * (y / HEIGHT)], axis=-1)


def tile_sums_of(pixels):
    """Tile sums of (..., HEIGHT, WIDTH, 3) pixel arrays, the Welch samples."""
    return pixels.reshape(*pixels.shape[:-3], TY, TILE, TX, TILE, 3).sum(axis=(-4, -2))


def exponential_source(rng, n, mu):
    """Reference: pixel = mu * (S + E_c) / 2, S shared by R, G, B, all Exp(1). CV 0.71, channel correlation 0.5."""
    shared = rng.exponential(size=(n, HEIGHT, WIDTH, 1))
    own = rng.exponential(size=(n, HEIGHT, WIDTH, 3))
    return tile_sums_of(mu * (shared + own) / 2.0)


def lognormal_source(rng, n, mu, sigma=1.0):
    """Test: the same mean with lognormal factors of mean 1 (variance e^sigma² - 1 = 1.72): heavier tails and a
    larger variance than the reference, again with a shared component across channels."""

    def unit_mean_lognormal(shape):
        return np.exp(sigma * rng.standard_normal(shape) - sigma**2 / 2.0)

    shared = unit_mean_lognormal((n, HEIGHT, WIDTH, 1))
    own = unit_mean_lognormal((n, HEIGHT, WIDTH, 3))
    return tile_sums_of(mu * (shared + own) / 2.0)


def run_from(sums, first_seed):
    return TileStats.from_sums(sums, range(first_seed, first_seed + len(sums)), HEIGHT, WIDTH, TILE)


def binomial_upper_limit(trials, alpha):
    return int(stats.binom.ppf(0.999, trials, alpha))


@pytest.mark.slow
def test_false_positive_rate_of_compare_under_h0():
    """2000 trials of `compare` at alpha = 0.01: exponential (10 passes) against lognormal (16 passes) pixels,
    correlated RGB, pixel-level sums into 8x8 tiles. Measured: 9 of 2000 `biased` (0.45 %); bound 35."""
    rng = np.random.default_rng(20200901)
    mu = pixel_means()
    biased = 0
    global_p = np.empty(TRIALS)
    for trial in range(TRIALS):
        ref = run_from(exponential_source(rng, 10, mu), 0)
        test = run_from(lognormal_source(rng, 16, mu), 1000)
        result = compare(ref, test, alpha=ALPHA)
        assert result.test == "welch"
        biased += result.verdict == "biased"
        global_p[trial] = result.p_value
    assert biased <= binomial_upper_limit(TRIALS, ALPHA), f"{biased} of {TRIALS} trials biased"
    # the global p-value itself is (super-)uniform at other levels too
    for level in (0.05, 0.1, 0.2):
        assert np.mean(global_p <= level) <= level + 3 * np.sqrt(level * (1 - level) / TRIALS)


@pytest.mark.slow
def test_false_positive_rate_at_few_passes():
    """2000 trials with very few, unequal passes (3 against 7: the normality check is off) and variances 1:9,
    on skewed Welch samples drawn directly as tile sums (Gamma, skewness 0.5). Measured: 7 of 2000 (0.35 %);
    bound 35."""
    rng = np.random.default_rng(77)
    mean = rng.uniform(50.0, 150.0, size=(TY, TX, 3))
    biased = 0
    for _ in range(TRIALS):
        ref_sums = mean + rng.gamma(16.0, 1.0, size=(3, TY, TX, 3)) - 16.0  # sd 4
        test_sums = mean + 3.0 * (rng.gamma(16.0, 1.0, size=(7, TY, TX, 3)) - 16.0)  # sd 12
        biased += compare(run_from(ref_sums, 0), run_from(test_sums, 100), alpha=ALPHA).verdict == "biased"
    assert biased <= binomial_upper_limit(TRIALS, ALPHA), f"{biased} of {TRIALS} trials biased"


@pytest.mark.slow
def test_false_positive_rate_of_the_paired_test():
    """1000 trials of the paired test with common random numbers (the same seeds on both sides): the shared
    noise cancels, only the small independent part remains. Measured: 3 of 1000 (0.3 %); bound 21 (the 99.9 %
    binomial limit for 1000 trials)."""
    rng = np.random.default_rng(4242)
    mean = rng.uniform(50.0, 150.0, size=(TY, TX, 3))
    trials, biased = 1000, 0
    for _ in range(trials):
        common = mean * rng.gamma(64.0, 1 / 64.0, size=(12, TY, TX, 1))  # shared by both sides and channels
        ref_sums = common + rng.exponential(2.0, size=common.shape[:3] + (3,))
        test_sums = common + rng.exponential(2.0, size=common.shape[:3] + (3,))
        result = compare(run_from(ref_sums, 0), run_from(test_sums, 0), alpha=ALPHA)
        assert result.test == "paired"
        biased += result.verdict == "biased"
    assert biased <= binomial_upper_limit(trials, ALPHA), f"{biased} of {trials} trials biased"


def test_tile_pvalues_uniform_on_normal_data():
    """Per tile-channel p-values under H0 with normal Welch samples, unequal variances and counts: uniform
    (two-sided Kolmogorov-Smirnov over 60x80x3 = 14400 independent tests)."""
    rng = np.random.default_rng(9)
    shape = (60, 80, 3)
    mean = rng.uniform(10.0, 20.0, size=shape)
    ref = mean + rng.normal(0.0, 1.0, size=(6, *shape))
    test = mean + rng.normal(0.0, 3.0, size=(15, *shape))
    result = compare(
        TileStats.from_sums(ref, range(6), 60 * 8, 80 * 8, 8),
        TileStats.from_sums(test, range(6, 21), 60 * 8, 80 * 8, 8),
    )
    p = result.pvalues.ravel()
    assert np.isfinite(p).all()
    assert stats.kstest(p, "uniform").pvalue > 0.01
    assert abs(np.mean(p <= 0.01) - 0.01) < 3 * np.sqrt(0.01 * 0.99 / p.size)
    assert result.verdict == "no_evidence"


def test_welch_pvalues_uniform_pooled_over_variance_ratios():
    """Welch's test with real-valued nu stays uniform across variance ratios and small unequal counts, where
    a rounded nu or the Gaussian p would not (checked by KS per configuration)."""
    rng = np.random.default_rng(10)
    for n1, n2, sd2 in ((3, 5, 1.0), (4, 12, 4.0), (10, 3, 0.3), (25, 25, 2.0)):
        a = rng.normal(0.0, 1.0, size=(n1, 20000))
        b = rng.normal(0.0, sd2, size=(n2, 20000))
        res = welch_from_stats(a.mean(0), a.var(0, ddof=1), n1, b.mean(0), b.var(0, ddof=1), n2)
        assert stats.kstest(res.pvalue, "uniform").pvalue > 0.001, (n1, n2, sd2)
