"""Welch's unequal-variance t-test and the paired t-test, per tile and channel (paper §3).

The summary-statistics function `welch_from_stats` is the core (as scipy's `ttest_ind_from_stats`); the raw-sample
function `welch_ttest` and the tile statistics feed it. Degenerate tile-channels get NaN and a `Reason` code
instead of a p-value, with one rule for every caller.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .errors import WelchInputError

__all__ = [
    "PVALUE_METHODS",
    "Reason",
    "TTestResult",
    "paired_from_stats",
    "paired_ttest",
    "pvalue_as_erf",
    "pvalue_exact",
    "pvalue_gauss",
    "two_sided_pvalue",
    "welch_from_stats",
    "welch_ttest",
]

#: Where the Gaussian approximation may replace the t-distribution (paper §3.3 and §5.7: nu >= 20).
GAUSS_MIN_DF = 20.0

#: p-value methods: exact Student t; the paper's Gaussian (eq. 5) where nu >= GAUSS_MIN_DF; the same with the
#: Abramowitz-Stegun erf of eq. 6 (for comparison with the paper only).
PVALUE_METHODS = ("exact", "gauss", "as_erf")


class Reason(enum.IntEnum):
    """Why a tile-channel has no p-value. VALID tiles have one."""

    VALID = 0
    TOO_FEW_PASSES = 1  # n < 2 on a side: no variance estimate
    NON_FINITE = 2  # NaN or inf in a pass's tile sum
    ZERO_VARIANCE = 3  # both sides constant and equal (black background, constant emitter)
    DETERMINISTIC_DIFFERENCE = 4  # both sides constant but different: a difference no noise explains

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass(frozen=True)
class TTestResult:
    """Per-element result of a t-test. Excluded elements have NaN statistic, df and pvalue."""

    statistic: np.ndarray
    df: np.ndarray
    pvalue: np.ndarray
    reason: np.ndarray  # Reason codes, uint8
    mean_difference: np.ndarray  # second minus first (test minus reference)
    standard_error: np.ndarray


# -- p-values ----------------------------------------------------------------------------------------------


def pvalue_exact(t: npt.ArrayLike, df: npt.ArrayLike) -> np.ndarray:
    """Two-sided p of Student's t with real-valued `df` (eq. 4), full relative precision for tiny p.

    `stdtr(df, -|t|)` is the lower tail itself (an incomplete beta function), never 1 - cdf.
    """
    from scipy import special  # here: the names of this module are needed where scipy is not (a stock Blender)

    t, df = np.asarray(t, dtype=float), np.asarray(df, dtype=float)
    return 2.0 * special.stdtr(df, -np.abs(t))


def pvalue_gauss(t: npt.ArrayLike) -> np.ndarray:
    """Two-sided p of the standard normal, p_inf = erfc(|t| / sqrt 2) (eq. 5), computed without cancellation."""
    from scipy import special

    return special.erfc(np.abs(np.asarray(t, dtype=float)) / np.sqrt(2.0))


# Abramowitz & Stegun 7.1.25 (|error| <= 2.5e-5), quoted in the paper as eq. 6.
_AS_P, _AS_A = 0.47047, (0.3480242, -0.0958798, 0.7478556)


def pvalue_as_erf(t: npt.ArrayLike) -> np.ndarray:
    """The paper's p_inf with its Abramowitz-Stegun erf (eq. 6): for comparison only, not for decisions."""
    x = np.abs(np.asarray(t, dtype=float)) / np.sqrt(2.0)
    s = 1.0 / (1.0 + _AS_P * x)
    return (_AS_A[0] * s + _AS_A[1] * s**2 + _AS_A[2] * s**3) * np.exp(-(x**2))  # 1 - erf(x), eq. 6


def two_sided_pvalue(t: npt.ArrayLike, df: npt.ArrayLike, method: str = "exact") -> np.ndarray:
    """Two-sided p-value by `method` (see PVALUE_METHODS). The Gaussian forms apply only where df >= 20."""
    if method not in PVALUE_METHODS:
        raise WelchInputError(f"`pvalue_method` must be one of {PVALUE_METHODS}, got {method!r}")
    if method == "exact":
        return pvalue_exact(t, df)
    t, df = (np.array(a, dtype=float) for a in np.broadcast_arrays(np.asarray(t, dtype=float), np.asarray(df)))
    large = df >= GAUSS_MIN_DF  # paper §5.7: the approximation everywhere is not calibrated at small nu
    approx = pvalue_gauss if method == "gauss" else pvalue_as_erf
    p = np.empty(t.shape)
    p[large] = approx(t[large])  # the cheap form where it applies, the exact one only elsewhere
    p[~large] = pvalue_exact(t[~large], df[~large])
    return p


# -- tests -------------------------------------------------------------------------------------------------


