"""From many tile-channel p-values to one decision with a stated false-positive rate.

The paper reads the colour map and the histogram by eye (§4.4). Here: the channels of a tile are combined by
Bonferroni (valid however strongly R, G and B are correlated), tiles by Holm (family-wise error, finds localised
bias) and by a one-sided Kolmogorov-Smirnov test of the tile p-values against the uniform distribution (the
histogram reasoning of §3.2 made quantitative: finds a weak bias spread over many tiles). The global p-value is
the Bonferroni combination of the two, so a `biased` verdict has a false-positive rate of at most alpha.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import special

from .errors import WelchInputError, check_alpha

__all__ = [
    "GlobalTest",
    "bh_qvalues",
    "bonferroni",
    "bonferroni_p",
    "combine_channels",
    "global_test",
    "holm",
    "uniformity_pvalue",
]


def bonferroni(alpha: float, *family_sizes: int) -> float:
    """The tool's one split of alpha: a hypothesis in a union of families (the scales, the tile-channels of a
    scale, the two sides of an interval, the layers of a render, the steps of a bisect) is tested at alpha over the
    product of their sizes, so that the chance of rejecting any true one is at most alpha (Bonferroni: valid
    however the tests depend on each other)."""
    return alpha / math.prod(max(int(size), 1) for size in family_sizes)


def bonferroni_p(pvalue: npt.ArrayLike, *family_sizes: int) -> np.ndarray | float:
    """The p-value of `bonferroni`'s split: what is compared with alpha itself (the p times the family's size,
    at most 1)."""
    adjusted = np.minimum(np.asarray(pvalue, dtype=float) * math.prod(max(int(s), 1) for s in family_sizes), 1.0)
    return float(adjusted) if adjusted.ndim == 0 else adjusted


def combine_channels(pvalues: npt.ArrayLike) -> np.ndarray:
    """One p-value per tile from its channels (last axis): Bonferroni on the smallest, k * min p, capped at 1.

    k counts the channels that have a p-value; a tile with none gets NaN. No independence is assumed.
    """
    p = np.asarray(pvalues, dtype=float)
    k = np.isfinite(p).sum(axis=-1)
    with np.errstate(invalid="ignore"):
        smallest = np.nanmin(np.where(np.isfinite(p), p, np.inf), axis=-1)
        return np.where(k > 0, np.minimum(1.0, k * smallest), np.nan)


def _adjust_sorted(pvalues: npt.ArrayLike, adjust) -> np.ndarray:
    """Apply `adjust` to the finite p-values in ascending order, cap at 1, and put them back; NaN stays NaN."""
    p = np.asarray(pvalues, dtype=float)
    out = np.full(p.shape, np.nan)
    valid = np.isfinite(p)
    ascending = np.sort(p[valid])
    if ascending.size:
        order = np.argsort(p[valid])
        result = np.empty(ascending.size)
        result[order] = np.minimum(1.0, adjust(ascending, ascending.size))
        out[valid] = result
    return out


def holm(pvalues: npt.ArrayLike) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error under any dependence). NaN stays NaN."""
    return _adjust_sorted(pvalues, lambda p, m: np.maximum.accumulate((m - np.arange(m)) * p))


def bh_qvalues(pvalues: npt.ArrayLike) -> np.ndarray:
    """Benjamini-Hochberg q-values (false-discovery rate for independent or positively dependent tests)."""
    return _adjust_sorted(pvalues, lambda p, m: np.minimum.accumulate((p * m / np.arange(1, m + 1))[::-1])[::-1])


def uniformity_pvalue(pvalues: npt.ArrayLike) -> float:
    """One-sided KS test that the p-values are not stochastically smaller than uniform (paper §3.2, Fig. 10).

    Valid for conservative (super-uniform) p-values too, such as Bonferroni-combined tile p-values. NaN if none.
    """
    p = np.asarray(pvalues, dtype=float)
    p = p[np.isfinite(p)]
    if p.size == 0:
        return float("nan")
    # One-sided statistic D+ = max(i/n - p_(i)): how far the empirical CDF rises above the uniform CDF, i.e. too
    # many small p-values. Its exact survival function is Smirnov's (what scipy.stats.kstest uses for
    # alternative="greater"; scipy.special alone keeps scipy.stats out of the import path).
    ordered = np.sort(p)
    n = ordered.size
    d_plus = max(float(np.max(np.arange(1, n + 1) / n - ordered)), 0.0)
    if d_plus > 1.0 - 1.0 / n:
        # Where n(1 - D+) < 1 the survival function is (1 - D+)^n, and 1 - D+ = min(p_(i) + 1 - i/n) computed
        # without the cancellation of 1 - D+ (a single tile's p of 1e-23 gave 0 instead of 1e-23).
        complement = float(np.min(ordered + (n - np.arange(1, n + 1)) / n))
        return complement**n
    return float(special.smirnov(n, d_plus))


@dataclass(frozen=True)
class GlobalTest:
    """The image-level test: is any tile biased (Holm), or are the tile p-values too small overall (KS)?"""

    pvalue: float  # Bonferroni over the two components: NaN when there are no tiles
    holm_pvalue: float  # smallest Holm-adjusted tile p-value
    uniformity_pvalue: float  # one-sided KS of the tile p-values
    adjusted: np.ndarray  # Holm-adjusted tile p-values, NaN where excluded
    qvalues: np.ndarray  # Benjamini-Hochberg q-values, NaN where excluded
    alpha: float

    @property
    def rejected(self) -> bool:
        return bool(np.isfinite(self.pvalue) and self.pvalue <= self.alpha)


def global_test(tile_pvalues: npt.ArrayLike, alpha: float = 0.01) -> GlobalTest:
    """Combine tile p-values (NaN = excluded) into the global p-value at level `alpha`."""
    alpha = check_alpha(alpha)
    p = np.asarray(tile_pvalues, dtype=float)
    finite_p = p[np.isfinite(p)]
    if ((finite_p < 0) | (finite_p > 1)).any():
        raise WelchInputError("`tile_pvalues` must lie in [0, 1]")
    adjusted = holm(p)
    qvalues = bh_qvalues(p)
    finite = np.isfinite(adjusted)
    if not finite.any():
        nan = float("nan")
        return GlobalTest(nan, nan, nan, adjusted, qvalues, alpha)
    holm_min = float(np.min(adjusted[finite]))
    ks = uniformity_pvalue(p)
    combined = min(1.0, 2.0 * min(holm_min, ks))  # Bonferroni over the two components
    return GlobalTest(combined, holm_min, ks, adjusted, qvalues, alpha)
