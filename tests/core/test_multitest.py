"""Channel combination, Holm, Benjamini-Hochberg, the uniformity test and the global test (welch_core.multitest)."""

import itertools
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import stats

from welch_core import WelchInputError, bh_qvalues, combine_channels, global_test, holm, uniformity_pvalue


def holm_brute_force(p):
    """Holm's adjusted p_(i) = max over j <= i of min(1, (m - j + 1) p_(j)), written as loops over ranks."""
    m = len(p)
    order = sorted(range(m), key=lambda i: p[i])
    out = [0.0] * m
    for rank, i in enumerate(order):
        out[i] = max(min(1.0, (m - j) * p[order[j]]) for j in range(rank + 1))
    return out


def holm_rejections(p, alpha):
    """Holm's step-down procedure itself: reject the smallest p-values while p_(k) <= alpha / (m - k)."""
    m = len(p)
    rejected = set()
    for k, i in enumerate(sorted(range(m), key=lambda i: p[i])):
        if p[i] > alpha / (m - k):
            break
        rejected.add(i)
    return rejected


def test_holm_hand_example():
    # sorted: 0.005 (x4 = 0.02), 0.01 (x3 = 0.03), 0.03 (x2 = 0.06), 0.04 (x1 = 0.04 -> monotone 0.06)
    assert_allclose(holm([0.01, 0.04, 0.03, 0.005]), [0.03, 0.06, 0.06, 0.02], rtol=1e-15)


