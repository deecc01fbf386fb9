"""Relative effect sizes, their confidence intervals and the minimum detectable bias (welch_core.effect)."""

import numpy as np
from numpy.testing import assert_allclose
from scipy import optimize, stats

from welch_core import Effect, TileStats, compare, effect_sizes, welch_from_stats
from welch_core.effect import DETECTION_POWER, relative_interval
from welch_core.tile_test import TileTest
from welch_core.tile_tests import tile_test_of


def welch_tested(ref_mean, ref_var, n_ref, test_mean, test_var, n_test, known_reference=False):
    """Welch's test as `welch_test.WelchTest` makes it, from summary statistics; `known_reference`: the
    reference mean is taken as exact (no variance of its estimate)."""
    result = welch_from_stats(ref_mean, ref_var, n_ref, test_mean, test_var, n_test)
    ref_mean = np.broadcast_to(np.asarray(ref_mean, dtype=float), result.pvalue.shape)
    v = np.zeros(ref_mean.shape) if known_reference else np.broadcast_to(np.asarray(ref_var) / n_ref, ref_mean.shape)
    return TileTest(tile_test_of("welch"), result, np.zeros(ref_mean.shape, bool), True, ref_mean, v, -v)


def fieller_by_root_finding(d, r, v_dd, v_dr, v_rr, q):
    """An independent oracle for the interval: the thetas where (d - theta r) / sqrt(V(theta)) = -q and = +q,
    found by brentq on each side of the estimate."""
    f = lambda theta, target: (d - theta * r) / np.sqrt(v_dd - 2 * theta * v_dr + theta**2 * v_rr) - target  # noqa: E731
    est = d / r
    return optimize.brentq(f, est, est + 10, args=(-q,)), optimize.brentq(f, est - 10, est, args=(q,))


def test_rel_diff_sign_and_value():
    ref_mean = np.array([100.0, 100.0, 50.0, -20.0])
    test_mean = np.array([102.0, 97.0, 50.0, -21.0])
    tested = welch_tested(ref_mean, 4.0, 30, test_mean, 4.0, 30)
    effect = effect_sizes(tested, alpha=0.05, n_tests=4)
    assert isinstance(effect, Effect)
    # (test - reference) / |reference|: brighter is positive, darker negative
    assert_allclose(effect.rel_diff, [0.02, -0.03, 0.0, -0.05], rtol=1e-12, atol=1e-15)
    # Fieller's interval, against root finding on the test of the ratio (the reference's own noise included)
    for i in range(3):  # positive reference means
        q = stats.t.isf(0.025, tested.result.df[i])
        d, r = test_mean[i] - ref_mean[i], ref_mean[i]
        high, low = fieller_by_root_finding(d, r, 8 / 30, -4 / 30, 4 / 30, q)
        assert_allclose([effect.ci_low[i], effect.ci_high[i]], [low, high], rtol=1e-9, atol=1e-12)
    # a negative reference mean: relative to |mu_ref|, the interval of the ratio turns over
    assert effect.ci_low[3] < -0.05 < effect.ci_high[3]
    # with the reference taken as exact, the interval is the t interval of the difference over |reference|
    exact = effect_sizes(welch_tested(ref_mean, 4.0, 30, test_mean, 4.0, 30, known_reference=True), 0.05, 4)
    half = stats.t.isf(0.025, tested.result.df) * tested.result.standard_error / np.abs(ref_mean)
    assert_allclose(exact.ci_low, exact.rel_diff - half, rtol=1e-9)
    assert_allclose(exact.ci_high, exact.rel_diff + half, rtol=1e-9)


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
    # Fieller's interval of the ratio, from the estimated reference mean (what compare has): exact for normal
    # samples but for the Welch-Satterthwaite degrees of freedom
    tested = welch_tested(ref.mean(0), ref.var(0, ddof=1), 12, test.mean(0), test.var(0, ddof=1), 9)
    effect = effect_sizes(tested, alpha, n_tests=1)
    covered = np.mean((effect.ci_low <= truth) & (truth <= effect.ci_high))
    assert abs(covered - (1 - alpha)) < 3 * np.sqrt(alpha * (1 - alpha) / n_elements)
    assert_allclose(relative_interval(tested, alpha)[0], effect.ci_low)


