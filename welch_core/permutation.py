"""A permutation test of the whole family, for Welch's test between runs of different pass counts.

Why: Welch's t is calibrated by the normal approximation of each side's mean. With equal pass counts the
skewness of the two sides cancels to first order, but with unequal ones the smaller side's mean and variance
decide the statistic: a side of 4 passes of a caustic tile usually misses the fireflies that the 256 passes of
the other side hold, so its mean is low and its variance tiny, and |t| lands far in a tail that the t
distribution says is nearly empty. Measured on a rendered glass caustic (64x64, 16-px tiles, alpha 0.01): 4 v
256 passes called `biased` in 87 % of unbiased splits. No test that reads the small side alone can know better:
its few passes say nothing of what they missed. The other side's passes can, if the two are drawn from one
distribution.

The test: H0 "the passes of both runs are exchangeable" (one distribution of per-pass tile sums for both sides,
which is what two unbiased renders of one setting with independent seeds are), against "some tile-channel of
some tile size differs". The statistic is the largest |Welch t| over the family of the `biased` claim, every
tile-channel of every tile size (a coarse tile is a sum of finer ones; a pass's sums at every size are one
vector, so permuting passes keeps their dependence); its null distribution is that of the same maximum over
random reassignments of the passes to the two sides with the pass counts kept (Westfall and Young 1993, the
single-step max-T). Under H0 every reassignment is as likely as the observed one, so
``p = (1 + #{resamples with max >= observed}) / (1 + resamples)`` has P(p <= level) <= level for any pass counts
and any shape of the tile sums, fireflies included (Phipson and Smyth 2010); a tile-channel's adjusted p-value
uses the same maxima, which controls the family-wise error rate over the tile-channels (subset pivotality holds:
the statistic of a tile-channel depends on its own column alone). Studentizing keeps the test asymptotically
valid where the two sides share a mean but not a distribution (another sampling pattern: Janssen 1997).

It serves as a second key: `biased` between sides of different pass counts needs the t-tests' family and this
test both to reject (an intersection of rejections: its level is at most either's), so nothing that the t-tests
do with equal counts changes. Its smallest p-value is 1 / (1 + resamples), and no smaller than one over the
number of distinct reassignments (45 for 2 v 8 passes): where that is above the level it had to reach, the run
cannot be called `biased` and the outcome says so.

References: P. H. Westfall and S. S. Young, "Resampling-Based Multiple Testing", Wiley, 1993; B. Phipson and
G. K. Smyth, "Permutation P-values Should Never Be Zero", Stat. Appl. Genet. Mol. Biol. 9(1), 2010; A. Janssen,
"Studentized permutation tests for non-i.i.d. hypotheses and the generalized Behrens-Fisher problem", Stat.
Probab. Lett. 36, 1997.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["MAX_RESAMPLES", "RESAMPLES_PER_LEVEL", "Resampling", "permutation_max_t"]

#: Resamples drawn for a test at `level`: this many over the level (999 at 0.01), so that a p-value well under the
#: level is found under it with near certainty (the Monte Carlo error of p at the level is about 30 %).
RESAMPLES_PER_LEVEL = 10
#: At most this many (a look late in a long check has a small level): the smallest p-value is then 1 / 20 001.
MAX_RESAMPLES = 20_000
#: Resamples drawn at once: a block of this many rows times the family's columns stays a few MB.
_BLOCK = 128
#: The resampling is seeded: the same data give the same p-value (a resumed check, a report made twice).
_SEED = 20200

_METHOD = "permutation max-T"
#: Relative tolerance of a tie between a resampled and the observed |t| (rounding of sums in another order).
_TIE = 1e-9


@dataclass(frozen=True)
class Resampling:
    """The permutation test of the family (see the module docstring)."""

    p_value: float  # (1 + exceedances) / (1 + resamples drawn)
    level: float  # the level it had to reach
    resamples: int  # resamples drawn (fewer than planned when the first ones already exceeded the level)
    smallest: float  # the smallest p-value this test can give for these pass counts and resamples
    #: per scale, (tiles_y, tiles_x, channels): each tile-channel's adjusted p-value (NaN outside the family)
    adjusted: tuple[np.ndarray, ...]
    method: str = _METHOD

    @property
    def rejects(self) -> bool:
        return self.p_value <= self.level

    @property
    def limited(self) -> bool:
        """The level is out of this test's reach: too few passes (or resamples) to reject at it."""
        return self.smallest > self.level

    def to_json(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "p_value": self.p_value,
            "level": self.level,
            "resamples": self.resamples,
            "smallest": self.smallest,
            "rejects": self.rejects,
            "limited": self.limited,
        }


