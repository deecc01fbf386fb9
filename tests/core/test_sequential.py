"""Group-sequential boundaries by Lan-DeMets O'Brien-Fleming spending (welch_core.sequential).

Independent oracles: the multivariate normal CDF of (Z_1, ..., Z_k) for up to four looks, a Monte Carlo of
Brownian paths, the textbook recursion on a fine uniform grid, and the spending function's closed form.
"""

import math
import re
import time

import mpmath
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import optimize, special, stats

from welch_core import sequential
from welch_core.errors import WelchInputError
from welch_core.sequential import boundaries, nominal_levels, obrien_fleming_spending


def increments(fractions, alpha):
    """alpha(t_k) - alpha(t_{k-1}) of the spending function, fractions clipped to 1."""
    spent = obrien_fleming_spending(np.minimum(fractions, 1.0), alpha)
    return np.diff(np.concatenate(([0.0], spent)))


def exits_by_multivariate_normal(fractions, c, rng, relative_error=1e-7, clip=True):
    """P(|Z_1| < c_1, ..., |Z_{k-1}| < c_{k-1}, |Z_k| >= c_k) from the joint normal with corr sqrt(t_i / t_j).

    By symmetry it is twice the probability of the box (-c_1, c_1) x ... x [c_k, inf). scipy integrates that box
    directly (`lower_limit`); the 2^k-corner inclusion/exclusion of plain CDFs would cancel to nothing at levels
    of 1e-6. The QMC error tolerance is absolute, so it is set from the size of the probability.
    """
    t = np.asarray(fractions, dtype=float)
    t = np.minimum(t, 1.0) if clip else t
    cov = np.sqrt(np.minimum.outer(t, t) / np.maximum.outer(t, t))
    exits = [2.0 * stats.norm.sf(c[0])]
    for k in range(1, t.size):
        scale = 2.0 * stats.norm.sf(c[k])  # an upper bound on the exit probability
        mvn = stats.multivariate_normal(
            np.zeros(k + 1), cov[: k + 1, : k + 1], abseps=relative_error * scale, releps=0.0, seed=rng
        )
        upper = np.append(c[:k], np.inf)
        lower = np.append(-c[:k], c[k])
        exits.append(2.0 * mvn.cdf(upper, lower_limit=lower))
    return np.array(exits)


def boundaries_textbook(fractions, alpha, step=0.01):
    """The recursion as Jennison and Turnbull write it: the density of Z_k on the continuation region, Simpson's
    rule on a uniform grid over (-c_k, c_k), brentq on the exit probability. Plain floats: moderate alpha only."""
    t = np.minimum(np.asarray(fractions, dtype=float), 1.0)
    inc = increments(t, alpha)
    c = np.empty(t.size)
    c[0] = stats.norm.isf(inc[0] / 2.0)

    def grid(top):
        n = 2 * math.ceil(top / step)
        z = np.linspace(-top, top, n + 1)
        w = np.where(np.arange(n + 1) % 2 == 1, 4.0, 2.0)
        w[0] = w[-1] = 1.0
        return z, w * (z[1] - z[0]) / 3.0

    z, w = grid(c[0])
    density = np.exp(-0.5 * z**2) / math.sqrt(2.0 * math.pi)
    for k in range(1, t.size):
        root_before, root_now, root_delta = math.sqrt(t[k - 1]), math.sqrt(t[k]), math.sqrt(t[k] - t[k - 1])
        weighted = w * density

        def excess(ck, z=z, weighted=weighted, target=inc[k], a=root_before, b=root_now, d=root_delta):
            up = special.ndtr((z * a - ck * b) / d)
            down = special.ndtr((-z * a - ck * b) / d)
            return np.sum(weighted * (up + down)) - target

        c[k] = optimize.brentq(excess, 0.1, 40.0, xtol=1e-13)
        new_z, new_w = grid(c[k])
        x = (new_z[:, None] * root_now - z[None, :] * root_before) / root_delta
        density = (root_now / root_delta / math.sqrt(2.0 * math.pi)) * (np.exp(-0.5 * x * x) @ weighted)
        z, w = new_z, new_w
    return c


# -- the spending function ---------------------------------------------------------------------------------------


