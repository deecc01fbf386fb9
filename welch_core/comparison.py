"""Compare two runs: the per-tile test at every tile scale, the diagnostics, the effect sizes and one verdict.

The stored tile size is the finest scale; coarser scales (2x, 4x, ... the stored tile, up to the image) come from
the stored per-pass sums without re-rendering. Each scale is tested on its own (tiles by Holm and a one-sided KS
test of uniformity, see `multitest`); the scales are combined by Bonferroni: the global p-value is the number of
scales times the smallest scale p-value. Bonferroni holds however strongly the scales depend on each other (a
coarse tile is the sum of finer ones), and with log2 of the image size scales it costs little. A small tile finds
a local bias, a large one a weak bias spread over the image; nobody has to know in advance which it is.

The verdict and its numbers are decided in `welch_core.decision` (the same rules serve the looks of a run that
renders until decided); this module makes the per-tile statistics they rest on.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from .decision import Evidence, Outcome, decide, equivalence_alpha
from .diagnostics import split_halves
from .effect import Effect, effect_sizes
from .errors import WelchInputError, check_alpha
from .multitest import GlobalTest, bonferroni, bonferroni_p, combine_channels, global_test
from .permutation import permutation_max_t
from .pixels import PixelMoments, PixelUse, pixel_use
from .tile_test import TileTest, TileTestMethod
from .tile_tests import TileTestKind, choose_test
from .tiles import TileStats
from .ttest import Reason, TTestResult
from .verdict import Verdict

__all__ = [
    "Comparison",
    "ScaleTests",
    "assess_scales",
    "compare",
    "pixel_share",
    "scale_factors",
    "scale_tests",
    "selftest",
]


@dataclass(frozen=True, kw_only=True)
class Comparison:
    """Per-tile statistics of a comparison, at one scale or (the top level `compare` returns) at every scale with
    the `outcome`: the verdict and its numbers (`welch_core.decision`), which is what people are shown.

    Arrays are (tiles_y, tiles_x[, channels]), row 0 at the top of the image.
    """

    alpha: float
    p_value: float  # this scale's p-value (at the top level the global one; 0 for a deterministic difference)
    test: TileTestKind
    pvalue_method: str
    result: TTestResult
    tile_pvalues: np.ndarray  # channels combined; NaN where no channel has a p-value
    trusted: np.ndarray  # tiles whose Welch samples pass the normality check (or were too few to check)
    normality_checked: bool  # False when a side has fewer than MIN_PASSES_FOR_NORMALITY passes
    global_test: GlobalTest
    significant: np.ndarray  # tiles found significant by the `biased` test of the whole family (see `compare`)
    ref_mean: np.ndarray  # the reference's tile means, the scale of relative differences
    n_ref: int
    n_test: int
    width: int
    height: int
    tile: int
    #: every scale tested, finest (this one's own) first; empty for the single-scale entries themselves
    scales: tuple[Comparison, ...] = ()
    #: base tiles that could be tested at no scale (all-constant tiles excluded); None for a single scale
    uncovered: np.ndarray | None = None
    outcome: Outcome | None = None
    tested: TileTest | None = None  # the tile test this scale's statistics come from
    pixel_use: PixelUse | None = None  # whether tiles were tested by their pixel variances, and why

    @property
    def verdict(self) -> Verdict:
        return self.outcome.verdict

    @functools.cached_property
    def effect(self) -> Effect:
        """Relative differences with pointwise intervals and the minimum detectable bias, per tile-channel, for
        the map (computed when first asked for: the t quantiles are most of a comparison's cost)."""
        return effect_sizes(self.tested, self.alpha, int(self.used.sum()))

    @property
    def pvalues(self) -> np.ndarray:
        return self.result.pvalue

    @property
    def reasons(self) -> np.ndarray:
        return self.result.reason

    @property
    def used(self) -> np.ndarray:
        """Tiles that enter the verdict: testable and trusted."""
        return np.isfinite(self.tile_pvalues) & self.trusted

    @property
    def adjusted_pvalues(self) -> np.ndarray:
        """Each tile's p adjusted over the fixed design's family of `biased` (Holm within this scale, Bonferroni
        over both sides of the interval and the scales): what is compared with alpha itself."""
        return bonferroni_p(self.global_test.adjusted, 2, max(len(self.scales), 1))

    @property
    def qvalues(self) -> np.ndarray:
        return self.global_test.qvalues

    @property
    def n_valid(self) -> int:
        """Tiles with a p-value in at least one channel."""
        return int(np.isfinite(self.tile_pvalues).sum())

    @property
    def n_untrusted(self) -> int:
        """Valid tiles left out because their Welch samples are clearly not normal."""
        return int((np.isfinite(self.tile_pvalues) & ~self.trusted).sum())

    @property
    def n_deterministic(self) -> int:
        """Tile-channels constant on both sides but different."""
        return int((self.reasons == Reason.DETERMINISTIC_DIFFERENCE).sum())

    @property
    def reason_counts(self) -> dict[str, int]:
        """Tile-channels per reason (valid included)."""
        return {r.label: int((self.reasons == r).sum()) for r in Reason}

    def region_scales(self) -> tuple[np.ndarray, np.ndarray]:
        """Per tile of this (the finest) grid: the tile size of the finest scale whose tile covering it is tested
        (0 where none is), and that tile's p-values per channel (NaN where none). What the map shows."""
        ty, tx = self.tile_pvalues.shape
        sizes = np.zeros((ty, tx), dtype=int)
        pvalues = np.full((ty, tx, self.pvalues.shape[-1]), np.nan)
        for scale in reversed(self.scales or (self,)):  # coarsest first: finer scales overwrite
            f = scale.tile // self.tile
            r, c = np.arange(ty) // f, np.arange(tx) // f
            used = scale.used[r[:, None], c[None, :]]
            sizes[used] = scale.tile
            pvalues[used] = scale.pvalues[r[:, None], c[None, :]][used]
        return sizes, pvalues


def scale_factors(run: TileStats, tile: int | None = None) -> list[int]:
    """The factors of the stored tile that give the tested scales: 1, 2, 4, ... up to the one whose single tile
    covers the whole image (the tiles at the right and bottom edges partial where a factor does not divide the
    grid), or the one factor of `tile` (a multiple of the stored tile, at most the image's longer side)."""
    if tile is not None:
        if isinstance(tile, bool) or not isinstance(tile, (int, np.integer)) or tile < 1 or tile % run.tile:
            raise WelchInputError(f"`tile` must be a multiple of the stored tile {run.tile}, got {tile!r}")
        if tile > max(run.height, run.width):
            raise WelchInputError(f"`tile` {tile} is larger than the image {run.width}x{run.height}")
        return [tile // run.tile]
    factors, f = [1], 1
    while max(run.tiles_y, run.tiles_x) > f:
        f *= 2
        factors.append(f)
    return factors


#: The smallest tolerance: a claim within less than ten times float rounding would rest on differences it counts
#: as none.
MIN_TOLERANCE = 1e-5


def compare(
    ref: TileStats,
    test: TileStats,
    alpha: float = 0.01,
    test_kind: str = "auto",
    pvalue_method: str = "exact",
    tile: int | None = None,
    tolerance: float | None = None,
    equivalence_tile: int | None = None,
    pixel_variance: str = "off",
    pairs: PixelMoments | None = None,
) -> Comparison:
    """Test whether `test` converges to the same image as `ref`, per tile at every scale and as a whole.

    Parameters
    ----------
    ref, test : TileStats
        The two runs, on the same grid.
    alpha : float
        The false-positive rate of a `biased` verdict, and of an `equivalent` one (see `welch_core.decision`).
    test_kind : {"auto", "welch", "paired"}
        "auto" picks the paired test when both runs used the same seeds and Welch's test when they are disjoint.
    pvalue_method : {"exact", "gauss", "as_erf"}
        See `welch_core.ttest.two_sided_pvalue`.
    tile : int, optional
        Test only this tile size (a multiple of the stored tile); default: every scale.
    tolerance : float, optional
        Relative tolerance (0.005 for 0.5 %): enables the `equivalent` verdict, which then says that every tile
        of the finest tested scale is within it.
    equivalence_tile : int, optional
        Claim `equivalent` at this coarser tile size instead (one of the tested scales).
    pixel_variance : {"off", "auto", "on"}
        Test tiles by their pixels' variances where the runs allow it (`welch_core.pixels`): "auto" where their
        records prove independent pixels, "on" where the user vouches for the renderer.
    pairs : PixelMoments, optional
        Paired runs: the moments of each pixel's difference test - reference over the seeds (the pixel test of
        paired runs needs them; neither run's own moments hold them).

    Returns
    -------
    Comparison
        The finest scale's per-tile results, the scales themselves (`scales`), the base tiles no scale could test
        (`uncovered`) and the `outcome`: the verdict and every number that goes with it.

    The per-scale p-values are Holm's test over the tiles and a one-sided KS test of uniformity, Bonferroni-
    combined; the global p-value is the number of scales times the smallest. A tile is `significant` when its
    Holm-adjusted p alone brings the global p-value to alpha (adjusted p x 2 x scales <= alpha), so a tile is
    outlined only where the verdict is `biased`.
    """
    alpha = check_alpha(alpha)
    tolerance = check_tolerance(tolerance)
    start = scale_tests(ref, test, alpha, test_kind, pvalue_method, tile, pixel_variance, pairs)
    scales, tests, runs = start.scales, start.tests, start.runs
    claim = check_claim_tile(equivalence_tile, scales, tolerance)
    count = len(scales)
    with np.errstate(invalid="ignore"):
        found = [(s.global_test.adjusted <= bonferroni(alpha, 2, count))[..., None] & (s.reasons == Reason.VALID)
                 for s in scales]  # fmt: skip
    p_values = [s.p_value for s in scales if np.isfinite(s.p_value)]
    p_value = bonferroni_p(min(p_values), count) if p_values else float("nan")
    resampling = None
    if start.method.needs_resampling(ref.n, test.n):
        # Different pass counts: `biased` needs the permutation test too (an intersection of two rejections), and
        # a tile-channel is significant where both families reject it.
        resampling = permutation_max_t(runs, alpha)
        with np.errstate(invalid="ignore"):
            found = [sig & (adjusted <= alpha) for sig, adjusted in zip(found, resampling.adjusted, strict=True)]
        p_value = max(p_value, resampling.p_value)
    scales = tuple(dataclasses.replace(s, significant=sig.any(axis=-1)) for s, sig in zip(scales, found, strict=True))
    evidence = Evidence(
        design="fixed",
        significant=found,
        simultaneous=[bonferroni(alpha, 2, count, s.pvalues.size) for s in scales],
        equivalence=equivalence_alpha(alpha),
        whole=alpha,
        p_value=p_value,
        resampling=resampling,
    )
    outcome = decide(scales, tests, runs, evidence, alpha, tolerance, claim, start.identical, start.whole,
                     start.uncovered)  # fmt: skip
    finest = scales[0]
    if outcome.deterministic:
        p_value = 0.0
    use = pixel_share(start.pixel_use, tests)
    return dataclasses.replace(
        finest, p_value=p_value, scales=scales, uncovered=start.uncovered, outcome=outcome, pixel_use=use
    )


def pixel_share(use: PixelUse, tests) -> PixelUse:
    """`use` with the share of the valid tile-channels of every scale (`tests`) that the pixel test decided."""
    decided = [(t.pixel[t.result.reason == Reason.VALID]) for t in tests if t.pixel is not None]
    valid = np.concatenate(decided) if decided else np.zeros(0, bool)
    return dataclasses.replace(use, share=float(valid.mean()) if valid.size else 0.0)


def selftest(ref: TileStats, alpha: float = 0.01) -> Comparison | None:
    """The paper's advice (§6): test the reference against itself first. Its two halves (alternate passes)
    compared by Welch's test at the stored tile size only (the finest tiles are where a miscalibration shows
    first, at half the cost); None when the reference has fewer than 4 passes. Anything but `no evidence of bias`
    is a reason to doubt a verdict against it."""
    if ref.n < 4:
        return None
    return compare(*split_halves(ref), alpha=alpha, test_kind=TileTestKind.WELCH, tile=ref.tile)


def check_tolerance(tolerance) -> float | None:
    if tolerance is None:
        return None
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not MIN_TOLERANCE <= tolerance < 10:
        raise WelchInputError(
            f"`tolerance` must be a relative difference in [{MIN_TOLERANCE:g}, 10) (less is float rounding), got "
            f"{tolerance!r}"
        )
    return float(tolerance)


def check_claim_tile(equivalence_tile, scales, tolerance) -> int | None:
    """The tile size an `equivalent` speaks of: the finest tested one unless a coarser one is asked for."""
    if equivalence_tile is None:
        return scales[0].tile if tolerance is not None else None
    if tolerance is None:
        raise WelchInputError("`equivalence_tile` needs a `tolerance`")
    sizes = [s.tile for s in scales]
    if equivalence_tile not in sizes:
        raise WelchInputError(
            f"`equivalence_tile` must be one of the tested tile sizes {sizes}, got {equivalence_tile!r}"
        )
    return int(equivalence_tile)


@dataclass(frozen=True)
class ScaleTests:
    """What `compare` and a look of a check (`welch_core.looks.sequential_look`) both start from: the tile test
    their seeds call for (`method`), whether every pass is identical on both sides, where the pixel test is used,
    every scale's comparison, tile test and runs, the finest tiles no scale tests, and the whole image's test."""

    method: TileTestMethod
    identical: bool
    pixel_use: PixelUse
    scales: tuple
    tests: list
    runs: list
    uncovered: np.ndarray
    whole: TileTest


def scale_tests(
    ref: TileStats, test: TileStats, alpha: float, test_kind: str = "auto", pvalue_method: str = "exact",
    tile: int | None = None, pixel_variance: str = "off", pairs: PixelMoments | None = None,
) -> ScaleTests:  # fmt: skip
    """The runs tested at every scale (see `compare` for the arguments): the one start of every decision."""
    ref.same_grid(test)
    method = choose_test(ref, test, test_kind)
    identical = method.identical_passes(ref, test)
    use = pixel_use(ref, test, method, pixel_variance, method.differences(ref, test, pairs))
    scales, tests, runs, uncovered = assess_scales(ref, test, method, pvalue_method, alpha, tile, use.used, pairs)
    whole = method.test(ref.whole(), test.whole(), pvalue_method)
    return ScaleTests(method, identical, use, scales, tests, runs, uncovered, whole)


def assess_scales(
    ref: TileStats, test: TileStats, method: TileTestMethod, pvalue_method: str, alpha: float, tile=None,
    pixels: bool = False, pairs: PixelMoments | None = None,
):  # fmt: skip
    """Every scale tested on its own: (the scales' comparisons, their tile tests, their (reference, test) runs,
    the finest tiles no scale can test). `compare` and the looks decide from them; `pixels`: see
    `TileTestMethod.test`."""
    tests, scales, runs = [], [], []
    a, b, done = ref, test, 1
    for f in scale_factors(ref, tile):  # one scale at a time from the one before (factors 1, 2, 4, ...)
        if f != done:
            a, b, done = a.retile(f // done), b.retile(f // done), f
        runs.append((a, b))
        tests.append(method.test(a, b, pvalue_method, pixels, pairs))
        scales.append(_scale(a, b, tests[-1], pvalue_method, alpha))
    return tuple(scales), tests, runs, _uncovered(scales[0], scales)


def _scale(ref, test, tested: TileTest, pvalue_method, alpha) -> Comparison:
    """One scale's statistics: its tiles by Holm and the KS test of uniformity (see `multitest`)."""
    result, suspect = tested.result, tested.suspect
    tile_p = combine_channels(result.pvalue)
    trusted = ~suspect.any(axis=-1)
    used = np.isfinite(tile_p) & trusted
    glob = global_test(np.where(used, tile_p, np.nan), alpha)
    return Comparison(
        alpha=alpha,
        p_value=glob.pvalue,
        test=tested.kind,
        pvalue_method=pvalue_method,
        result=result,
        tile_pvalues=tile_p,
        trusted=trusted,
        normality_checked=tested.checked,
        global_test=glob,
        significant=np.zeros(tile_p.shape, bool),
        ref_mean=ref.mean,
        tested=tested,
        n_ref=ref.n,
        n_test=test.n,
        width=ref.width,
        height=ref.height,
        tile=ref.tile,
    )


def covering(finest: Comparison, scale: Comparison, values: np.ndarray) -> np.ndarray:
    """`values` of a scale's tiles at the finest grid: each finest tile gets its covering tile's value (every
    finest tile has one: the coarse grids cover what the finest does)."""
    ty, tx = finest.tile_pvalues.shape
    f = scale.tile // finest.tile
    r, c = np.arange(ty) // f, np.arange(tx) // f
    return values[r[:, None], c[None, :]]


def _uncovered(finest: Comparison, scales) -> np.ndarray:
    """Finest tiles that no scale tests (used: testable and trusted), among those not constant on both sides."""
    covered = np.zeros(finest.tile_pvalues.shape, dtype=bool)
    for scale in scales:
        covered |= covering(finest, scale, scale.used)
    relevant = ~(finest.reasons == Reason.ZERO_VARIANCE).all(axis=-1)
    return relevant & ~covered
