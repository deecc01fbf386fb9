"""Welch's t-test, the paired t-test and the p-value functions (welch_core.ttest)."""

import re
from fractions import Fraction

import mpmath
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import special, stats

from welch_core import (
    PVALUE_METHODS,
    Reason,
    WelchInputError,
    paired_from_stats,
    paired_ttest,
    pvalue_as_erf,
    pvalue_exact,
    pvalue_gauss,
    two_sided_pvalue,
    welch_from_stats,
    welch_ttest,
)


def mp_student_p(t, df, digits=50):
    """Two-sided Student-t p-value at `digits` digits: I_{df / (df + t^2)}(df / 2, 1 / 2)."""
    with mpmath.workdps(digits):
        t, df = mpmath.mpf(t), mpmath.mpf(df)
        return mpmath.betainc(df / 2, mpmath.mpf(1) / 2, 0, df / (df + t * t), regularized=True)


def mp_gauss_p(t, digits=50):
    with mpmath.workdps(digits):
        return mpmath.erfc(abs(mpmath.mpf(t)) / mpmath.sqrt(2))


def rel_err(x, ref):
    return float(abs((mpmath.mpf(float(x)) - ref) / ref))


# -- reference values --------------------------------------------------------------------------------------


def test_welch_reference_values_from_scipy():
    # rng = np.random.default_rng(2020)
    # a = rng.normal(10.0, 1.0, size=12)
    # b = rng.normal(10.8, 2.5, size=9)
    # scipy.stats.ttest_ind(a, b, equal_var=False)
    # -> statistic -1.7700514916194954, df 9.2136520090355, pvalue 0.10972056808975283
    rng = np.random.default_rng(2020)
    a = rng.normal(10.0, 1.0, size=12)
    b = rng.normal(10.8, 2.5, size=9)
    res = welch_ttest(a, b)
    assert_allclose(res.statistic, -1.7700514916194954, rtol=1e-12)
    assert_allclose(res.df, 9.2136520090355, rtol=1e-12)
    assert_allclose(res.pvalue, 0.10972056808975283, rtol=1e-12)
    assert res.reason == Reason.VALID
    assert_allclose(res.mean_difference, b.mean() - a.mean(), rtol=1e-12)
    assert_allclose(res.standard_error, np.sqrt(a.var(ddof=1) / 12 + b.var(ddof=1) / 9), rtol=1e-12)


def test_welch_reference_values_small_p():
    # rng = np.random.default_rng(31)
    # a = rng.normal(0.0, 1.0, size=40)
    # b = rng.normal(3.0, 1.5, size=25)
    # scipy.stats.ttest_ind(a, b, equal_var=False)
    # -> statistic -10.020130768694344, df 44.74807256454989, pvalue 5.199383596071784e-13
    rng = np.random.default_rng(31)
    a = rng.normal(0.0, 1.0, size=40)
    b = rng.normal(3.0, 1.5, size=25)
    res = welch_ttest(a, b)
    assert_allclose(res.statistic, -10.020130768694344, rtol=1e-12)
    assert_allclose(res.df, 44.74807256454989, rtol=1e-12)
    assert_allclose(res.pvalue, 5.199383596071784e-13, rtol=1e-10)


@pytest.mark.parametrize("n1, n2", [(2, 2), (3, 17), (12, 9), (64, 5)])
def test_welch_matches_scipy_along_axis(n1, n2):
    rng = np.random.default_rng(100 * n1 + n2)
    a = rng.normal(1.0, rng.uniform(0.5, 2.0, size=(4, 5, 3)), size=(n1, 4, 5, 3))
    b = rng.normal(1.2, rng.uniform(0.5, 2.0, size=(4, 5, 3)), size=(n2, 4, 5, 3))
    res = welch_ttest(a, b, axis=0)
    ref = stats.ttest_ind(a, b, axis=0, equal_var=False)
    assert_allclose(res.statistic, ref.statistic, rtol=1e-11)
    assert_allclose(res.df, ref.df, rtol=1e-11)
    assert_allclose(res.pvalue, ref.pvalue, rtol=1e-9, atol=1e-300)
    assert (res.reason == Reason.VALID).all()


def test_welch_other_axis():
    rng = np.random.default_rng(5)
    a = rng.normal(size=(6, 11))
    b = rng.normal(0.3, 2.0, size=(6, 8))
    res = welch_ttest(a, b, axis=1)
    ref = stats.ttest_ind(a, b, axis=1, equal_var=False)
    assert_allclose(res.statistic, ref.statistic, rtol=1e-12)
    assert_allclose(res.pvalue, ref.pvalue, rtol=1e-10)


