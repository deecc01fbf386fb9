"""Effect sizes: how much brighter or darker the test is per tile, and the smallest bias the run could find.

"2 % too bright in these tiles" is what a user acts on; a p-value alone is not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from .multitest import bonferroni

__all__ = ["DETECTION_POWER", "Effect", "effect_sizes", "relative_interval"]

#: Power at which the minimum detectable bias is quoted (the usual convention in power analysis).
DETECTION_POWER = 0.8


@dataclass(frozen=True)
class Effect:
    """Relative difference of the tile means, (test - reference) / |reference|, per tile-channel."""

    rel_diff: np.ndarray
    ci_low: np.ndarray  # confidence interval at level 1 - alpha, same units
    ci_high: np.ndarray
    min_detectable: np.ndarray  # smallest |rel_diff| found with DETECTION_POWER at the per-tile level used


def effect_sizes(tested, alpha: float, n_tests: int) -> Effect:
    """Relative effect sizes with pointwise (1 - alpha) intervals (`relative_interval`) and the minimum
    detectable bias, which uses the Bonferroni level alpha / n_tests that a tile must reach to flag on its own.
    `tested` is a `tile_test.TileTest`."""
    result, scale = tested.result, np.abs(tested.ref_mean)
    low, high = relative_interval(tested, alpha)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = result.mean_difference / scale
        level = bonferroni(alpha, n_tests)
        detectable = (special.stdtrit(result.df, 1.0 - level / 2.0) + special.stdtrit(result.df, DETECTION_POWER)) * (
            result.standard_error / scale
        )
    return Effect(rel, low, high, detectable)


def relative_interval(tested, level) -> tuple[np.ndarray, np.ndarray]:
    """The two-sided interval of the relative difference theta = (mu_test - mu_ref) / |mu_ref| at two-sided error
    `level` per element (a scalar, or an array broadcast against the result), by Fieller's method: theta is in
    the interval when the test of "mu_test = (1 + theta) mu_ref" does not reject, that is when

        (d - theta r)^2 <= q^2 (V_dd - 2 theta V_dr + theta^2 V_rr)

    for the mean difference d = mean_test - mean_ref, the reference mean r, the variances and covariance of their
    estimates V (`tile_test.TileTest`), and the t quantile q at the element's degrees of freedom. Each end is the
    boundary of an exact one-sided test of the ratio (for normal Welch samples), which makes the two one-sided
    tests of `equivalent` exact too. Dividing d's interval by |r| instead ignores the reference's uncertainty:
    1.04x the stated error rate at a 2 % tolerance with equal variances, and far more in a paired test whose
    differences vary much less than the sides (a change of a few light paths). Elements without a p-value get
    NaN; where the reference mean is not clearly away from 0 (q^2 V_rr >= r^2) the interval is infinite."""
    result = tested.result
    d, r = result.mean_difference, tested.ref_mean
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        q2 = special.stdtrit(result.df, 1.0 - np.asarray(level, dtype=float) / 2.0) ** 2
        a = r * r - q2 * tested.ref_var
        b = d * r - q2 * tested.cross
        c = d * d - q2 * result.standard_error**2
        root = np.sqrt(np.maximum(b * b - a * c, 0.0))
        low, high = (b - root) / a, (b + root) / a  # theta = mu_test / mu_ref - 1
        bounded = a > 0
        low, high = np.where(bounded, low, -np.inf), np.where(bounded, high, np.inf)
        flip = r < 0  # relative to |mu_ref|: the sign of theta turns with the reference's
        low, high = np.where(flip, -high, low), np.where(flip, -low, high)
        invalid = ~np.isfinite(result.pvalue)
        return np.where(invalid, np.nan, low), np.where(invalid, np.nan, high)
