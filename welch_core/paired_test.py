"""The paired t-test of two runs with the same seeds, on each seed's difference per tile and channel: with common
random numbers the noise both sides share cancels, so a small change of one setting shows in far fewer passes."""

from __future__ import annotations

import numpy as np

from .diagnostics import MIN_PASSES_FOR_NORMALITY, normality
from .errors import WelchInputError
from .pixels import PixelMoments, pixel_paired
from .tile_test import ROUNDING, TileTest, TileTestMethod, side_checks, take_pixels, where
from .tiles import TileStats, tile_row_blocks
from .ttest import paired_from_stats, welch_from_stats

__all__ = ["SPARSE_SHARE", "PairedTest", "paired_differences"]

#: Paired differences exactly zero in at least this share of the passes are "mostly exact zeros": a change that
#: alters a few light paths, its own case in the diagnostics (not fireflies), whichever test the tile gets.
SPARSE_SHARE = 0.5


class PairedTest(TileTestMethod):
    """The paired t-test of the per-seed differences' tile sums (df = N - 1), or of their pixels' variances where
    the runs keep each pixel's difference per seed (`pairs`). Where the differences are clearly not normal but
    each side's own samples are, Welch's test on the two sides instead (`welch_rule`, see `test`)."""

    seeds = "identical"
    wrong_seeds = "the paired test needs the same seeds on both sides, but the seed lists are disjoint"
    #: test the tile-channels whose differences are not normal by Welch's test on the sides (False: leave them
    #: untrusted, the paired test alone; what-if studies only)
    welch_rule = True

    def test(
        self, ref: TileStats, test: TileStats, pvalue_method: str = "exact", pixels: bool = False,
        pairs: PixelMoments | None = None,
    ) -> TileTest:  # fmt: skip
        """The paired test per tile-channel, with the normality check of the per-pass differences.

        Where the differences are clearly not normal but each side's own samples are (a change that alters a few
        light paths: differences exactly zero in most passes and large in a few), the tile-channel is tested by
        Welch's test on the two sides instead, as if their passes were independent. With the same seeds the
        sides are positively correlated, so Var(test) + Var(ref) overstates the variance of the difference and
        the test is conservative; it sees what an unpaired test sees, where the paired one would see nothing.
        Only where the sides' sample covariance is positive: with a negative one Welch's variance would
        understate it. `pixels`: as Welch's test (`welch_core.welch_test`), with `pairs`' moments."""
        ref_var, own, own_excess = side_checks(ref, test)
        diffs = paired_differences(ref, test, pairs)
        result = paired_from_stats(diffs.mean, diffs.variance, diffs.n, pvalue_method=pvalue_method)
        use = np.zeros(result.pvalue.shape, bool)
        few = np.zeros(result.pvalue.shape, bool)
        if pixels and diffs.pixels is not None:
            result, use, few = take_pixels(result, pixel_paired(diffs, pvalue_method))
        # cov(d, r) per pass from Var(test) = Var(ref) + Var(d) + 2 cov(d, r), over the passes' count
        with np.errstate(invalid="ignore", divide="ignore"):
            cross = (test.variance - ref.variance - diffs.variance) / (2.0 * diffs.n)
            sides = test.variance + ref.variance - diffs.variance  # 2 cov(test, ref) per pass
        of_diffs = normality(diffs)
        suspect, excess = of_diffs.suspect | (few & (diffs.n < MIN_PASSES_FOR_NORMALITY)), of_diffs.excess
        unpaired = suspect & ~own & (sides > 0) & self.welch_rule
        if unpaired.any():
            welch = welch_from_stats(
                ref.mean, ref.variance, ref.n, test.mean, test.variance, test.n, pvalue_method=pvalue_method
            )
            result = where(unpaired, welch, result)
            cross = np.where(unpaired, -ref_var, cross)
            suspect, excess = suspect & ~unpaired, np.where(unpaired, own_excess, excess)
        checked = diffs.n >= MIN_PASSES_FOR_NORMALITY
        sparse = (diffs.sums == 0).mean(axis=0) >= SPARSE_SHARE if diffs.n else np.zeros_like(suspect)
        pixel = use & ~unpaired if pixels else None
        return TileTest(self, result, suspect, checked, ref.mean, ref_var, cross, unpaired, sparse & checked, pixel,
                        excess)  # fmt: skip

    def differences(self, ref: TileStats, test: TileStats, pairs: PixelMoments | None) -> TileStats | None:
        """The per-seed differences with their pixel moments (None where the runs kept none)."""
        if pairs is None:
            return None
        if pairs.n != ref.n or pairs.shape != (ref.height, ref.width, ref.channels):
            raise WelchInputError(
                f"`pairs` must be the moments of the {ref.n} paired passes' differences, got {pairs.n}"
            )
        return paired_differences(ref, test, pairs)

    def pixel_runs(self, ref: TileStats, test: TileStats, differences: TileStats | None) -> tuple | str:
        if differences is None or differences.pixels is None:
            return "the paired runs' per-seed pixel differences were not kept"
        return (differences,)

    def both_sides_grow(self, n_ref: int, n_test: int) -> bool:
        return True

    def identical_passes(self, ref: TileStats, test: TileStats) -> bool:
        """Whether every pass of `test` equals the reference's pass of the same seed in every tile sum. Two runs
        with identical passes that were also made the same way (the same configuration) are one run compared
        with itself: refused, as that is a mistake and not evidence that two settings agree."""
        same = bool(np.array_equal(_in_reference_order(ref, test), ref.sums, equal_nan=True))
        if same and ref.info.identity() == test.info.identity():
            raise WelchInputError(
                "the two runs hold the same passes and were made the same way (a run compared with itself): "
                "compare it with a run rendered with other seeds or settings, or run selftest on it"
            )
        return same

    def welch_tiles(self, tested: TileTest) -> np.ndarray | bool:
        return tested.unpaired if tested.unpaired is not None else False


def paired_differences(ref: TileStats, test: TileStats, pairs: PixelMoments | None = None) -> TileStats:
    """The per-pass differences test - reference of two runs with the same seeds, in the reference's order, with
    `pairs`, the moments of each pixel's difference over those seeds, where given. A pass's difference no larger
    than float rounding of its tile sum (`ROUNDING`) is zero: passes that differ only in their last bits are the
    same passes, not a change that alters a few light paths."""
    differences = _in_reference_order(ref, test) - ref.sums
    for rows in tile_row_blocks(differences):  # a block at a time: no temporaries the size of the sums
        d = differences[:, rows]
        with np.errstate(invalid="ignore"):
            d[np.abs(d) <= ROUNDING * np.abs(ref.sums[:, rows])] = 0.0
    return TileStats.from_sums(
        differences, ref.seeds, ref.height, ref.width, ref.tile, edges=ref.edges, covered=ref.covered,
        pixels=pairs,
    )  # fmt: skip


def _in_reference_order(ref: TileStats, test: TileStats) -> np.ndarray:
    """`test`'s tile sums in the order of the reference's seeds."""
    if test.seeds == ref.seeds:
        return test.sums
    order = {seed: i for i, seed in enumerate(test.seeds)}
    return test.sums[[order[s] for s in ref.seeds]]