def test_min_detectable_bias_has_the_stated_power():
    """A shift equal to the quoted minimum detectable bias is found at level alpha / n_tests with about the
    stated power (0.8)."""
    rng = np.random.default_rng(63)
    n, sd, elements, alpha, n_tests = 20, 5.0, 4000, 0.05, 10
    mu = np.full(elements, 100.0)
    # the minimum detectable bias for this design (computed from one run, as a user would)
    a = mu + rng.normal(0.0, sd, size=(n, elements))
    b = mu + rng.normal(0.0, sd, size=(n, elements))
    r = welch_tested(mu, a.var(0, ddof=1), n, b.mean(0) - a.mean(0) + mu, b.var(0, ddof=1), n)
    mdb = np.median(effect_sizes(r, alpha, n_tests).min_detectable)
    # fresh runs with that shift: the share found at the per-tile Bonferroni level
    a = mu + rng.normal(0.0, sd, size=(n, elements))
    b = mu * (1 + mdb) + rng.normal(0.0, sd, size=(n, elements))
    r = welch_tested(mu, a.var(0, ddof=1), n, b.mean(0) - a.mean(0) + mu, b.var(0, ddof=1), n)
    power = np.mean(r.result.pvalue <= alpha / n_tests)
    assert abs(power - DETECTION_POWER) < 0.06
    # and the formula: (t_{1 - level/2} + t_{power}) * SE / |ref|
    df, se = r.result.df, r.result.standard_error
    expected = (stats.t.ppf(1 - alpha / n_tests / 2, df) + stats.t.ppf(0.8, df)) * se / mu
    assert_allclose(effect_sizes(r, alpha, n_tests).min_detectable, expected, rtol=1e-10)


def test_min_detectable_shrinks_with_more_passes():
    rng = np.random.default_rng(64)
    mdb = []
    for n in (10, 40, 160):
        a = rng.normal(100.0, 5.0, size=(n, 500))
        b = rng.normal(100.0, 5.0, size=(n, 500))
        r = welch_tested(np.full(500, 100.0), a.var(0, ddof=1), n, 100.0 + b.mean(0) - a.mean(0), b.var(0, ddof=1), n)
        mdb.append(np.median(effect_sizes(r, 0.01, 100).min_detectable))
    assert mdb[0] > 2 * mdb[1] > 4 * mdb[2] * 0.9


def test_excluded_elements_have_nan_effects():
    tested = welch_tested([1.0, 2.0, 1.0], np.array([1.0, 0.0, 1.0]), 10, [1.0, 2.5, 1.2], [1.0, 0.0, 1.0], 10)
    tested.result.pvalue[0] = np.nan  # as for a side with a single pass: no p-value
    tested.result.df[0] = np.nan
    effect = effect_sizes(tested, 0.01, 3)
    # n < 2 and a deterministic difference: no interval; the relative difference itself stays defined
    for name in ("ci_low", "ci_high", "min_detectable"):
        values = getattr(effect, name)
        assert np.isnan(values[:2]).all() and np.isfinite(values[2]), name
    assert effect.rel_diff[1] == 0.25


def test_zero_reference_mean_gives_non_finite_relative_effect(recwarn):
    """A black reference tile against a noisy test tile: no relative effect, and no floating-point warning."""
    effect = effect_sizes(welch_tested([0.0], 1.0, 10, [0.5], 1.0, 10), 0.01, 1)
    assert not np.isfinite(effect.rel_diff).any() and not np.isfinite(effect.ci_low).any()
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]