def test_spending_function_values():
    alpha = 0.05
    z = stats.norm.isf(alpha / 2.0)
    t = np.array([0.0, 0.01, 0.2, 0.5, 0.999, 1.0, 1.5])
    spent = obrien_fleming_spending(t, alpha)
    assert_allclose(spent[1:-2], 2.0 - 2.0 * stats.norm.cdf(z / np.sqrt(t[1:-2])), rtol=0.0, atol=1e-15)
    # 2 - 2 Phi(x) = erfc(x / sqrt 2), the form without cancellation
    expected = np.concatenate(([0.0], special.erfc(z / np.sqrt(2.0 * t[1:-2])), [alpha, alpha]))
    assert_allclose(spent, expected, rtol=1e-13, atol=0.0)
    assert spent[-2] == alpha and spent[-1] == alpha  # exactly alpha at and after the end
    assert np.all(np.diff(spent) >= 0.0)


def test_spending_function_keeps_precision_far_out():
    # 2 - 2 Phi(x) would be 0 here; 2 Phi(-x) is what the spending is, to full relative precision
    t, alpha = np.array([0.03, 0.1, 0.5]), 1e-10
    x = stats.norm.isf(alpha / 2.0) / np.sqrt(t)  # 37.3, 20.5, 9.1
    spent = obrien_fleming_spending(t, alpha)
    assert_allclose(spent, [float(mpmath.erfc(v / mpmath.sqrt(2))) for v in x], rtol=1e-12)
    assert np.all(spent > 0.0) and np.all(2.0 - 2.0 * stats.norm.cdf(x) == 0.0)
    assert obrien_fleming_spending(0.01, alpha) == 0.0  # erfc(64.7 / sqrt 2) is below the smallest double


def test_spending_function_broadcasts():
    t = np.linspace(0.1, 1.0, 4)[:, None]
    alpha = np.array([0.1, 0.01, 1e-5])
    spent = obrien_fleming_spending(t, alpha)
    assert spent.shape == (4, 3)
    for j, a in enumerate(alpha):
        assert_array_equal(spent[:, j], obrien_fleming_spending(t[:, 0], a))


@pytest.mark.parametrize(
    ("t", "alpha", "message"),
    [
        ([-0.1, 0.5], 0.05, "`t` must be >= 0, got [-0.1, 0.5]"),
        ([np.nan], 0.05, "`t` must be >= 0, got [nan]"),
        (0.5, [0.05, 1.0], "`alpha` must lie in (0, 1), got [0.05, 1.0]"),
        (0.5, 0.0, "`alpha` must lie in (0, 1), got 0.0"),
        ("half", 0.05, "`t` must be numbers, got 'half'"),
    ],
)
def test_spending_function_rejects_bad_input(t, alpha, message):
    with pytest.raises(WelchInputError, match=f"^{re.escape(message)}$"):
        obrien_fleming_spending(t, alpha)


# -- published and closed-form values ----------------------------------------------------------------------------


def test_one_look_is_the_fixed_sample_test():
    alphas = np.array([0.2, 0.05, 1e-3, 1e-6, 1e-10])
    assert_array_equal(boundaries([1.0], alphas)[0], stats.norm.isf(alphas / 2.0))
    assert_array_equal(boundaries([2.5], alphas)[0], stats.norm.isf(alphas / 2.0))  # clipped to 1
    # a single look before the end spends only alpha(t)
    assert_allclose(boundaries([0.5], alphas)[0], stats.norm.isf(alphas / 2.0) / math.sqrt(0.5), rtol=1e-14)


def test_five_equal_looks():
    # The first look spends 2 Phi(-z_{0.975} / sqrt(0.2)), so c_1 = 1.959964 / sqrt(0.2) = 4.382613 exactly. The
    # rest are the textbook recursion on a grid of step 0.002 (which this module matches to 1.2e-7); the exit
    # probabilities of this module's boundaries match the 5-variate normal CDF to 4e-7 relative.
    #
    # The often quoted Lan-DeMets O'Brien-Fleming values 4.8769, 3.3569, 2.6803, 2.2898, 2.0310 are for another
    # spending: one-sided alpha = 0.025, i.e. each side of a symmetric test spends 2 - 2 Phi(z_{1-0.0125} /
    # sqrt(t)), which is not 2 - 2 Phi(z_{0.975} / sqrt(t)) split in two. Those values are reproduced below.
    c = boundaries(np.arange(1, 6) / 5.0, [0.05])[:, 0]
    assert c[0] == pytest.approx(stats.norm.isf(0.025) / math.sqrt(0.2), rel=1e-14)
    assert_allclose(c, [4.3826127, 3.0997275, 2.5533550, 2.2538479, 2.0635011], atol=1e-6)