def test_holm_against_brute_force_and_the_procedure():
    rng = np.random.default_rng(21)
    for size in (1, 2, 7, 50):
        p = np.concatenate([rng.uniform(size=size), rng.uniform(0, 1e-3, size=size // 2)])
        adjusted = holm(p)
        assert_allclose(adjusted, holm_brute_force(list(p)), rtol=1e-14)
        for alpha in (0.001, 0.01, 0.05, 0.2):
            assert set(np.flatnonzero(adjusted <= alpha)) == holm_rejections(list(p), alpha)


def test_holm_keeps_shape_and_nan():
    p = np.array([[0.01, np.nan], [0.2, 0.04]])
    out = holm(p)
    assert out.shape == (2, 2) and np.isnan(out[0, 1])
    assert_allclose(out[~np.isnan(p)], holm_brute_force([0.01, 0.2, 0.04]), rtol=1e-15)
    assert np.isnan(holm([np.nan, np.nan])).all()
    assert holm([]).shape == (0,)


def test_holm_ties():
    assert_allclose(holm([0.01, 0.01, 0.01]), [0.03, 0.03, 0.03])


def test_bh_against_scipy():
    rng = np.random.default_rng(22)
    for size in (1, 3, 40, 500):
        p = np.concatenate([rng.uniform(size=size), rng.beta(0.2, 5, size=size // 3)])
        assert_allclose(bh_qvalues(p), stats.false_discovery_control(p, method="bh"), rtol=1e-14)


def test_bh_with_nan_and_shape():
    rng = np.random.default_rng(23)
    p = rng.uniform(size=(6, 5))
    p[2, 3] = np.nan
    q = bh_qvalues(p)
    assert q.shape == p.shape and np.isnan(q[2, 3])
    finite = ~np.isnan(p)
    assert_allclose(q[finite], stats.false_discovery_control(p[finite], method="bh"), rtol=1e-14)


def test_bh_never_above_holm():
    rng = np.random.default_rng(24)
    p = rng.beta(0.5, 2.0, size=200)
    assert (bh_qvalues(p) <= holm(p) + 1e-15).all()


def test_combine_channels():
    p = np.array(
        [
            [0.2, 0.01, np.nan],  # two channels: 2 * 0.01
            [0.5, 0.6, 0.7],  # 3 * 0.5 capped at 1
            [np.nan, np.nan, np.nan],  # no channel: NaN
            [0.001, 0.3, 0.002],  # 3 * 0.001
        ]
    )
    assert_allclose(combine_channels(p), [0.02, 1.0, np.nan, 0.003], rtol=1e-15)
    assert combine_channels(np.ones((4, 5, 3))).shape == (4, 5)


def test_combine_channels_is_valid_for_perfectly_correlated_channels():
    """The same p in all three channels (fully correlated): k * min p stays super-uniform."""
    rng = np.random.default_rng(25)
    u = rng.uniform(size=20000)
    combined = combine_channels(np.repeat(u[:, None], 3, axis=1))
    for a in (0.01, 0.05, 0.2):
        assert (combined <= a).mean() <= a


def test_uniformity_pvalue():
    rng = np.random.default_rng(26)
    u = rng.uniform(size=2000)
    assert uniformity_pvalue(u) > 0.05
    assert uniformity_pvalue(u**2) < 1e-10  # too many small p-values
    assert uniformity_pvalue(np.sqrt(u)) > 0.5  # super-uniform (conservative) p-values are not evidence
    # a small excess of tiny p-values among many uniform ones (the [0, 1/30] bin of the paper's Fig. 10)
    assert uniformity_pvalue(np.concatenate([u, rng.uniform(0, 1 / 30, size=150)])) < 1e-3
    assert np.isnan(uniformity_pvalue([np.nan, np.nan]))
    assert np.isnan(uniformity_pvalue([]))
    assert uniformity_pvalue(np.concatenate([u, [np.nan] * 10])) == uniformity_pvalue(u)


def test_uniformity_pvalue_is_the_one_sided_ks_test():
    rng = np.random.default_rng(27)
    p = rng.beta(0.9, 1.0, size=300)
    assert uniformity_pvalue(p) == stats.kstest(p, "uniform", alternative="greater").pvalue


@pytest.mark.parametrize(
    ("p", "expected"),
    [([2e-23], 2e-23), ([1e-5, 2e-5], 4e-10), ([1e-200, 3e-200, 0.4], None)],
)
def test_uniformity_pvalue_of_few_tiny_p_values_keeps_its_precision(p, expected):
    """With n(1 - D+) < 1 the one-sided KS p-value is (1 - D+)^n exactly; 1 - D+ must not be formed by
    cancellation (a whole-image tile's p of 2e-23 gave 0, shown as '< 1e-300'). The oracle: mpmath at 50 digits of
    the same closed form."""
    import mpmath

    mpmath.mp.dps = 50
    ordered = sorted(p)
    n = len(ordered)
    d = max(mpmath.mpf(i + 1) / n - mpmath.mpf(q) for i, q in enumerate(ordered))
    oracle = (1 - d) ** n if d > 1 - mpmath.mpf(1) / n else None
    got = uniformity_pvalue(p)
    if oracle is not None:
        assert got == pytest.approx(float(oracle), rel=1e-12)
    if expected is not None:
        assert got == pytest.approx(expected, rel=1e-12)
    assert got > 0


def test_global_test_components():
    rng = np.random.default_rng(28)
    p = rng.uniform(size=(8, 12))
    p[3, 4] = 1e-7
    g = global_test(p, alpha=0.05)
    assert_allclose(g.adjusted, holm(p), rtol=1e-15)
    assert_allclose(g.qvalues, bh_qvalues(p), rtol=1e-15)
    assert g.holm_pvalue == pytest.approx(96 * 1e-7)
    assert g.uniformity_pvalue == uniformity_pvalue(p)
    assert g.pvalue == min(1.0, 2 * min(g.holm_pvalue, g.uniformity_pvalue))
    assert g.rejected and g.alpha == 0.05


def test_global_test_all_nan():
    g = global_test(np.full((4, 4), np.nan))
    assert np.isnan(g.pvalue) and np.isnan(g.holm_pvalue) and np.isnan(g.uniformity_pvalue)
    assert not g.rejected
    assert np.isnan(g.adjusted).all() and g.adjusted.shape == (4, 4)


def test_global_test_calibrated_on_uniform_pvalues():
    """2000 families of 60 independent uniform p-values: rejections at alpha = 0.01 within binomial error."""
    rng = np.random.default_rng(29)
    rejected = sum(global_test(rng.uniform(size=60), alpha=0.01).rejected for _ in range(2000))
    assert rejected <= stats.binom.ppf(0.999, 2000, 0.01)


@pytest.mark.parametrize("alpha", [0, 1, -0.1, 1.5, "0.01", True, None])
def test_global_test_bad_alpha(alpha):
    with pytest.raises(WelchInputError, match=re.escape(f"`alpha` must be a number in (0, 1), got {alpha!r}")):
        global_test([0.5, 0.2], alpha=alpha)


@pytest.mark.parametrize("bad", [-0.1, 1.5])
def test_global_test_pvalues_out_of_range(bad):
    with pytest.raises(WelchInputError, match=re.escape("`tile_pvalues` must lie in [0, 1]")):
        global_test([0.5, bad])


def test_holm_matches_every_subset_order():
    """Holm is invariant to the order of its input."""
    p = np.array([0.04, 0.001, 0.3, 0.02])
    base = holm(p)
    for perm in itertools.permutations(range(4)):
        assert_array_equal(holm(p[list(perm)]), base[list(perm)])
