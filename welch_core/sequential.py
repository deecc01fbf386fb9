"""Group-sequential boundaries: look at the data after every chunk of passes and still keep the level alpha.

A bias test that looks at its data after every chunk of render passes and stops at the first significant look
tests many times; rejecting whenever p < alpha at any look would inflate the false-positive rate far above alpha
(to 1 with enough looks, by the law of the iterated logarithm). Group-sequential boundaries fix that: at look k,
with information fraction t_k (passes so far / planned maximum passes), a hypothesis is rejected when
|Z_k| >= c_k, and the c_k are chosen so that under H0 the chance of ever crossing is alpha.

Method
------
Lan and DeMets (1983) alpha spending: a spending function alpha(t), increasing from 0 at t = 0 to alpha at t = 1,
says how much of the level may be used up by information fraction t; c_k is the boundary whose crossing at look
k (and at no earlier look) has probability alpha(t_k) - alpha(t_{k-1}) under H0. The looks need not be planned in
advance, only the maximum information. Here alpha(t) has the O'Brien-Fleming shape
``alpha(t) = 2 - 2 Phi(z_{1-alpha/2} / sqrt(t))``: almost nothing is spent early, so an early stop needs
overwhelming evidence (c_1 = 4.38 for 5 equally spaced looks at alpha = 0.05) and the final look keeps nearly the
full alpha (c_5 = 2.06 against 1.96 for a single test). A user who always renders the full number of passes
therefore loses almost no power compared with the fixed-sample test, and a grossly biased renderer is still
caught after a few chunks. A fraction t >= 1 is the final look and spends whatever is left.

The crossing probabilities are computed by numerical integration, the recursion of Armitage, McPherson and Rowe
(1969) in the form of Jennison and Turnbull (2000), chapter 19: the sub-density of Z_k on the paths that have not
crossed before look k is carried from look to look by integrating against the Gaussian transition kernel over the
continuation region, and each c_k is solved with a root finder (brentq) on the exit probability. Three changes
keep the result accurate to better than 1e-6 in c for levels from 0.2 down to 1e-10 and for many looks:

* The sub-density is stored as h_k(z) = phi(z) q_k(z), where q_k(z) = P(no crossing before look k | Z_k = z) lies
  in [0, 1]. The Gaussian factor, which spans hundreds of orders of magnitude at the boundaries of tiny levels, is
  kept analytically and exit probabilities are summed in log space with log_ndtr, so nothing cancels or
  underflows. By Bayes' rule q_k is q_{k-1} integrated against the backward kernel Z_{k-1} | Z_k = z ~
  N(rho z, 1 - rho^2), rho = sqrt(t_{k-1} / t_k).
* q is integrated against that kernel exactly on a piecewise-quadratic interpolant (product integration), so a
  kernel narrower than the grid spacing, as for two looks close together, is no problem.
* Instead of Jennison and Turnbull's fixed pattern of 6r - 1 points the grid is graded to the problem: fine (a
  fraction of the kernel width) where q varies, around the images of earlier truncation points, and where the
  next look's exit probability has its mass; coarser with distance from those places. The exit mass sits just
  inside the boundary for moderate levels but well inside it for tiny ones, so its place is guessed from the
  previous boundary, checked once c is known, and the grid refined if the guess was wrong. The grid ends at the
  boundary, or at |z| = 42 where there is none.

Where a look spends nothing, or so little that c would exceed 40 (2 Phi(-40) ~ 1e-349), c is +inf: no rejection is
possible at that look, and the unspent crumb is simply not used (conservative).

The computation is deterministic and a look's boundary depends only on the fractions up to it, bit for bit: a
resumed run that recomputes the boundaries from its stored fractions gets the ones it used before, and each alpha
gets the same boundaries alone as in any batch.

Requirement on the statistic
----------------------------
The boundaries assume that Z_k is (approximately) standard normal under H0 with the covariance of a Brownian
motion sampled at the information fractions, corr(Z_i, Z_j) = sqrt(t_i / t_j): Z_k must summarise all the data
seen so far, and the data added between looks must be independent of the earlier data (independent increments).
A Welch or paired t statistic is not a z; the caller maps it to z through its exact p-value,
z = Phi^{-1}(1 - p / 2), and compares that z with c_k (equivalently, compares p with `nominal_levels(c)[k]`).
The same c_k give repeated confidence intervals, estimate +- c_k * SE, that cover the true value at all looks
simultaneously with probability 1 - alpha.

References
----------
K. K. G. Lan and D. L. DeMets, "Discrete sequential boundaries for clinical trials", Biometrika 70(3):659-663, 1983.
C. Jennison and B. W. Turnbull, "Group Sequential Methods with Applications to Clinical Trials", Chapman &
Hall/CRC, 2000, chapter 19 (numerical computations for group sequential tests).
P. Armitage, C. K. McPherson and B. C. Rowe, "Repeated significance tests on accumulating data", J. R. Stat. Soc.
A 132(2):235-244, 1969.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy import optimize, special

from .errors import WelchInputError

__all__ = ["SPENDING", "boundaries", "nominal_levels", "obrien_fleming_spending", "pocock_spending"]

#: Boundaries above this are returned as inf: 2 Phi(-40) ~ 1e-349 is below the smallest double.
_C_MAX = 40.0

# The grid of a look ends at its boundary, or here where the boundary is infinite (or larger): P(|Z| > 42) ~ 1e-385
# is negligible beside any exit probability that gets a finite boundary (c <= _C_MAX). A cut placed by the later
# looks' increments would be cheaper for moderate levels but would make a boundary depend on later fractions.
_Z_MAX = _C_MAX + 2.0
# Grid nodes per standard deviation of a feature of q (a truncation step smoothed by the kernel) and of the exit
# kernel, the growth of the node spacing with distance from such a feature, the largest spacing, and how many
# exit-kernel standard deviations below the exit mass are still resolved. Chosen by convergence tests: against a
# grid four times finer (and wider margins) no boundary moved by more than 2e-7 for levels 0.2 to 1e-10 with up to
# 60 equal or irregular looks or looks 1e-7 apart, 5e-7 for 40 random looks; the error falls as the fourth power
# of the spacing (the exit spacing dominates).
_NODES_PER_SD = 6.0
_EXIT_NODES_PER_SD = 10.0
_GRADING = 0.5
_H_MAX = 0.25
_EXIT_SDS = 10.0
# Kernel mass beyond this many standard deviations (~1e-23) is left out of the product integration.
_WINDOW_SDS = 10.0
# Safety net: no grid has more panels than this. Reached only if the guess for the exit mass fails for two looks
# a hair apart (1e-9), and then accuracy degrades gracefully instead of the run time exploding.
_MAX_PANELS = 6000
_LOG2 = math.log(2.0)
# 0, then 1e-3 to 1e13 in steps of a factor 1.25: where the spacing around a feature is sampled (`_panel_ends`)
_GEOMETRIC = np.concatenate(([0.0], 1e-3 * 1.25 ** np.arange(166)))
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


# -- input checks -----------------------------------------------------------------------------------------------


def _show(values: npt.ArrayLike) -> str:
    """The bad input on one line: as a Python list when short, summarised when long."""
    arr = np.asarray(values)
    if arr.size <= 12:
        return repr(arr.tolist())
    return np.array2string(arr, separator=", ", threshold=12, edgeitems=3, max_line_width=10**9)


def _as_float_array(name: str, values: npt.ArrayLike) -> np.ndarray:
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise WelchInputError(f"`{name}` must be numbers, got {values!r}") from None


def _as_vector(name: str, values: npt.ArrayLike) -> np.ndarray:
    arr = _as_float_array(name, values)
    if arr.ndim != 1:
        raise WelchInputError(f"`{name}` must be a 1-D sequence, got shape {arr.shape}")
    if arr.size == 0:
        raise WelchInputError(f"`{name}` must not be empty, got []")
    return arr


def _check_alphas(name: str, alphas: np.ndarray) -> None:
    if not np.all((alphas > 0.0) & (alphas < 1.0)):  # NaN fails too
        raise WelchInputError(f"`{name}` must lie in (0, 1), got {_show(alphas)}")


# -- the spending function ---------------------------------------------------------------------------------------


def obrien_fleming_spending(t: npt.ArrayLike, alpha: npt.ArrayLike) -> np.ndarray:
    """Lan-DeMets O'Brien-Fleming-type spending function, two-sided.

    ``alpha(t) = 2 - 2 Phi(z_{1-alpha/2} / sqrt(t))`` for t in (0, 1], `alpha` for t >= 1, 0 at t = 0. It is
    evaluated as ``2 Phi(-z / sqrt(t))`` (``ndtr`` of a negative argument), so tiny values keep full relative
    precision instead of cancelling in ``2 - 2 Phi``.

    Parameters
    ----------
    t : array_like
        Information fractions, >= 0.
    alpha : array_like
        Overall two-sided levels, each in (0, 1). Broadcast against `t`.

    Returns
    -------
    numpy.ndarray
        The level spent by information fraction `t`, of the broadcast shape of `t` and `alpha`.

    Raises
    ------
    WelchInputError
        If a `t` is negative or NaN, or an `alpha` is outside (0, 1).
    """
    t, alpha = _spending_args(t, alpha)
    z = -special.ndtri(alpha / 2.0)
    with np.errstate(divide="ignore"):  # t = 0: z / 0 = inf, ndtr(-inf) = 0 as wanted
        spent = 2.0 * special.ndtr(-z / np.sqrt(np.minimum(t, 1.0)))
    # exactly alpha at and after the end, not alpha up to rounding
    return np.where(t >= 1.0, alpha, spent)


def pocock_spending(t: npt.ArrayLike, alpha: npt.ArrayLike) -> np.ndarray:
    """Lan-DeMets Pocock-type spending function, ``alpha(t) = alpha ln(1 + (e - 1) t)`` for t in [0, 1], `alpha`
    for t >= 1 (Lan and DeMets 1983; Kim and DeMets 1987).

    It spends evenly on the log scale of the information: boundaries are nearly constant over the looks, so a
    large bias stops the run early at little cost in z (the price is a somewhat higher last boundary than
    O'Brien-Fleming's). Arguments and errors as `obrien_fleming_spending`.
    """
    t, alpha = _spending_args(t, alpha)
    return np.where(t >= 1.0, alpha, alpha * np.log1p((math.e - 1.0) * np.minimum(t, 1.0)))


def _spending_args(t, alpha) -> tuple[np.ndarray, np.ndarray]:
    """A spending function's information fractions and alphas, checked and broadcast against each other."""
    t = _as_float_array("t", t)
    alpha = _as_float_array("alpha", alpha)
    if not np.all(t >= 0.0):
        raise WelchInputError(f"`t` must be >= 0, got {_show(t)}")
    _check_alphas("alpha", alpha)
    return np.broadcast_arrays(t, alpha)


