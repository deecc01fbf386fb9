"""Relative effect sizes, their confidence intervals and the minimum detectable bias (welch_core.effect)."""

import numpy as np
from numpy.testing import assert_allclose
from scipy import special, stats

from welch_core import Effect, TileStats, compare, effect_sizes, welch_from_stats
from welch_core.effect import DETECTION_POWER


def test_rel_diff_sign_and_value():
    ref_mean = np.array([100.0, 100.0, 50.0, -20.0])
    test_mean = np.array([102.0, 97.0, 50.0, -21.0])
    result = welch_from_stats(ref_mean, 4.0, 30, test_mean, 4.0, 30)
    effect = effect_sizes(result, ref_mean, alpha=0.05, n_tests=4)
    assert isinstance(effect, Effect)
    # (test - reference) / |reference|: brighter is positive, darker negative
    assert_allclose(effect.rel_diff, [0.02, -0.03, 0.0, -0.05], rtol=1e-12, atol=1e-15)
    half = special.stdtrit(result.df, 0.975) * result.standard_error / np.abs(ref_mean)
    assert_allclose(effect.ci_low, effect.rel_diff - half, rtol=1e-12)
    assert_allclose(effect.ci_high, effect.rel_diff + half, rtol=1e-12)


def test_rel_diff_from_compare_on_a_known_shift():
    rng = np.random.default_rng(61)
    mean = rng.uniform(500.0, 1500.0, size=(3, 4, 3))
    ref = TileStats.from_sums(mean * rng.normal(1.0, 0.01, size=(40, 3, 4, 3)), range(40), 24, 32, 8)
    test = TileStats.from_sums(mean * 0.97 * rng.normal(1.0, 0.01, size=(40, 3, 4, 3)), range(40, 80), 24, 32, 8)
    effect = compare(ref, test).effect
    assert_allclose(effect.rel_diff, -0.03, atol=0.01)
    assert (effect.ci_high < 0).all()


def test_confidence_interval_coverage():
    """2400 independent tile-channels with a true +2 % shift: the 90 % interval covers it in 90 % of them
    (within 3 binomial standard deviations)."""
    rng = np.random.default_rng(62)
    alpha, n_elements = 0.1, 2400
    truth = 0.02
    mu = rng.uniform(50.0, 150.0, size=n_elements)
    ref = mu + rng.normal(0.0, 0.05 * mu, size=(12, n_elements))
    test = mu * (1 + truth) + rng.normal(0.0, 0.08 * mu, size=(9, n_elements))
    result = welch_from_stats(ref.mean(0), ref.var(0, ddof=1), 12, test.mean(0), test.var(0, ddof=1), 9)
    # the interval is for (test - ref) / |ref|; with the true reference mean in the denominator it is exact
    effect = effect_sizes(result, mu, alpha, n_tests=1)
    covered = np.mean((effect.ci_low <= truth) & (truth <= effect.ci_high))
    assert abs(covered - (1 - alpha)) < 3 * np.sqrt(alpha * (1 - alpha) / n_elements)
    # with the estimated reference mean (what compare uses) the coverage is the same to first order
    effect = effect_sizes(result, ref.mean(0), alpha, n_tests=1)
    covered = np.mean((effect.ci_low <= truth) & (truth <= effect.ci_high))
    assert abs(covered - (1 - alpha)) < 0.03


def test_min_detectable_bias_has_the_stated_power():
    """A shift equal to the quoted minimum detectable bias is found at level alpha / n_tests with about the
    stated power (0.8)."""
    rng = np.random.default_rng(63)
    n, sd, elements, alpha, n_tests = 20, 5.0, 4000, 0.05, 10
    mu = np.full(elements, 100.0)
    # the minimum detectable bias for this design (computed from one run, as a user would)
    a = mu + rng.normal(0.0, sd, size=(n, elements))
    b = mu + rng.normal(0.0, sd, size=(n, elements))
    r = welch_from_stats(a.mean(0), a.var(0, ddof=1), n, b.mean(0), b.var(0, ddof=1), n)
    mdb = np.median(effect_sizes(r, mu, alpha, n_tests).min_detectable)
    # fresh runs with that shift: the share found at the per-tile Bonferroni level
    a = mu + rng.normal(0.0, sd, size=(n, elements))
    b = mu * (1 + mdb) + rng.normal(0.0, sd, size=(n, elements))
    r = welch_from_stats(a.mean(0), a.var(0, ddof=1), n, b.mean(0), b.var(0, ddof=1), n)
    power = np.mean(r.pvalue <= alpha / n_tests)
    assert abs(power - DETECTION_POWER) < 0.06
    # and the formula: (t_{1 - level/2} + t_{power}) * SE / |ref|
    expected = (stats.t.ppf(1 - alpha / n_tests / 2, r.df) + stats.t.ppf(0.8, r.df)) * r.standard_error / mu
    assert_allclose(effect_sizes(r, mu, alpha, n_tests).min_detectable, expected, rtol=1e-10)


def test_min_detectable_shrinks_with_more_passes():
    rng = np.random.default_rng(64)
    mdb = []
    for n in (10, 40, 160):
        a = rng.normal(100.0, 5.0, size=(n, 500))
        b = rng.normal(100.0, 5.0, size=(n, 500))
        r = welch_from_stats(a.mean(0), a.var(0, ddof=1), n, b.mean(0), b.var(0, ddof=1), n)
        mdb.append(np.median(effect_sizes(r, np.full(500, 100.0), 0.01, 100).min_detectable))
    assert mdb[0] > 2 * mdb[1] > 4 * mdb[2] * 0.9


def test_excluded_elements_have_nan_effects():
    result = welch_from_stats([1.0, 2.0, 1.0], [1.0, 0.0, 1.0], [1, 10, 10], [1.0, 2.5, 1.2], [1.0, 0.0, 1.0], 10)
    effect = effect_sizes(result, np.array([1.0, 2.0, 1.0]), 0.01, 3)
    # n < 2 and a deterministic difference: no interval; the relative difference itself stays defined
    for name in ("ci_low", "ci_high", "min_detectable"):
        values = getattr(effect, name)
        assert np.isnan(values[:2]).all() and np.isfinite(values[2]), name
    assert effect.rel_diff[1] == 0.25


def test_zero_reference_mean_gives_non_finite_relative_effect(recwarn):
    """A black reference tile against a noisy test tile: no relative effect, and no floating-point warning."""
    result = welch_from_stats([0.0], [1.0], [10], [0.5], [1.0], [10])
    effect = effect_sizes(result, np.array([0.0]), 0.01, 1)
    assert not np.isfinite(effect.rel_diff).any() and not np.isfinite(effect.ci_low).any()
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]