def test_published_one_sided_values():
    # Feed the per-side spending of a one-sided alpha = 0.025 design (both sides together spend twice that) to
    # the same recursion. It gives 4.876885, 3.357012, 2.680280, 2.289817, 2.031032: the published four decimals
    # except 3.3569 for c_2, where a 30-digit mpmath quadrature of the two-look exit probability gives
    # c_2 = 3.3570119216 (the published value is 1e-4 low, probably from a coarser grid).
    t = np.arange(1, 6) / 5.0
    spent = 4.0 * special.ndtr(-stats.norm.isf(0.0125) / np.sqrt(t))
    spent[-1] = 0.05
    c = sequential._compute(t, np.log(spent)[:, None], spent[:1])[:, 0]
    assert_allclose(c, [4.8769, 3.3569, 2.6803, 2.2898, 2.0310], atol=1.3e-4)
    assert c[1] == pytest.approx(3.3570119216, abs=1e-7)


# -- independent oracles ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fractions", "alphas"),
    [
        ([0.3, 1.0], [0.2, 0.05, 1e-3, 1e-6]),
        ([0.25, 0.5, 1.0], [0.2, 0.05, 1e-3, 1e-6]),
        ([0.2, 0.45, 0.7, 1.0], [0.2, 0.05]),
        ([0.1, 0.11, 0.6, 1.4], [0.05, 1e-6]),  # two looks close together, and a last look past the end
    ],
)
def test_exit_probabilities_match_multivariate_normal(fractions, alphas):
    rng = np.random.default_rng(20240611)
    c = boundaries(fractions, alphas)
    for j, alpha in enumerate(alphas):
        expected = increments(fractions, alpha)
        exits = exits_by_multivariate_normal(fractions, c[:, j], rng)
        # The first look is exact (a normal tail). Later increments below 1e-12 are skipped: the QMC error of
        # the CDF is absolute, and reaching 1e-6 relative there takes too long; the convergence test below
        # covers them.
        checked = (np.arange(len(fractions)) == 0) | (expected > 1e-12)
        assert checked[-1]
        assert_allclose(exits[checked], expected[checked], rtol=1e-6, atol=0, err_msg=f"alpha = {alpha}")


def reserve_spending(t, alpha, reserve):
    """The spending with a reserve, written out: (1 - r) alpha ln(1 + (e - 1) t) up to t = 1, alpha (1 - r / t)
    beyond (Pocock's shape)."""
    t = np.asarray(t, dtype=float)
    inside = (1 - reserve) * alpha * np.log(1 + (math.e - 1) * np.minimum(t, 1.0))
    return np.where(t <= 1.0, inside, alpha * (1 - reserve / np.maximum(t, 1.0)))


@pytest.mark.parametrize(
    ("fractions", "alphas"),
    [
        ([0.25, 0.5, 1.0, 1.5, 3.0], [0.05, 1e-4]),  # a grown budget: looks past the planned last one
        ([0.4, 1.0], [0.05]),  # the planned last look keeps the reserve
        ([1.2, 2.0], [0.05]),  # the first look already past the end
    ],
)
def test_a_reserve_is_kept_at_the_end_and_spent_past_it(fractions, alphas):
    rng = np.random.default_rng(20261202)
    c = boundaries(fractions, alphas, "pocock", reserve=0.1)
    for j, alpha in enumerate(alphas):
        spent = reserve_spending(fractions, alpha, 0.1)
        expected = np.diff(np.concatenate(([0.0], spent)))
        exits = exits_by_multivariate_normal(fractions, c[:, j], rng, clip=False)
        assert_allclose(exits, expected, rtol=1e-5, atol=0, err_msg=f"alpha = {alpha}")
        assert exits.sum() < alpha  # never all of it, however far the looks go
    # The boundaries of the looks up to the planned end don't depend on the looks after it.
    assert_array_equal(boundaries(fractions[:2], alphas, "pocock", reserve=0.1), c[:2])