def test_summary_path_equals_raw_path():
    rng = np.random.default_rng(11)
    a = rng.exponential(2.0, size=(14, 30))
    b = rng.exponential(2.1, size=(23, 30))
    raw = welch_ttest(a, b)
    summary = welch_from_stats(a.mean(0), a.var(0, ddof=1), 14, b.mean(0), b.var(0, ddof=1), 23)
    for name in ("statistic", "df", "pvalue", "mean_difference", "standard_error"):
        assert_allclose(getattr(summary, name), getattr(raw, name), rtol=1e-12, err_msg=name)
    assert_array_equal(summary.reason, raw.reason)
    scipy_ref = stats.ttest_ind_from_stats(
        a.mean(0), a.std(0, ddof=1), 14, b.mean(0), b.std(0, ddof=1), 23, equal_var=False
    )
    assert_allclose(summary.statistic, scipy_ref.statistic, rtol=1e-12)
    assert_allclose(summary.pvalue, scipy_ref.pvalue, rtol=1e-10)


def test_df_is_the_real_welch_satterthwaite_value():
    """nu from eq. 3 in exact rational arithmetic: 2523/457 = 5.52..., not rounded to 5 or 6."""
    a = np.array([1.0, 2.0, 3.0, 4.0])  # variance 5/3, n = 4
    b = np.array([2.0, 4.0, 6.0, 8.0, 10.0])  # variance 10, n = 5
    s1, s2 = Fraction(5, 3) / 4, Fraction(10) / 5
    nu = (s1 + s2) ** 2 / (s1**2 / 3 + s2**2 / 4)  # eq. 3
    assert nu == Fraction(2523, 457)
    res = welch_ttest(a, b)
    assert_allclose(res.df, float(nu), rtol=1e-14)
    assert res.df != np.round(res.df)
    t = (2.5 - 6.0) / np.sqrt(float(s1 + s2))  # eq. 1
    assert_allclose(res.statistic, t, rtol=1e-14)
    assert rel_err(res.pvalue, mp_student_p(t, nu.numerator / mpmath.mpf(nu.denominator))) < 1e-12
    assert_allclose(res.pvalue, stats.ttest_ind(a, b, equal_var=False).pvalue, rtol=1e-12)
    # Rounding nu (what some ports do) would give a visibly different p-value.
    assert abs(pvalue_exact(t, 5) - res.pvalue) > 1e-3 * res.pvalue


# -- paired test -------------------------------------------------------------------------------------------


def test_paired_reference_values_from_scipy():
    # rng = np.random.default_rng(7)
    # a = rng.normal(5.0, 1.0, size=15)
    # b = a + rng.normal(0.8, 0.5, size=15)
    # scipy.stats.ttest_rel(a, b) -> statistic -3.732835159321325, df 14, pvalue 0.00222774681837129
    rng = np.random.default_rng(7)
    a = rng.normal(5.0, 1.0, size=15)
    b = a + rng.normal(0.8, 0.5, size=15)
    res = paired_ttest(a, b)
    assert_allclose(res.statistic, -3.732835159321325, rtol=1e-12)
    assert res.df == 14.0
    assert_allclose(res.pvalue, 0.00222774681837129, rtol=1e-12)
    assert_allclose(res.mean_difference, np.mean(b - a), rtol=1e-12)


def test_paired_matches_scipy_along_axis():
    rng = np.random.default_rng(8)
    common = rng.gamma(2.0, size=(20, 3, 4, 3))  # shared noise of common random numbers
    a = common + rng.normal(0, 0.1, size=common.shape)
    b = common * 1.01 + rng.normal(0, 0.1, size=common.shape)
    res = paired_ttest(a, b, axis=0)
    ref = stats.ttest_rel(a, b, axis=0)
    assert_allclose(res.statistic, ref.statistic, rtol=1e-10)
    assert_allclose(res.pvalue, ref.pvalue, rtol=1e-9)
    assert_array_equal(res.df, np.full((3, 4, 3), 19.0))


def test_paired_sign_agrees_with_welch():
    rng = np.random.default_rng(9)
    a = rng.normal(0.0, 1.0, size=30)
    b = a + 0.5 + rng.normal(0.0, 0.2, size=30)
    assert np.sign(paired_ttest(a, b).statistic) == np.sign(welch_ttest(a, b).statistic) == -1