#: Spending functions by name: (the function, log of it for fractions (rows) and alphas (columns)).
SPENDING = {
    "obrien_fleming": obrien_fleming_spending,
    "pocock": pocock_spending,
}


def _log_spending(
    t: np.ndarray, alpha: np.ndarray, spending: str = "obrien_fleming", reserve: float = 0.0
) -> np.ndarray:
    """log alpha(t) for t > 0 (rows) and alphas (columns); finite far below the smallest double. With a `reserve`
    (see `boundaries`) it is (1 - reserve) alpha(t) up to t = 1 and alpha (1 - reserve / t) beyond."""
    inside = np.minimum(t, 1.0)
    if spending == "pocock":
        logs = np.log(alpha)[None, :] + np.log(np.log1p((math.e - 1.0) * inside))[:, None]
    else:
        z = -special.ndtri(alpha / 2.0)
        logs = _LOG2 + special.log_ndtr(-z[None, :] / np.sqrt(inside)[:, None])
    logs = np.where(t[:, None] >= 1.0, np.log(alpha)[None, :], logs)
    if reserve == 0.0:
        return logs
    with np.errstate(divide="ignore"):
        beyond = np.log(alpha)[None, :] + np.log1p(-reserve / np.maximum(t, 1.0))[:, None]
    return np.where(t[:, None] > 1.0, beyond, logs + math.log1p(-reserve))