def test_no_reserve_is_the_plain_spending():
    t = [0.2, 0.5, 1.0]
    assert_array_equal(boundaries(t, [0.05], "pocock", reserve=0.0), boundaries(t, [0.05], "pocock"))
    # With a reserve the last planned look spends 0.9 alpha: its boundary is the plain one of 0.9 alpha.
    assert_allclose(boundaries(t, [0.05], "pocock", reserve=0.1), boundaries(t, [0.045], "pocock"), rtol=1e-9)


@pytest.mark.parametrize("reserve", [-0.1, 1.0, np.nan])
def test_a_reserve_outside_0_1_is_refused(reserve):
    with pytest.raises(WelchInputError, match=rf"^`reserve` must lie in \[0, 1\), got {reserve!r}$"):
        boundaries([0.5, 1.0], [0.05], reserve=reserve)


def test_monte_carlo_crossing_rates():
    rng = np.random.default_rng(7)
    t = np.array([0.04, 0.1, 0.17, 0.3, 0.38, 0.5, 0.66, 0.8, 0.93, 1.0])
    alpha, n = 0.05, 400_000
    c = boundaries(t, [alpha])[:, 0]
    steps = rng.standard_normal((n, t.size)) * np.sqrt(np.diff(t, prepend=0.0))
    z = np.cumsum(steps, axis=1) / np.sqrt(t)
    crossed = np.abs(z) >= c
    first = np.where(crossed.any(axis=1), crossed.argmax(axis=1), -1)
    counts = np.bincount(first[first >= 0], minlength=t.size)
    rate = counts.sum() / n
    assert abs(rate - alpha) < 3.0 * math.sqrt(alpha * (1.0 - alpha) / n), rate
    expected = increments(t, alpha) * n
    assert np.all(np.abs(counts - expected) < 4.0 * np.sqrt(expected)), (counts, expected)
    # all looks together: Pearson's chi-square of the crossing counts and the paths that never crossed
    observed = np.append(counts, n - counts.sum())
    assert stats.chisquare(observed, np.append(expected, n - expected.sum())).pvalue > 0.001


@pytest.mark.parametrize(
    ("fractions", "alpha"),
    [
        (np.arange(1, 61) / 60.0, 0.05),
        ([0.03, 0.07, 0.15, 0.22, 0.35, 0.5, 0.61, 0.77, 0.9, 1.2], 1e-3),
    ],
)
def test_textbook_recursion_on_a_fine_grid(fractions, alpha):
    assert_allclose(boundaries(fractions, [alpha])[:, 0], boundaries_textbook(fractions, alpha), atol=1e-6, rtol=0)


def test_discretisation_converges(monkeypatch):
    # No independent oracle reaches levels of 1e-10 with 1e-6 accuracy; a grid twice as fine everywhere shows
    # that the discretisation error is below that (it falls as the fourth power of the spacing).
    t = np.array([0.02, 0.05, 0.13, 0.2, 0.41, 0.42, 0.7, 0.9300001, 0.93001, 1.3])
    alphas = [0.2, 1e-3, 1e-8, 1e-10]
    c = boundaries(t, alphas)
    for name in ("_NODES_PER_SD", "_EXIT_NODES_PER_SD"):
        monkeypatch.setattr(sequential, name, 2.0 * getattr(sequential, name))
    monkeypatch.setattr(sequential, "_H_MAX", sequential._H_MAX / 2.0)
    fine = boundaries(t, alphas)
    assert_array_equal(np.isfinite(c), np.isfinite(fine))
    finite = np.isfinite(c)
    assert_allclose(c[finite], fine[finite], atol=1e-6, rtol=0)


# -- shapes of the boundaries ------------------------------------------------------------------------------------


def test_irregular_fractions_and_a_last_look_past_the_end():
    t = [0.07, 0.19, 0.2, 0.55, 0.81, 1.35]
    alphas = [0.1, 0.01]
    c = boundaries(t, alphas)
    assert_array_equal(c, boundaries([0.07, 0.19, 0.2, 0.55, 0.81, 1.0], alphas))
    assert np.all(np.diff(c, axis=0) < 0.0)
    # O'Brien-Fleming shape: on the Brownian-motion scale the boundary c sqrt(t) barely moves, and it never
    # drops below the fixed-sample critical value
    z = stats.norm.isf(np.array(alphas) / 2.0)
    scaled = c * np.sqrt(np.minimum(t, 1.0))[:, None]
    assert np.all(scaled > z - 1e-9) and np.all(scaled < 1.1 * z)
    # the last look spends all that is left, alpha - alpha(0.81), as in the textbook recursion
    assert_allclose(c[:, 0], boundaries_textbook(t, alphas[0]), atol=1e-6, rtol=0)


