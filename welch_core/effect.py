"""Effect sizes: how much brighter or darker the test is per tile, and the smallest bias the run could find.

"2 % too bright in these tiles" is what a user acts on; a p-value alone is not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from .ttest import TTestResult

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


def effect_sizes(result: TTestResult, ref_mean: np.ndarray, alpha: float, n_tests: int) -> Effect:
    """Relative effect sizes with confidence intervals and the minimum detectable bias.

    The interval is the t interval of the difference of means divided by |reference mean| (the reference's own
    uncertainty in the denominator is ignored: it is of second order once the difference is small). The minimum
    detectable bias uses the Bonferroni level alpha / n_tests that a tile must reach to flag on its own.
    """
    scale = np.abs(ref_mean)
    with np.errstate(invalid="ignore", divide="ignore"):
        half = special.stdtrit(result.df, 1.0 - alpha / 2.0) * result.standard_error
        rel = result.mean_difference / scale
        level = alpha / max(n_tests, 1)
        detectable = (special.stdtrit(result.df, 1.0 - level / 2.0) + special.stdtrit(result.df, DETECTION_POWER)) * (
            result.standard_error / scale
        )
        low, high = rel - half / scale, rel + half / scale  # a zero reference mean gives inf/NaN, not a warning
    return Effect(rel, low, high, detectable)


def relative_interval(result: TTestResult, ref_mean: np.ndarray, level) -> tuple[np.ndarray, np.ndarray]:
    """The two-sided t interval of the relative difference (test - reference) / |reference| at error `level`
    per element (a scalar or an array broadcast against the result: a Bonferroni share, or the nominal level of
    a group-sequential boundary), with the t quantile at the element's own degrees of freedom.

    Elements without a p-value get NaN; a zero reference mean gives an infinite interval.
    """
    scale = np.abs(ref_mean)
    with np.errstate(invalid="ignore", divide="ignore"):
        half = special.stdtrit(result.df, 1.0 - np.asarray(level, dtype=float) / 2.0) * result.standard_error
        rel = result.mean_difference / scale
        return rel - half / scale, rel + half / scale