def _isf_log(log_p: float) -> float:
    """The z with P(Z > z) = exp(log_p) for a standard normal Z, also where exp(log_p) underflows."""
    if log_p == -np.inf:
        return np.inf
    if log_p > -700.0:
        return float(-special.ndtri(math.exp(log_p)))
    return float(-special.ndtri_exp(log_p))


# -- the grid ----------------------------------------------------------------------------------------------------


class _Grid:
    """A grid on [0, top] for the even function q: panel ends, Simpson nodes (ends and midpoints) and weights.

    Only z >= 0 is stored; the boundaries are symmetric, so q is even and integrals over (-top, top) are
    integrals over [0, top] of the function and its mirror image.
    """

    def __init__(self, ends: np.ndarray):
        self.ends = ends
        nodes = np.empty(2 * ends.size - 1)
        nodes[0::2] = ends
        nodes[1::2] = 0.5 * (ends[:-1] + ends[1:])
        self.nodes = nodes
        widths = np.diff(ends)
        weights = np.zeros(nodes.size)
        weights[0:-1:2] += widths / 6.0
        weights[1::2] += 4.0 * widths / 6.0
        weights[2::2] += widths / 6.0
        self.weights = weights


def _spacing(z: np.ndarray, features: list[tuple[float, float]], exit_band: tuple[float, float] | None) -> np.ndarray:
    """The node spacing wanted at `z`: a fraction of the width of the nearest feature, growing with distance."""
    h = np.full(z.shape, _H_MAX)
    for loc, width in features:
        h = np.minimum(h, (width + _GRADING * np.abs(z - loc)) / _NODES_PER_SD)
    if exit_band is not None:
        low, sd = exit_band
        h = np.minimum(h, (sd + _GRADING * np.maximum(low - z, 0.0)) / _EXIT_NODES_PER_SD)
    return h