def test_paired_shape_mismatch():
    msg = "paired samples must have the same shape, got (5,) and (6,)"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        paired_ttest(np.zeros(5), np.zeros(6))


def test_paired_degenerate_differences():
    rng = np.random.default_rng(12)
    a = rng.normal(size=(8, 4))
    a[:, 1] = 0.3
    b = a.copy()
    b[:, 1] = 0.4  # a constant difference (0.4 - 0.3 is not an exact binary fraction)
    b[:, 2] += rng.normal(size=8)
    b[3, 3] = np.nan
    res = paired_ttest(a, b)
    assert_array_equal(
        res.reason, [Reason.ZERO_VARIANCE, Reason.DETERMINISTIC_DIFFERENCE, Reason.VALID, Reason.NON_FINITE]
    )
    assert np.isnan(res.pvalue[[0, 1, 3]]).all()
    assert 0.0 < res.pvalue[2] < 1.0
    one = paired_ttest(a[:1], b[:1])
    assert (one.reason == Reason.TOO_FEW_PASSES).all() and np.isnan(one.pvalue).all()


# -- p-values ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "t, df",
    [(40.0, 5.0), (10.0, 1000.0), (1.5, 2.0), (0.01, 1.0), (7.0, 3.3), (25.0, 19.99), (5.0, 1e4), (60.0, 200.0)],
)
def test_pvalue_exact_against_mpmath(t, df):
    ref = mp_student_p(t, df)
    assert rel_err(pvalue_exact(t, df), ref) < 1e-10
    assert rel_err(pvalue_exact(-t, df), ref) < 1e-10


def test_pvalue_exact_tiny_values_keep_precision():
    """Where 2 (1 - cdf) gives 0 (p < 1e-16), the exact p keeps full relative precision."""
    p = pvalue_exact(10.0, 1000.0)
    assert 0.0 < p < 1e-20
    assert 2.0 * (1.0 - stats.t.cdf(10.0, 1000.0)) == 0.0
    assert rel_err(p, mp_student_p(10.0, 1000.0)) < 1e-10
    p = pvalue_exact(40.0, 5.0)  # 1.84e-7: the naive form keeps only ~9 digits here
    assert rel_err(2.0 * (1.0 - stats.t.cdf(40.0, 5.0)), mp_student_p(40.0, 5.0)) > 1e-12
    assert rel_err(p, mp_student_p(40.0, 5.0)) < 1e-14


@pytest.mark.parametrize("t", [0.0, 0.1, 1.0, 2.5, 5.0, 10.0, 20.0, 37.0])
def test_pvalue_gauss_against_mpmath(t):
    assert rel_err(pvalue_gauss(t), mp_gauss_p(t)) < 1e-12
    assert rel_err(pvalue_gauss(-t), mp_gauss_p(t)) < 1e-12


def test_pvalue_as_erf_within_abramowitz_stegun_bound():
    t = np.linspace(0.0, 40.0, 40001)
    err = np.abs(pvalue_as_erf(t) - special.erfc(t / np.sqrt(2.0)))
    assert err.max() <= 2.5e-5  # A&S 7.1.25
    assert err.max() > 1e-6  # and it really is the approximation, not erfc
    assert_allclose(pvalue_as_erf(-t), pvalue_as_erf(t))


def test_gaussian_used_only_where_df_at_least_20():
    t = np.array([3.0, 3.0, 3.0, 3.0, 4.0])
    df = np.array([1.0, 5.5, 19.999, 20.0, 500.0])
    exact = pvalue_exact(t, df)
    for method, approx in (("gauss", pvalue_gauss), ("as_erf", pvalue_as_erf)):
        p = two_sided_pvalue(t, df, method)
        assert_array_equal(p[:3], exact[:3])
        assert_array_equal(p[3:], approx(t[3:]))
    assert_array_equal(two_sided_pvalue(t, df, "exact"), exact)
    assert PVALUE_METHODS == ("exact", "gauss", "as_erf")


def test_pvalue_method_passes_through_welch_from_stats():
    res = welch_from_stats([0.0, 0.0], [1.0, 1.0], [4, 40], [1.0, 1.0], [1.0, 1.0], [4, 40], pvalue_method="gauss")
    exact = welch_from_stats([0.0, 0.0], [1.0, 1.0], [4, 40], [1.0, 1.0], [1.0, 1.0], [4, 40])
    assert res.pvalue[0] == exact.pvalue[0]  # nu = 6: exact
    assert res.pvalue[1] == pvalue_gauss(exact.statistic[1])  # nu = 78: Gaussian