def test_tiny_alphas_many_looks():
    t = np.arange(1, 61) / 60.0
    alphas = np.array([1e-8, 1e-10])
    c = boundaries(t, alphas)
    z = stats.norm.isf(alphas / 2.0)
    for j in range(alphas.size):
        finite = np.isfinite(c[:, j])
        first = int(finite.argmax())
        # inf while the spending is so small that c would pass 40, then finite and decreasing to the end
        assert np.all(finite[first:]) and not np.any(finite[:first])
        assert first >= 1, "a first look at t = 1/60 spends below 2 Phi(-40)"
        assert c[first, j] <= 40.0
        assert stats.norm.isf(increments(t, alphas[j])[first - 1] / 2.0) > 40.0
        assert np.all(np.diff(c[first:, j]) < 0.0)
        assert z[j] < c[-1, j] < 1.02 * z[j]
        scaled = c[first:, j] * np.sqrt(t[first:])
        assert np.all(scaled > z[j] - 1e-9) and np.all(scaled < 1.1 * z[j])
    assert np.all(nominal_levels(c[-1]) < alphas) and np.all(nominal_levels(c[-1]) > 0.5 * alphas)


def test_inf_where_nothing_is_spent():
    # 2 Phi(-z_{1-alpha/2} / sqrt(t)) underflows far below the smallest double at t = 1e-6: c is inf, and the
    # next look is computed as if that look had not happened
    alphas = [0.05, 1e-10]
    c = boundaries([1e-6, 0.5, 1.0], alphas)
    assert np.all(np.isinf(c[0]))
    assert_allclose(c[1:], boundaries([0.5, 1.0], alphas), atol=1e-7, rtol=0)
    # a boundary of 41 would be needed: inf too; one of 39 is kept
    t_41 = (stats.norm.isf(0.025) / 41.0) ** 2
    t_39 = (stats.norm.isf(0.025) / 39.0) ** 2
    c = boundaries([t_41, t_39, 1.0], [0.05])[:, 0]
    assert c[0] == np.inf and c[1] == pytest.approx(39.0, abs=1e-6) and np.isfinite(c[2])


def test_looks_close_together():
    t = np.array([0.2, 0.5, 0.5 + 1e-9, 0.9999999, 1.0])
    c = boundaries(t, [0.05, 1e-10])
    assert np.all(np.isfinite(c))
    # almost no information between the looks: almost the same boundary, a hair higher on the W scale
    scaled = c * np.sqrt(t)[:, None]
    assert np.all(scaled[2] >= scaled[1]) and np.all(scaled[2] - scaled[1] < 1e-3)
    assert np.all(scaled[4] >= scaled[3]) and np.all(scaled[4] - scaled[3] < 1e-3)


def test_a_wrong_first_guess_of_the_grid_is_corrected(monkeypatch):
    # The fine part of each grid is placed from a guess at the next boundary; force a guess that is far too high
    # (the loosest upper bound) and the recursion must notice and refine, ending at the same boundaries.
    t = np.array([0.1, 0.3, 0.30001, 0.6, 0.9999999, 1.0])
    alphas = [0.05, 1e-10]
    c = boundaries(t, alphas)
    monkeypatch.setattr(sequential._Schedule, "first_anchor", lambda self, k, a, c_before: min(self.high[k, a], 40.0))
    assert_allclose(boundaries(t, alphas), c, atol=2e-7, rtol=0)


def test_vectorised_alphas_equal_single_calls_and_results_are_deterministic():
    t = [0.05, 0.13, 0.2, 0.41, 0.42, 0.7, 0.93, 1.3]
    alphas = [0.2, 0.05, 1e-3, 1e-6, 1e-8, 1e-10]
    c = boundaries(t, alphas)
    assert c.shape == (8, 6)
    for j, alpha in enumerate(alphas):
        assert_array_equal(c[:, j], boundaries(t, [alpha])[:, 0])
    assert_array_equal(boundaries(t, alphas[::-1])[:, ::-1], c)
    assert_array_equal(boundaries(t, alphas), c)
    # a look's boundary doesn't depend on later looks: recomputing at every look gives the same history
    for k in range(1, len(t)):
        assert_array_equal(boundaries(t[:k], alphas), c[:k])


