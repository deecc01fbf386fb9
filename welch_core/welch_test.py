"""Welch's t-test of two runs with disjoint seeds, per tile and channel (paper §3): the paper's test."""

from __future__ import annotations

import dataclasses

import numpy as np

from .diagnostics import MIN_PASSES_FOR_NORMALITY
from .pixels import PixelMoments, pixel_welch
from .tile_test import ROUNDING, TileTest, TileTestMethod, side_checks, take_pixels
from .tiles import TileStats
from .ttest import Reason, TTestResult, welch_from_stats

__all__ = ["WelchTest"]


class WelchTest(TileTestMethod):
    """Welch's unequal-variance t-test of the two sides' tile sums (eq. 1-4), or of their pixels' variances
    where the runs allow it (`welch_core.pixels`)."""

    seeds = "disjoint"
    wrong_seeds = (
        "the runs use identical seeds, so their passes are not independent: the unpaired Welch test would be "
        "invalid; use the paired test"
    )

    def test(
        self, ref: TileStats, test: TileStats, pvalue_method: str = "exact", pixels: bool = False,
        pairs: PixelMoments | None = None,
    ) -> TileTest:  # fmt: skip
        """Welch's test per tile-channel. With `pixels`, each tile-channel whose pixel test has at least
        `pixels.MIN_PIXEL_DF` degrees of freedom takes that test's result (its variance from the pixels); while
        the normality of the tile sums can't be checked (fewer than `MIN_PASSES_FOR_NORMALITY` passes), one whose
        pixel test has fewer is not trusted: a few pixels carry its variance, so its tile sums are far from
        normal (a caustic), and Welch's t on 2-7 of them is not calibrated there (a glass caustic at 3 v 3
        passes: `biased` in 1.7 % of unbiased splits at alpha 1 %, every rejection such a tile's)."""
        ref_var, suspect, excess = side_checks(ref, test)
        result = welch_from_stats(
            ref.mean, ref.variance, ref.n, test.mean, test.variance, test.n, pvalue_method=pvalue_method
        )
        result = _rounding_is_no_difference(result, ref.mean)
        checked = min(ref.n, test.n) >= MIN_PASSES_FOR_NORMALITY
        if not pixels:
            return TileTest(self, result, suspect, checked, ref.mean, ref_var, -ref_var, excess=excess)
        result, use, few = take_pixels(result, pixel_welch(ref, test, pvalue_method))
        ref_var = np.where(use, ref.pixel_terms()[0] / ref.n, ref_var)
        suspect = suspect | (few & ~checked)
        return TileTest(self, result, suspect, checked, ref.mean, ref_var, -ref_var, pixel=use, excess=excess)

    def pixel_runs(self, ref: TileStats, test: TileStats, differences: TileStats | None) -> tuple:
        return ref, test

    def both_sides_grow(self, n_ref: int, n_test: int) -> bool:
        return n_ref == n_test

    def needs_resampling(self, n_ref: int, n_test: int) -> bool:
        """Between different pass counts (see `welch_core.permutation`)."""
        return n_ref != n_test

    def welch_tiles(self, tested: TileTest) -> bool:
        return True


def _rounding_is_no_difference(result: TTestResult, ref_mean: np.ndarray) -> TTestResult:
    """`result` with each deterministic difference (both sides constant) no larger than float rounding of the
    tile's value (`ROUNDING`) counted as no difference (ZERO_VARIANCE): it is the arithmetic's, not the light's,
    and would otherwise be `biased` at any size. (Paired passes: `paired_test.paired_differences` zeroes such a
    difference pass by pass.)"""
    with np.errstate(invalid="ignore"):
        rounding = (result.reason == Reason.DETERMINISTIC_DIFFERENCE) & (
            np.abs(result.mean_difference) <= ROUNDING * np.abs(ref_mean)
        )
    if not rounding.any():
        return result
    return dataclasses.replace(result, reason=np.where(rounding, Reason.ZERO_VARIANCE, result.reason).astype(np.uint8))