def welch_from_stats(
    mean1: npt.ArrayLike,
    var1: npt.ArrayLike,
    n1: npt.ArrayLike,
    mean2: npt.ArrayLike,
    var2: npt.ArrayLike,
    n2: npt.ArrayLike,
    *,
    pvalue_method: str = "exact",
) -> TTestResult:
    """Welch's t-test from means, unbiased variances and counts, elementwise.

    Parameters
    ----------
    mean1, var1, n1 : array_like
        Sample mean, unbiased sample variance (ddof=1) and count of the first sample (the reference).
    mean2, var2, n2 : array_like
        The same for the second sample (the test).
    pvalue_method : {"exact", "gauss", "as_erf"}
        "exact" uses Student's t with real-valued nu everywhere. "gauss" uses the paper's Gaussian (eq. 5) where
        nu >= 20 and the exact p elsewhere; "as_erf" does the same with the paper's erf formula (eq. 6).

    Returns
    -------
    TTestResult
        t (eq. 1), the Welch-Satterthwaite nu as a real number (eq. 3) and the two-sided p (eq. 4). Elements
        with n < 2, non-finite input or zero variance on both sides get NaN and a `Reason` code.
    """
    m1, v1, c1, m2, v2, c2 = np.broadcast_arrays(
        *(np.asarray(a, dtype=float) for a in (mean1, var1, n1, mean2, var2, n2))
    )
    if (v1 < 0).any() or (v2 < 0).any():
        raise WelchInputError("variances must be >= 0, got a negative value")
    with np.errstate(divide="ignore", invalid="ignore"):
        se1, se2 = v1 / c1, v2 / c2
        se2_total = se1 + se2
        diff = m2 - m1
        t = -diff / np.sqrt(se2_total)  # eq. 1: (mean1 - mean2) / sqrt(S1²/N1 + S2²/N2)
        df = se2_total**2 / (se1**2 / (c1 - 1) + se2**2 / (c2 - 1))  # eq. 3, never rounded
    few = (c1 < 2) | (c2 < 2)
    return _finish(t, df, diff, np.sqrt(se2_total), few, (m1, v1, m2, v2), pvalue_method)


def welch_ttest(a: npt.ArrayLike, b: npt.ArrayLike, axis: int = 0, *, pvalue_method: str = "exact") -> TTestResult:
    """Welch's t-test on raw samples `a` (reference) and `b` (test) along `axis`; equals the summary path."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return welch_from_stats(*_summary(a, axis), *_summary(b, axis), pvalue_method=pvalue_method)


def paired_ttest(a: npt.ArrayLike, b: npt.ArrayLike, axis: int = 0, *, pvalue_method: str = "exact") -> TTestResult:
    """Paired t-test on per-pass differences along `axis` (the same seeds on both sides), df = N - 1.

    The statistic is mean(a - b) / SE like `welch_ttest`; `mean_difference` is mean(b - a), test minus reference.

    With common random numbers the noise shared by both sides cancels in the difference, so a small change of
    one setting is found with far fewer passes than by the unpaired test.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape:
        raise WelchInputError(f"paired samples must have the same shape, got {a.shape} and {b.shape}")
    return paired_from_stats(*_summary(b - a, axis), pvalue_method=pvalue_method)


def paired_from_stats(
    mean_diff: npt.ArrayLike, var_diff: npt.ArrayLike, n: npt.ArrayLike, *, pvalue_method: str = "exact"
) -> TTestResult:
    """The paired t-test from the mean, unbiased variance and count of the per-pass differences (test minus
    reference), elementwise; `paired_ttest` is this on raw samples."""
    mean, var, n = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (mean_diff, var_diff, n)))
    with np.errstate(divide="ignore", invalid="ignore"):
        se = np.sqrt(var / n)
        t = -mean / se  # mean(a - b) / se: the sign convention of welch_ttest and scipy's ttest_rel
        df = n - 1.0
    zero = np.zeros_like(mean)
    return _finish(t, df, mean, se, n < 2, (zero, zero, mean, var), pvalue_method)


def _summary(x: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = x.shape[axis]
    if not n:
        mean = np.full(np.delete(x.shape, axis), np.nan)
        return mean, np.full(mean.shape, np.nan), np.full(mean.shape, 0.0)
    # Shift by the first sample: constant samples then give exactly their value and zero variance (numpy's
    # mean of n equal values can be off by an ulp, which made a constant tile look like a valid test).
    shift = np.take(x, [0], axis=axis)
    d = x - shift
    mean = np.squeeze(shift, axis=axis) + d.mean(axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        var = d.var(axis=axis, ddof=1) if n > 1 else np.full(mean.shape, np.nan)
    return mean, var, np.full(mean.shape, float(n))


def _finish(t, df, diff, se, few, inputs, pvalue_method) -> TTestResult:
    """Apply the one rule for degenerate elements, then compute p where the test is defined."""
    m1, v1, m2, v2 = inputs
    reason = np.zeros(np.shape(t), dtype=np.uint8)
    finite = np.isfinite(m1) & np.isfinite(v1) & np.isfinite(m2) & np.isfinite(v2)
    constant = finite & (v1 == 0) & (v2 == 0)
    reason[constant & (m1 == m2)] = Reason.ZERO_VARIANCE
    reason[constant & (m1 != m2)] = Reason.DETERMINISTIC_DIFFERENCE
    reason[~finite] = Reason.NON_FINITE
    reason[few] = Reason.TOO_FEW_PASSES  # checked last: with n < 2 nothing else is known
    valid = reason == Reason.VALID
    t = np.where(valid, t, np.nan)
    df = np.where(valid, df, np.nan)
    p = np.full(t.shape, np.nan)
    p[valid] = two_sided_pvalue(t[valid], df[valid], pvalue_method)
    return TTestResult(t, df, p, reason, np.asarray(diff, dtype=float), np.asarray(se, dtype=float))