def permutation_max_t(runs, level: float) -> Resampling:
    """The permutation max-T test of `runs`, the (reference, test) TileStats of every tested tile size.

    Parameters
    ----------
    runs : sequence of (TileStats, TileStats)
        Per tile size, the two runs (the same passes at each size).
    level : float
        The level in (0, 1) it must reach: it draws ``RESAMPLES_PER_LEVEL / level - 1`` resamples (at most
        `MAX_RESAMPLES`) and stops early once the p-value can no longer reach it.
    """
    if not 0 < level < 1:
        raise ValueError(f"`level` must lie in (0, 1), got {level!r}")
    columns, shapes = _family(runs)
    n_ref, n_test = runs[0][0].n, runs[0][1].n
    total = n_ref + n_test
    planned = min(MAX_RESAMPLES, max(1, math.ceil(RESAMPLES_PER_LEVEL / level) - 1))
    distinct = math.comb(total, n_test)  # an int beyond any float for a few hundred passes a side
    smallest = max(1.0 / (planned + 1), 1.0 / distinct if distinct < 10**300 else 0.0)
    empty = tuple(np.full(shape, np.nan) for shape in shapes)
    if columns is None or n_ref < 2 or n_test < 2 or smallest > level:  # nothing to test, or out of reach
        return Resampling(1.0, level, 0, smallest, empty)
    x, family = columns
    labels = np.zeros((1, total))
    labels[0, n_ref:] = 1.0
    # Ties count as exceedances, up to rounding: the observed assignment drawn again (certain for few passes)
    # must not look smaller than itself because a block's matrix product summed in another order.
    observed = _abs_t(x, labels, n_ref, n_test)[0] * (1.0 - _TIE)
    top = float(observed.max())
    rng = np.random.default_rng(_SEED)
    maxima, exceed, drawn = [], 0, 0
    # Once (1 + exceed) / (1 + planned) > level the test can't reject: the rest need not be drawn.
    allowed = level * (planned + 1) - 1
    while drawn < planned and exceed <= allowed:
        count = min(_BLOCK, planned - drawn)
        block = rng.permuted(np.repeat(labels, count, axis=0), axis=1)
        m = _abs_t(x, block, n_ref, n_test).max(axis=1)
        maxima.append(m)
        exceed += int(np.sum(m >= top))
        drawn += count
    maxima = np.sort(np.concatenate(maxima))
    p_value = (1 + exceed) / (1 + drawn)
    # Adjusted p of each tile-channel: the share of resampled maxima at or above its own |t|.
    adjusted_flat = (1 + drawn - np.searchsorted(maxima, observed, side="left")) / (1 + drawn)
    adjusted, start = [], 0
    for shape, used in zip(shapes, family, strict=True):
        size = int(np.prod(shape))
        out = np.full(size, np.nan)
        count = int(used.sum())
        out[used] = adjusted_flat[start : start + count]
        start += count
        adjusted.append(out.reshape(shape))
    return Resampling(float(p_value), level, drawn, smallest, tuple(adjusted))


def _family(runs):
    """Every tile-channel of every size as one column of pooled per-pass sums (reference passes first), those
    that vary and are finite in every pass; standardized (Welch's t does not change under a column's shift and
    scale, and the sums of squares below then do not cancel)."""
    blocks, family, shapes = [], [], []
    for ref, test in runs:
        pooled = np.concatenate([ref.sums, test.sums]).reshape(ref.n + test.n, -1)
        shapes.append(ref.grid_shape)
        with np.errstate(invalid="ignore"):
            used = np.isfinite(pooled).all(axis=0) & (np.ptp(pooled, axis=0) > 0)
        family.append(used)
        blocks.append(pooled[:, used])
    x = np.concatenate(blocks, axis=1) if blocks else np.zeros((0, 0))
    if x.shape[1] == 0:
        return None, shapes
    x = (x - x.mean(axis=0)) / x.std(axis=0)
    squares = x * x
    return ((x, squares, x.sum(axis=0), squares.sum(axis=0)), family), shapes


def _abs_t(x: tuple[np.ndarray, ...], labels: np.ndarray, n_ref: int, n_test: int) -> np.ndarray:
    """|Welch t| (eq. 1) of every column for each row of 0/1 `labels` (1: the test side), shape (rows, columns);
    `x` is the pooled columns, their squares and the sums of both."""
    values, squares, total, total_squares = x
    s_test, q_test = labels @ values, labels @ squares
    s_ref, q_ref = total - s_test, total_squares - q_test
    m_test, m_ref = s_test / n_test, s_ref / n_ref
    v_test = np.maximum(q_test - s_test * m_test, 0.0) / (n_test - 1)
    v_ref = np.maximum(q_ref - s_ref * m_ref, 0.0) / (n_ref - 1)
    diff = np.abs(m_test - m_ref)
    se = np.sqrt(v_test / n_test + v_ref / n_ref)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = diff / se
    # 0 / 0 (a column constant on both sides in this assignment): no difference; d / 0 stays inf
    return np.where(np.isnan(t), 0.0, t)