def test_bad_pvalue_method():
    msg = "`pvalue_method` must be one of ('exact', 'gauss', 'as_erf'), got 'normal'"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        two_sided_pvalue(1.0, 5.0, "normal")
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        welch_ttest(np.zeros(3), np.ones(3), pvalue_method="normal")


# -- degenerate elements -----------------------------------------------------------------------------------


def test_degenerate_cases_and_reasons():
    #           n<2   0-var  determ.  one 0-var  nan mean  inf var  valid
    mean1 = [1.0, 2.0, 2.0, 3.0, np.nan, 1.0, 1.0]
    var1 = [1.0, 0.0, 0.0, 0.0, 1.0, np.inf, 1.0]
    n1 = [1, 10, 10, 10, 10, 10, 10]
    mean2 = [1.0, 2.0, 2.5, 3.5, 1.0, 1.0, 1.5]
    var2 = [1.0, 0.0, 0.0, 2.0, 1.0, 1.0, 2.0]
    n2 = [10, 12, 12, 7, 10, 10, 12]
    res = welch_from_stats(mean1, var1, n1, mean2, var2, n2)
    assert_array_equal(
        res.reason,
        [
            Reason.TOO_FEW_PASSES,
            Reason.ZERO_VARIANCE,
            Reason.DETERMINISTIC_DIFFERENCE,
            Reason.VALID,
            Reason.NON_FINITE,
            Reason.NON_FINITE,
            Reason.VALID,
        ],
    )
    assert res.reason.dtype == np.uint8
    excluded = res.reason != Reason.VALID
    for name in ("statistic", "df", "pvalue"):
        assert np.isnan(getattr(res, name)[excluded]).all(), name
        assert np.isfinite(getattr(res, name)[~excluded]).all(), name
    # One side constant: a valid test, nu = n_other - 1 (eq. 3 with S1 = 0).
    assert_allclose(res.df[3], 6.0, rtol=1e-14)
    assert_allclose(res.statistic[3], -0.5 / np.sqrt(2.0 / 7), rtol=1e-14)
    assert Reason.DETERMINISTIC_DIFFERENCE.label == "deterministic_difference"


def test_constant_samples_are_zero_variance_not_a_valid_test():
    """Equal constant samples (0.1 is not a binary fraction) are ZERO_VARIANCE, never a p-value."""
    res = welch_ttest(np.full(7, 0.1), np.full(9, 0.1))
    assert res.reason == Reason.ZERO_VARIANCE and np.isnan(res.pvalue)
    res = welch_ttest(np.full(7, 0.1), np.full(13, 0.3))
    assert res.reason == Reason.DETERMINISTIC_DIFFERENCE and np.isnan(res.pvalue)
    res = welch_ttest(np.full(7, 0.1), np.array([0.1, 0.2, 0.3]))
    assert res.reason == Reason.VALID
    assert_allclose(res.df, 2.0, rtol=1e-14)


def test_nan_sample_never_gives_p_one():
    rng = np.random.default_rng(13)
    a = rng.normal(size=(10, 3))
    b = rng.normal(size=(10, 3))
    a[4, 1] = np.nan
    b[2, 2] = np.inf
    res = welch_ttest(a, b)
    assert_array_equal(res.reason, [Reason.VALID, Reason.NON_FINITE, Reason.NON_FINITE])
    assert np.isnan(res.pvalue[1:]).all()


def test_too_few_samples():
    res = welch_ttest(np.array([1.0]), np.array([1.0, 2.0, 3.0]))
    assert res.reason == Reason.TOO_FEW_PASSES and np.isnan(res.pvalue)
    res = welch_ttest(np.empty(0), np.array([1.0, 2.0, 3.0]))
    assert res.reason == Reason.TOO_FEW_PASSES and np.isnan(res.pvalue)


def test_negative_variance_rejected():
    msg = "variances must be >= 0, got a negative value"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        welch_from_stats(0.0, -1e-12, 5, 0.0, 1.0, 5)


def test_paired_summary_path_equals_raw_path():
    rng = np.random.default_rng(77)
    a = rng.normal(5.0, 1.0, size=(12, 4, 3))
    b = a + rng.normal(0.1, 0.2, size=a.shape)
    raw = paired_ttest(a, b, axis=0)
    d = b - a
    summary = paired_from_stats(d.mean(axis=0), d.var(axis=0, ddof=1), 12)
    for name in ("statistic", "df", "pvalue", "mean_difference", "standard_error"):
        np.testing.assert_allclose(getattr(summary, name), getattr(raw, name), rtol=1e-12)