def test_thirty_looks_four_alphas_timing():
    t = np.arange(1, 31) / 30.0
    alphas = [0.05, 0.01, 1e-4, 1e-8]
    start = time.perf_counter()
    c = boundaries(t, alphas)
    elapsed = time.perf_counter() - start
    assert np.all(np.isfinite(c[-1])), f"30 looks x 4 alphas took {elapsed:.3f} s"
    assert np.all(np.diff(c[1:], axis=0) < 0.0), f"30 looks x 4 alphas took {elapsed:.3f} s"


# -- bad input ----------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fractions", "alphas", "message"),
    [
        ([0.5, 0.3], [0.05], "`fractions` must be strictly increasing and positive, got [0.5, 0.3]"),
        ([0.5, 0.5, 1.0], [0.05], "`fractions` must be strictly increasing and positive, got [0.5, 0.5, 1.0]"),
        ([0.0, 0.5], [0.05], "`fractions` must be strictly increasing and positive, got [0.0, 0.5]"),
        ([-0.2, 0.5], [0.05], "`fractions` must be strictly increasing and positive, got [-0.2, 0.5]"),
        ([0.2, np.nan], [0.05], "`fractions` must be strictly increasing and positive, got [0.2, nan]"),
        ([0.5, 1.0, 1.2], [0.05], "`fractions` may be >= 1 only at the last look, got [0.5, 1.0, 1.2]"),
        ([0.5, 1.0], [0.0], "`alphas` must lie in (0, 1), got [0.0]"),
        ([0.5, 1.0], [0.05, 1.0], "`alphas` must lie in (0, 1), got [0.05, 1.0]"),
        ([0.5, 1.0], [np.nan], "`alphas` must lie in (0, 1), got [nan]"),
        ([], [0.05], "`fractions` must not be empty, got []"),
        ([0.5, 1.0], [], "`alphas` must not be empty, got []"),
        ([[0.5, 1.0]], [0.05], "`fractions` must be a 1-D sequence, got shape (1, 2)"),
        (0.5, [0.05], "`fractions` must be a 1-D sequence, got shape ()"),
        ([0.5, 1.0], 0.05, "`alphas` must be a 1-D sequence, got shape ()"),
        ([0.5, 1.0], [[0.05]], "`alphas` must be a 1-D sequence, got shape (1, 1)"),
        (["a", "b"], [0.05], "`fractions` must be numbers, got ['a', 'b']"),
    ],
)
def test_bad_input(fractions, alphas, message):
    with pytest.raises(WelchInputError, match=f"^{re.escape(message)}$"):
        boundaries(fractions, alphas)


def test_long_bad_input_is_summarised_on_one_line():
    with pytest.raises(WelchInputError) as info:
        boundaries(np.linspace(1.0, 0.01, 100), [0.05])
    assert "\n" not in str(info.value) and "..." in str(info.value)


# -- nominal levels -----------------------------------------------------------------------------------------------


def test_nominal_levels():
    c = np.array([[0.0, 0.5, 1.0, 1.96], [3.0, 5.0, 8.0, 12.0]])
    assert_allclose(nominal_levels(c), 2.0 * stats.norm.sf(c), rtol=1e-13)
    assert nominal_levels(np.inf) == 0.0
    assert_array_equal(nominal_levels([np.inf, 0.0]), [0.0, 1.0])
    assert nominal_levels(boundaries([1.0], [0.05]))[0, 0] == pytest.approx(0.05, rel=1e-14)


def test_nominal_levels_far_out():
    # 1 - Phi(c) by subtraction is 0 from c = 8.3 on; the levels keep full relative precision down to the
    # smallest normal double (c = 37.5), then lose digits gracefully as subnormals, and are 0 only below the
    # smallest subnormal (c = 38.5), where a double can't hold them
    c = np.array([10.0, 20.0, 30.0, 37.0, 37.4, 37.6, 38.0])
    expected = [float(mpmath.erfc(x / mpmath.sqrt(2))) for x in c]
    assert_allclose(nominal_levels(c[:5]), expected[:5], rtol=1e-12)
    assert_allclose(nominal_levels(c[5:]), expected[5:], rtol=1e-6)
    assert np.all(2.0 * (1.0 - stats.norm.cdf(c)) == 0.0)
    assert nominal_levels(38.5) > 0.0 and nominal_levels(40.0) == 0.0