def _panel_ends(top: float, features: list[tuple[float, float]], exit_band: tuple[float, float] | None) -> np.ndarray:
    """Panel ends on [0, top] whose local spacing follows `_spacing`: equidistribute the panel density."""
    # Sample the spacing densely enough to integrate its reciprocal: uniformly, and geometrically around every
    # feature, since the spacing grows linearly (so its log evenly) away from it.
    pieces = [np.linspace(0.0, top, 257)]
    anchors = list(features)
    if exit_band is not None:
        anchors.append(exit_band)
    for loc, width in anchors:
        # offsets in feature widths from 1e-3 to past the whole grid
        offsets = width * _GEOMETRIC[: np.searchsorted(_GEOMETRIC, top / width + 1.0) + 1]
        pieces.append(loc + offsets)
        pieces.append(loc - offsets)
    z = np.concatenate(pieces)
    z = np.unique(np.clip(z, 0.0, top))
    density = 0.5 / _spacing(z, features, exit_band)  # panels per unit length (a panel is two node spacings)
    cumulative = np.concatenate(([0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(z))))
    panels = int(min(max(math.ceil(cumulative[-1]), 2), _MAX_PANELS))
    ends = np.interp(np.linspace(0.0, cumulative[-1], panels + 1), cumulative, z)
    ends[0], ends[-1] = 0.0, top
    return ends


# -- the recursion -----------------------------------------------------------------------------------------------


def _propagate(
    old_ends: np.ndarray, old_q: np.ndarray, old_count: np.ndarray, targets: np.ndarray, rho: float, sd: float
) -> np.ndarray:
    """q at the next look: integrate q (previous look) against the backward kernel N(u; +-rho z, sd^2).

    Batched over alphas (first axis). `old_ends` are panel ends padded by repeating the last end (zero-width
    panels), `old_count` the number of real panels per alpha, `old_q` q at the Simpson nodes. q is interpolated
    by the quadratic through each panel's ends and midpoint, and that quadratic is integrated exactly against the
    Gaussian kernel, so the kernel may be narrower than the panels.
    """
    n_alpha, n_targets = targets.shape
    rows = np.arange(n_alpha)[:, None, None]
    result = np.zeros(targets.shape)
    for sign in (1.0, -1.0):  # the kernel around rho z, and its mirror image around -rho z
        centre = sign * rho * targets
        if sign < 0.0:
            # The mirror image reaches u >= 0 only for targets near 0; targets are sorted, so it is a prefix.
            n_targets = int(np.sum(centre > -_WINDOW_SDS * sd, axis=1).max())
            if n_targets == 0:
                break
            centre = centre[:, :n_targets]
        # Only the panels within _WINDOW_SDS kernel sd of the centre matter: find that window per target.
        first = np.empty(centre.shape, dtype=np.intp)
        stop = np.empty(centre.shape, dtype=np.intp)
        for a in range(n_alpha):
            ends = old_ends[a, : old_count[a] + 1]
            first[a] = np.searchsorted(ends, centre[a] - _WINDOW_SDS * sd, side="right") - 1
            stop[a] = np.searchsorted(ends, centre[a] + _WINDOW_SDS * sd, side="left")
            first[a] = np.clip(first[a], 0, old_count[a] - 1)
            stop[a] = np.clip(stop[a], first[a] + 1, old_count[a])
        window = int((stop - first).max())
        ends = np.minimum(first[:, :, None] + np.arange(window + 1), old_ends.shape[1] - 1)  # (alpha, target, end)
        panel = np.minimum(ends[:, :, :-1], old_ends.shape[1] - 2)
        outside = first[:, :, None] + np.arange(window) >= stop[:, :, None]
        # the window's panel ends in kernel standard deviations from the centre; adjacent panels share an end
        w_left, w_mid, w_right = _quadratic_weights((old_ends[rows, ends] - centre[:, :, None]) / sd)
        total = (
            w_left * old_q[rows, 2 * panel] + w_mid * old_q[rows, 2 * panel + 1] + w_right * old_q[rows, 2 * panel + 2]
        )
        # A running sum adds the window in a fixed order, so the zeros that pad it for other alphas of the batch
        # don't change the last bit: one alpha gives the same boundaries alone as in any batch.
        result[:, :n_targets] += np.cumsum(np.where(outside, 0.0, total), axis=2)[:, :, -1]
    return np.clip(result, 0.0, 1.0)


def _quadratic_weights(ends: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weights of each panel's left end, midpoint and right end in the integral of its quadratic interpolant
    against the standard normal density. `ends` (last axis) are consecutive panel ends in kernel standard
    deviations from the kernel's centre."""
    tail = special.ndtr(-np.abs(ends))  # the tail beyond each end, never 1 - (something close to 1)
    dens = np.exp(-0.5 * ends * ends - _LOG_SQRT_2PI)
    a, b = ends[..., :-1], ends[..., 1:]
    tail_a, tail_b, dens_a, dens_b = tail[..., :-1], tail[..., 1:], dens[..., :-1], dens[..., 1:]
    # P(a < Z < b) from the tails on the panel's side of 0, so it keeps its relative precision far out
    mass = np.where(a >= 0.0, tail_a - tail_b, np.where(b <= 0.0, tail_b - tail_a, 1.0 - tail_a - tail_b))
    first = dens_a - dens_b  # integral of y phi(y) over the panel
    second = mass + a * dens_a - b * dens_b  # integral of y^2 phi(y)
    centre = 0.5 * (a + b)
    half = 0.5 * (b - a)
    with np.errstate(divide="ignore", invalid="ignore"):
        # moments of x = (y - centre) / half, the panel's own coordinate in [-1, 1]
        m1 = np.where(half > 0.0, (first - centre * mass) / half, 0.0)
        m2 = np.where(half > 0.0, (second - 2.0 * centre * first + centre * centre * mass) / (half * half), 0.0)
    # Lagrange basis on -1, 0, 1: x (x - 1) / 2, 1 - x^2, x (x + 1) / 2
    return 0.5 * (m2 - m1), mass - m2, 0.5 * (m2 + m1)


def _solve_boundary(
    grid: _Grid, q: np.ndarray, rho: float, sd: float, log_increment: float, low: float, high: float
) -> float:
    """The c whose exit probability P(no crossing before, |Z_k| >= c) is exp(log_increment); inf above _C_MAX.

    `grid` and `q` describe the previous look; `low` and `high` bracket the answer (see `_Schedule`).
    """
    if log_increment == -np.inf or low >= _C_MAX:
        return np.inf
    with np.errstate(divide="ignore"):
        base = np.log(grid.weights) + np.log(q) - 0.5 * grid.nodes**2 - _LOG_SQRT_2PI
    keep = np.isfinite(base)
    if not keep.any():  # no path is still running (an earlier c of 0): nothing left to cross
        return np.inf
    base, u = base[keep], rho * grid.nodes[keep]

    def excess(c: float) -> float:
        # log P(exit at c) - log(increment), summed in log space (log-sum-exp): the terms can be 1e-300 and less.
        # P(Z_k >= c | Z_{k-1} = u) = Phi((rho u - c) / sd); the second term is the crossing of -c from u (or of
        # c from -u, q being even).
        terms = base + np.logaddexp(special.log_ndtr((u - c) / sd), special.log_ndtr((-u - c) / sd))
        top = terms.max()
        if top == -np.inf:
            return -np.inf
        return _LOG2 + top + math.log(np.exp(terms - top).sum()) - log_increment

    # The bounds hold for the exact exit probability; the discretised one may differ by ~1e-7, so widen a little.
    high = min(high + 0.1, _C_MAX)
    f_high = excess(high)
    while f_high > 0.0 and high < _C_MAX:
        high = min(high + 1.0, _C_MAX)
        f_high = excess(high)
    if f_high >= 0.0:  # even |Z| >= _C_MAX is reached more often than the increment allows
        return np.inf
    low = max(low - 0.1, 0.0)
    f_low = excess(low)
    while f_low < 0.0 and low > 0.0:
        low = max(low - 1.0, 0.0)
        f_low = excess(low)
    if f_low <= 0.0:  # not reachable with a proper spending function; reject everything
        return 0.0
    return optimize.brentq(excess, low, high, xtol=1e-12, rtol=4.0 * np.finfo(float).eps)


class _Schedule:
    """What the spending function fixes before any integration, per look (rows) and alpha (columns)."""

    def __init__(self, t: np.ndarray, log_spent: np.ndarray, first_spent: np.ndarray):
        self.t = t
        self.first_spent = first_spent
        with np.errstate(divide="ignore", invalid="ignore"):
            # log(spent_k - spent_{k-1}) without forming the difference of two nearly equal numbers
            drop = np.maximum(-np.expm1(log_spent[:-1] - log_spent[1:]), 0.0)
            self.log_increment = np.vstack((log_spent[:1], log_spent[1:] + np.log(drop)))
        # Bounds on c_k: the exit probability is at most P(|Z_k| >= c), and at least that minus the level spent
        # before, so 2 Phi(-c_k) lies between the increment and the level spent by t_k.
        self.low = np.vectorize(_isf_log, otypes=[float])(log_spent - _LOG2)
        self.high = np.vectorize(_isf_log, otypes=[float])(self.log_increment - _LOG2)
        # the backward kernel Z_{k-1} | Z_k = z ~ N(rho z, sd^2)
        self.rho = np.sqrt(np.concatenate(([0.0], t[:-1] / t[1:])))
        self.sd = np.sqrt(np.concatenate(([1.0], np.diff(t) / t[1:])))

    def first_boundary(self) -> np.ndarray:
        """c_1: no earlier look, so exactly the fixed-sample critical value of the first increment."""
        with np.errstate(divide="ignore"):
            c = np.where(self.first_spent > 1e-300, -special.ndtri(self.first_spent / 2.0), self.high[0])
        return np.where(c > _C_MAX, np.inf, c)

    def first_anchor(self, k: int, a: int, c_before: float) -> float:
        """A first guess at a lower bound on c_k, for placing the fine part of the grid of look k - 1.

        `low` is a proven bound but loose where two looks are close together; the boundary of the previous look
        carried along the W scale, rho c_{k-1}, is close for O'Brien-Fleming shapes, whose W-scale boundary
        c sqrt(t) barely moves. A guess above c_k is detected after solving and corrected (`_Tracker.solve`).
        """
        if not np.isfinite(c_before):
            return self.low[k, a]
        return max(self.low[k, a], self.rho[k] * c_before - 2.0 * _EXIT_SDS * self.sd[k])

    def exit_band(self, k: int, anchor: float) -> tuple[float, float] | None:
        """Where the exit probability of look k has its mass on the grid of look k - 1 if c_k >= `anchor`
        (from rho c_k - _EXIT_SDS sd up), and the sd of its kernel."""
        if k >= self.t.size:
            return None
        return (self.rho[k] * min(anchor, _C_MAX) - _EXIT_SDS * self.sd[k], self.sd[k])


class _Tracker:
    """The recursion for a batch of alphas: grids and q of the latest look, and of the one before."""

    def __init__(self, schedule: _Schedule, c_first: np.ndarray):
        self.schedule = schedule
        n_alpha = c_first.size
        self.k = 0  # the look that `grids` and `qs` describe
        self.tops = np.minimum(c_first, _Z_MAX)
        self.features: list[list[tuple[float, float]]] = [[] for _ in range(n_alpha)]  # q_1 = 1 is flat
        self.anchors = [schedule.first_anchor(1, a, c_first[a]) for a in range(n_alpha)]
        self.grids = [self._grid(a) for a in range(n_alpha)]
        self.qs = [np.ones(g.nodes.size) for g in self.grids]
        self.previous: tuple[list[_Grid], list[np.ndarray]] | None = None

    def _grid(self, a: int) -> _Grid:
        band = self.schedule.exit_band(self.k + 1, self.anchors[a])
        return _Grid(_panel_ends(self.tops[a], self.features[a], band))

    def solve(self, a: int) -> float:
        """c of the next look for alpha number `a`; refines the grid until its fine part holds the exit mass."""
        s, k = self.schedule, self.k + 1
        for attempt in range(4):
            c = _solve_boundary(
                self.grids[a], self.qs[a], s.rho[k], s.sd[k], s.log_increment[k, a], s.low[k, a], s.high[k, a]
            )
            if c >= self.anchors[a] or self.anchors[a] <= s.low[k, a]:
                return c
            # The guess was too high: part of the exit mass lay on the coarse part of the grid, and c may be off
            # by about that part's spacing. Move the fine part down past c and solve again; the last attempt
            # falls back on the proven bound.
            miss = self.anchors[a] - c
            self.anchors[a] = s.low[k, a] if attempt == 2 else max(s.low[k, a], c - miss - _EXIT_SDS * s.sd[k])
            self.grids[a] = self._grid(a)
            if self.previous is None:
                self.qs[a] = np.ones(self.grids[a].nodes.size)
            else:
                old_grids, old_qs = self.previous
                (self.qs[a],) = _propagate_all([old_grids[a]], [old_qs[a]], [self.grids[a]], s.rho[k - 1], s.sd[k - 1])
        return c

    def advance(self, c: np.ndarray) -> None:
        """Carry q to the next look, whose boundaries are `c`."""
        s = self.schedule
        self.k += 1
        k = self.k
        rho, sd = s.rho[k], s.sd[k]
        new_tops = np.minimum(c, _Z_MAX)
        for a in range(new_tops.size):
            # q_k varies where rho z meets an earlier truncation point (a step smoothed to width sd / rho in z)
            # and where q_{k-1} varied (those features move out by 1 / rho and widen)
            moved = [(loc / rho, math.hypot(width, sd) / rho) for loc, width in self.features[a]]
            moved.append((self.tops[a] / rho, sd / rho))
            self.features[a] = [
                (loc, width)
                for loc, width in moved
                if loc - _WINDOW_SDS * width < new_tops[a] and width < _NODES_PER_SD * _H_MAX
            ]
            self.anchors[a] = s.first_anchor(k + 1, a, c[a])  # advance() is never called for the last look
        self.tops = new_tops
        new_grids = [self._grid(a) for a in range(new_tops.size)]
        self.previous = (self.grids, self.qs)
        self.qs = _propagate_all(self.grids, self.qs, new_grids, rho, sd)
        self.grids = new_grids


def _compute(t: np.ndarray, log_spent: np.ndarray, first_spent: np.ndarray) -> np.ndarray:
    """Boundaries for looks at `t` (clipped to <= 1) and the spending given as log spent level per look."""
    schedule = _Schedule(t, log_spent, first_spent)
    n_looks, n_alpha = log_spent.shape
    c = np.full((n_looks, n_alpha), np.inf)
    c[0] = schedule.first_boundary()
    if n_looks == 1:
        return c
    tracker = _Tracker(schedule, c[0])
    for k in range(1, n_looks):
        c[k] = [tracker.solve(a) for a in range(n_alpha)]
        if k < n_looks - 1:
            tracker.advance(c[k])
    return c


def _propagate_all(
    grids: list[_Grid], qs: list[np.ndarray], new_grids: list[_Grid], rho: float, sd: float
) -> list[np.ndarray]:
    """q on the new grids, all alphas in one batch (grids padded to a common size)."""
    n_panels = max(g.ends.size for g in grids)
    n_nodes = max(g.nodes.size for g in new_grids)
    old_ends = np.array([np.pad(g.ends, (0, n_panels - g.ends.size), mode="edge") for g in grids])
    old_q = np.array([np.pad(q, (0, 2 * n_panels - 1 - q.size), mode="edge") for q in qs])
    count = np.array([g.ends.size - 1 for g in grids])
    targets = np.array([np.pad(g.nodes, (0, n_nodes - g.nodes.size), mode="edge") for g in new_grids])
    new_q = _propagate(old_ends, old_q, count, targets, rho, sd)
    return [new_q[a, : g.nodes.size] for a, g in enumerate(new_grids)]


# -- public ------------------------------------------------------------------------------------------------------


def boundaries(
    fractions: npt.ArrayLike, alphas: npt.ArrayLike, spending: str = "obrien_fleming", reserve: float = 0.0
) -> np.ndarray:
    """Two-sided group-sequential boundaries by Lan-DeMets alpha spending (O'Brien-Fleming shape by default).

    Parameters
    ----------
    fractions : array_like
        Information fractions of the looks so far (passes so far / planned maximum passes), 1-D, strictly
        increasing and positive. Without a `reserve`, values >= 1 are clipped to 1 (the final look, which spends
        everything) and only the last one may be >= 1.
    alphas : array_like
        Overall two-sided levels, 1-D, each in (0, 1) (one per hypothesis, e.g. its Bonferroni share).
    spending : {"obrien_fleming", "pocock"}
        The spending function (see `SPENDING`).
    reserve : float, in [0, 1)
        The share of each alpha kept for looks past the planned maximum (fractions > 1, a budget grown after the
        planned last look): ``(1 - reserve) alpha(t)`` is spent up to t = 1 and ``alpha (1 - reserve / t)``
        beyond, so the level spent stays below alpha however far the looks go. The spending is fixed before any
        data, so growing the budget after seeing them keeps the level (Lan and DeMets 1983: only the spending
        function, not the number or the timing of the looks, must be fixed in advance).

    Returns
    -------
    numpy.ndarray
        ``c[k, j]``, shape ``(len(fractions), len(alphas))``: reject hypothesis j at look k when
        ``|Z_k| >= c[k, j]``. Under H0, with ``Z_k = W(t_k) / sqrt(t_k)`` for a standard Brownian motion W,
        ``P(|Z_1| < c_1, ..., |Z_{k-1}| < c_{k-1}, |Z_k| >= c_k) = alpha_j(t_k) - alpha_j(t_{k-1})``, to about
        1e-6 in c. ``inf`` where the look spends nothing or so little that c would exceed 40. Deterministic bit
        for bit: the result depends only on the inputs (resuming recomputes the same boundaries from stored
        fractions), the rows of earlier looks don't depend on later fractions, and a column doesn't depend on
        the other alphas.

    Raises
    ------
    WelchInputError
        For empty or not 1-D input, fractions that are not strictly increasing and positive or (without a
        reserve) reach 1 before the last look, alphas outside (0, 1) and a reserve outside [0, 1).
    """
    t = _as_vector("fractions", fractions)
    if not (t[0] > 0.0 and np.all(np.diff(t) > 0.0)):  # NaN fails too
        raise WelchInputError(f"`fractions` must be strictly increasing and positive, got {_show(t)}")
    if not 0.0 <= reserve < 1.0:  # NaN fails too
        raise WelchInputError(f"`reserve` must lie in [0, 1), got {reserve!r}")
    if reserve == 0.0 and np.any(t[:-1] >= 1.0):
        raise WelchInputError(f"`fractions` may be >= 1 only at the last look, got {_show(t)}")
    alphas = _as_vector("alphas", alphas)
    _check_alphas("alphas", alphas)
    if spending not in SPENDING:
        raise WelchInputError(f"`spending` must be one of {tuple(SPENDING)}, got {spending!r}")
    if reserve == 0.0:
        t = np.minimum(t, 1.0)
    first = SPENDING[spending](min(t[0], 1.0), alphas)  # the first look's level directly: tiny ones keep precision
    if reserve:
        first = first * (1.0 - reserve) if t[0] <= 1.0 else alphas * (1.0 - reserve / t[0])
    return _compute(t, _log_spending(t, alphas, spending, reserve), first)


def nominal_levels(c: npt.ArrayLike) -> np.ndarray:
    """The two-sided nominal p-value levels ``2 (1 - Phi(c))`` of boundaries `c`.

    Rejecting when the two-sided p-value of Z is <= the level is the same as rejecting when ``|Z| >= c``.
    Computed as ``erfc(c / sqrt 2)``, with full relative precision for large c instead of the cancellation of
    ``1 - Phi``; ``inf`` gives 0. Past c = 37.5 the level is below the smallest normal double (2.2e-308) and
    scipy's erfc flushes it to 0, so there it is ``exp(log 2 + log_ndtr(-c))``: 0 only below the smallest
    subnormal double (about c = 38.5).

    Parameters
    ----------
    c : array_like
        Boundaries, e.g. the output of `boundaries`.

    Returns
    -------
    numpy.ndarray
        The levels, of the shape of `c`.
    """
    c = _as_float_array("c", c)
    with np.errstate(over="ignore", under="ignore"):
        return np.where(c < 37.5, special.erfc(c / math.sqrt(2.0)), np.exp(_LOG2 + special.log_ndtr(-c)))
