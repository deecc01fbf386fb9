"""Compare two runs: the per-tile test at every tile scale, the diagnostics, the effect sizes and one verdict.

The stored tile size is the finest scale; coarser scales (2x, 4x, ... the stored tile, up to the image) come from
the stored per-pass sums without re-rendering. Each scale is tested on its own (tiles by Holm and a one-sided KS
test of uniformity, see `multitest`); the scales are combined by Bonferroni: the global p-value is the number of
scales times the smallest scale p-value. Bonferroni holds however strongly the scales depend on each other (a
coarse tile is the sum of finer ones), and with log2 of the image size scales it costs little. A small tile finds
a local bias, a large one a weak bias spread over the image; nobody has to know in advance which it is.

Verdicts: ``biased`` (the global p-value is at most alpha, or a tile differs deterministically); with a
tolerance, ``equivalent`` when at some scale every tested tile's simultaneous (1 - alpha) confidence interval of
the relative difference lies inside +-tolerance (two one-sided tests, Bonferroni over the tile-channels and the
scales); ``inconclusive`` when nothing is testable or too much of the image is testable at no scale (Welch
samples clearly not normal); else ``no_evidence``.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from .diagnostics import MIN_PASSES_FOR_NORMALITY, normality
from .effect import Effect, effect_sizes, relative_interval
from .errors import SeedOverlapError, WelchInputError, check_alpha
from .multitest import GlobalTest, combine_channels, global_test
from .tiles import TileStats
from .ttest import Reason, TTestResult, paired_from_stats, welch_from_stats
from .verdict import Verdict

__all__ = [
    "MAX_UNTRUSTED_SHARE",
    "TESTS",
    "Comparison",
    "Equivalence",
    "TileTest",
    "compare",
    "scale_factors",
    "seed_relation",
    "test_tiles",
]

TESTS = ("auto", "welch", "paired")

#: Above this share of the image untestable at every scale (the Welch samples of its tiles clearly not normal),
#: a run without significant tiles is `inconclusive`, not `no_evidence`: the untested part of the image is too
#: large to speak for the whole.
MAX_UNTRUSTED_SHARE = 0.25


def seed_relation(ref_seeds, test_seeds) -> str:
    """'disjoint', 'identical' (the same set of seeds) or 'overlap' (some shared, some not)."""
    a, b = set(ref_seeds), set(test_seeds)
    if not a or not b:
        raise WelchInputError("seed lists must not be empty")
    if a == b:
        return "identical"
    return "disjoint" if a.isdisjoint(b) else "overlap"


def _choose_test(requested: str, relation: str, shared: int) -> str:
    if requested not in TESTS:
        raise WelchInputError(f"`test_kind` must be one of {TESTS}, got {requested!r}")
    if relation == "overlap":
        raise SeedOverlapError(
            f"the runs share {shared} seeds but not all: the unpaired test needs disjoint seeds and the paired "
            "test identical ones; render one run again with a fitting seed range"
        )
    if requested == "welch" and relation == "identical":
        raise SeedOverlapError(
            "the runs use identical seeds, so their passes are not independent: the unpaired Welch test would be "
            "invalid; use the paired test"
        )
    if requested == "paired" and relation == "disjoint":
        raise SeedOverlapError("the paired test needs the same seeds on both sides, but the seed lists are disjoint")
    if requested == "auto":
        return "paired" if relation == "identical" else "welch"
    return requested


@dataclass(frozen=True, kw_only=True)
class Comparison:
    """Everything `compare` found, as statistics (the words for people are `batch.summary`'s).

    Arrays are (tiles_y, tiles_x[, channels]), row 0 at the top of the image.
    """

    verdict: Verdict
    alpha: float
    p_value: float  # the global p-value (0 for a deterministic difference, NaN when nothing is testable)
    test: str  # "welch" or "paired"
    pvalue_method: str
    result: TTestResult
    tile_pvalues: np.ndarray  # channels combined; NaN where no channel has a p-value
    trusted: np.ndarray  # tiles whose Welch samples pass the normality check (or were too few to check)
    normality_checked: bool  # False when a side has fewer than MIN_PASSES_FOR_NORMALITY passes
    global_test: GlobalTest
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
    equivalence: Equivalence | None = None

    @functools.cached_property
    def effect(self) -> Effect:
        """Relative differences with intervals and the minimum detectable bias (computed when first asked for:
        the t quantiles are most of a comparison's cost)."""
        return effect_sizes(self.result, self.ref_mean, self.alpha, int(self.used.sum()))

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
    def qvalues(self) -> np.ndarray:
        return self.global_test.qvalues

    @property
    def significant(self) -> np.ndarray:
        """Tiles significant after the family-wise (Holm) correction at alpha."""
        with np.errstate(invalid="ignore"):
            return self.global_test.adjusted <= self.alpha

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
            rows, cols = np.arange(ty) // f, np.arange(tx) // f
            inside = (rows[:, None] < scale.used.shape[0]) & (cols[None, :] < scale.used.shape[1])
            r, c = np.minimum(rows, scale.used.shape[0] - 1), np.minimum(cols, scale.used.shape[1] - 1)
            used = inside & scale.used[r[:, None], c[None, :]]
            sizes[used] = scale.tile
            pvalues[used] = scale.pvalues[r[:, None], c[None, :]][used]
        return sizes, pvalues


@dataclass(frozen=True)
class Equivalence:
    """Where the relative difference is bounded: per scale, the largest |bias| its simultaneous intervals rule
    out in every tested tile (inf where some tile of the scale can't be bounded), and the finest scale at which
    that bound is within the tolerance (None: at none)."""

    tolerance: float
    ruled_out: dict[int, float]  # tile size -> the largest relative bias not ruled out, max over tile-channels
    tile: int | None  # the finest tile size whose bound lies within the tolerance
    beyond: bool = False  # a significant tile-channel differs by more than the tolerance (see significant_beyond)

    @property
    def equivalent(self) -> bool:
        return self.tile is not None and not self.beyond

    @property
    def best(self) -> tuple[int, float] | None:
        """(tile size, bound) of the smallest bound over the scales, or None when no scale bounds every tile."""
        finite = [(bound, tile) for tile, bound in self.ruled_out.items() if np.isfinite(bound)]
        if not finite:
            return None
        bound, tile = min(finite)
        return tile, bound


@dataclass(frozen=True)
class TileTest:
    """The per-tile test of one scale before any decision: the t-test, which tiles are trusted, the means."""

    kind: str  # "welch" or "paired"
    result: TTestResult
    suspect: np.ndarray  # tile-channels whose Welch samples are clearly not normal
    checked: bool  # normality checked (enough passes)
    ref_mean: np.ndarray


def scale_factors(run: TileStats, tile: int | None = None) -> list[int]:
    """The factors of the stored tile that give the tested scales: 1, 2, 4, ... while a tile fits the image, or
    the one factor of `tile` (which must be a multiple of the stored tile that fits the image)."""
    if tile is not None:
        if isinstance(tile, bool) or not isinstance(tile, (int, np.integer)) or tile < 1 or tile % run.tile:
            raise WelchInputError(f"`tile` must be a multiple of the stored tile {run.tile}, got {tile!r}")
        if tile > min(run.height, run.width):
            raise WelchInputError(f"`tile` {tile} is larger than the image {run.width}x{run.height}")
        return [tile // run.tile]
    factors, f = [], 1
    while run.tile * f <= min(run.height, run.width):
        factors.append(f)
        f *= 2
    return factors


def test_tiles(ref: TileStats, test: TileStats, kind: str, pvalue_method: str = "exact") -> TileTest:
    """Welch's test (disjoint seeds) or the paired test (identical seeds) per tile and channel, with the
    normality check of the Welch samples (of each side, or of the per-pass differences)."""
    if kind == "paired":
        if test.seeds == ref.seeds:
            test_sums = test.sums
        else:
            order = {seed: i for i, seed in enumerate(test.seeds)}
            test_sums = test.sums[[order[s] for s in ref.seeds]]
        differences = test_sums - ref.sums
        if not np.count_nonzero(differences):  # no temporaries, unlike array_equal
            raise WelchInputError(
                "the two runs hold the same passes (a run compared with itself): compare it with a run rendered "
                "with other seeds or settings, or run selftest on it"
            )
        diffs = TileStats.from_sums(differences, ref.seeds, ref.height, ref.width, ref.tile)
        result = paired_from_stats(diffs.mean, diffs.variance, diffs.n, pvalue_method=pvalue_method)
        return TileTest(kind, result, normality(diffs).suspect, diffs.n >= MIN_PASSES_FOR_NORMALITY, ref.mean)
    result = welch_from_stats(
        ref.mean, ref.variance, ref.n, test.mean, test.variance, test.n, pvalue_method=pvalue_method
    )
    suspect = normality(ref).suspect | normality(test).suspect
    return TileTest(kind, result, suspect, min(ref.n, test.n) >= MIN_PASSES_FOR_NORMALITY, ref.mean)


def compare(
    ref: TileStats,
    test: TileStats,
    alpha: float = 0.01,
    test_kind: str = "auto",
    pvalue_method: str = "exact",
    tile: int | None = None,
    tolerance: float | None = None,
) -> Comparison:
    """Test whether `test` converges to the same image as `ref`, per tile at every scale and as a whole.

    Parameters
    ----------
    ref, test : TileStats
        The two runs, on the same grid.
    alpha : float
        The false-positive rate of a `biased` verdict (and of an `equivalent` one when the true difference is at
        the tolerance).
    test_kind : {"auto", "welch", "paired"}
        "auto" picks the paired test when both runs used the same seeds and Welch's test when they are disjoint.
    pvalue_method : {"exact", "gauss", "as_erf"}
        See `welch_core.ttest.two_sided_pvalue`.
    tile : int, optional
        Test only this tile size (a multiple of the stored tile); default: every scale.
    tolerance : float, optional
        Relative tolerance (0.005 for 0.5 %): enables the `equivalent` verdict.

    Returns
    -------
    Comparison
        The finest scale's per-tile results, with the verdict and the global p-value of all scales, the scales
        themselves (`scales`), the base tiles no scale could test (`uncovered`) and the equivalence assessment.
    """
    alpha = check_alpha(alpha)
    if tolerance is not None and not (isinstance(tolerance, (int, float)) and 0 < tolerance < 10):
        raise WelchInputError(f"`tolerance` must be a relative difference in (0, 10), got {tolerance!r}")
    ref.same_grid(test)
    kind = choose_test(ref, test, test_kind)
    scales, tests, uncovered = assess_scales(ref, test, kind, pvalue_method, alpha, tile)
    finest = scales[0]
    relevant = ~(finest.reasons == Reason.ZERO_VARIANCE).all(axis=-1)
    p_values = [s.p_value for s in scales if np.isfinite(s.p_value)]
    p_value = min(1.0, len(scales) * min(p_values)) if p_values else float("nan")  # Bonferroni over the scales
    equivalence = None
    if tolerance is not None:
        levels = [alpha / (len(scales) * s.pvalues.size) for s in scales]
        equivalence = bound_differences(scales, tests, levels, uncovered, float(tolerance))
    if equivalence is not None and equivalence.equivalent:
        significant = [s.significant[..., None] & (s.reasons == Reason.VALID) for s in scales]
        if significant_beyond(significant, tests, float(tolerance)):
            equivalence = dataclasses.replace(equivalence, beyond=True)
    if any(s.n_deterministic for s in scales):
        verdict, p_value = Verdict.BIASED, 0.0
    elif equivalence is not None and equivalence.equivalent and uncovered.sum() <= MAX_UNTRUSTED_SHARE * relevant.sum():
        verdict = Verdict.EQUIVALENT  # a difference, significant or not, that the intervals bound within tolerance
    elif p_values and p_value <= alpha:
        verdict = Verdict.BIASED
    elif not any(s.used.any() for s in scales) or uncovered.sum() > MAX_UNTRUSTED_SHARE * relevant.sum():
        verdict = Verdict.INCONCLUSIVE
    else:
        verdict = Verdict.NO_EVIDENCE
    return dataclasses.replace(
        finest, verdict=verdict, p_value=p_value, scales=scales, uncovered=uncovered, equivalence=equivalence
    )


def assess_scales(ref: TileStats, test: TileStats, kind: str, pvalue_method: str, alpha: float, tile=None):
    """Every scale tested and judged on its own: (the scales' comparisons, their tile tests, the finest tiles no
    scale can test). `compare` combines them into one verdict; the group-sequential `looks` use them too."""
    tests, scales = [], []
    a, b, done = ref, test, 1
    for f in scale_factors(ref, tile):  # one scale at a time: only the previous scale's sums are kept
        if f != done:  # each scale from the one before (factors 1, 2, 4, ...): a quarter of the sums to add
            a, b, done = a.retile(f // done), b.retile(f // done), f
        tests.append(test_tiles(a, b, kind, pvalue_method))
        scales.append(_decide(a, b, tests[-1], pvalue_method, alpha))
    return tuple(scales), tests, _uncovered(scales[0], scales)


def choose_test(ref: TileStats, test: TileStats, test_kind: str = "auto") -> str:
    """ "welch" or "paired" for these runs' seeds (see `compare`); raises when the seeds fit neither."""
    relation = seed_relation(ref.seeds, test.seeds)
    return _choose_test(test_kind, relation, len(set(ref.seeds) & set(test.seeds)))


def _decide(ref, test, tested: TileTest, pvalue_method, alpha) -> Comparison:
    """One scale's verdict: its tiles by Holm and the KS test of uniformity (see `multitest`)."""
    result, suspect = tested.result, tested.suspect
    tile_p = combine_channels(result.pvalue)
    trusted = ~suspect.any(axis=-1)
    used = np.isfinite(tile_p) & trusted
    glob = global_test(np.where(used, tile_p, np.nan), alpha)
    untrusted = int((np.isfinite(tile_p) & ~trusted).sum())
    p_value = glob.pvalue
    if (result.reason == Reason.DETERMINISTIC_DIFFERENCE).any():
        verdict, p_value = Verdict.BIASED, 0.0
    elif not used.any():
        verdict = Verdict.INCONCLUSIVE
    elif glob.rejected:
        verdict = Verdict.BIASED
    elif untrusted > MAX_UNTRUSTED_SHARE * np.isfinite(tile_p).sum():
        verdict = Verdict.INCONCLUSIVE
    else:
        verdict = Verdict.NO_EVIDENCE
    return Comparison(
        verdict=verdict,
        alpha=alpha,
        p_value=p_value,
        test=tested.kind,
        pvalue_method=pvalue_method,
        result=result,
        tile_pvalues=tile_p,
        trusted=trusted,
        normality_checked=tested.checked,
        global_test=glob,
        ref_mean=ref.mean,
        n_ref=ref.n,
        n_test=test.n,
        width=ref.width,
        height=ref.height,
        tile=ref.tile,
    )


def _covering(finest: Comparison, scale: Comparison, values: np.ndarray, fill) -> np.ndarray:
    """`values` of a scale's tiles at the finest grid: each finest tile gets its covering tile's value (`fill`
    where the scale's grid, which drops incomplete tiles, does not reach)."""
    ty, tx = finest.tile_pvalues.shape
    f = scale.tile // finest.tile
    rows, cols = np.arange(ty) // f, np.arange(tx) // f
    inside = (rows[:, None] < values.shape[0]) & (cols[None, :] < values.shape[1])
    r, c = np.minimum(rows, values.shape[0] - 1), np.minimum(cols, values.shape[1] - 1)
    return np.where(inside, values[r[:, None], c[None, :]], fill)


def _uncovered(finest: Comparison, scales) -> np.ndarray:
    """Finest tiles that no scale tests (used: testable and trusted), among those not constant on both sides."""
    covered = np.zeros(finest.tile_pvalues.shape, dtype=bool)
    for scale in scales:
        covered |= _covering(finest, scale, scale.used, False)
    relevant = ~(finest.reasons == Reason.ZERO_VARIANCE).all(axis=-1)
    return relevant & ~covered


def significant_beyond(significant: list[np.ndarray], tests: list[TileTest], tolerance: float) -> bool:
    """Whether a tile-channel found significant at some scale (`significant`: a mask per scale) differs by more
    than `tolerance` by its estimate. Such a tile rules `equivalent` out: a coarser scale's bound on a region's
    mean would otherwise hide a local bias several times the tolerance (a +5 % tile under a 64-tile region
    bounded within 1 %)."""
    for mask, tested in zip(significant, tests, strict=True):
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.abs(tested.result.mean_difference / np.abs(tested.ref_mean))
        if np.any(mask & (rel > tolerance)):
            return True
    return False


def bound_differences(scales, tests, levels, uncovered: np.ndarray, tolerance: float) -> Equivalence:
    """Per scale, the largest relative bias its simultaneous intervals leave open over the tiles it must cover:
    every tile whose region some scale can test, bar constant ones (whose difference is known to be zero).
    `levels` are the per-tile-channel error levels of each scale's intervals (a Bonferroni share, or the nominal
    level of a group-sequential boundary)."""
    finest = scales[0]
    ruled_out = {}
    for scale, tested, level in zip(scales, tests, levels, strict=True):
        low, high = relative_interval(tested.result, tested.ref_mean, level)
        bound = np.maximum(np.abs(low), np.abs(high))
        equal = scale.reasons == Reason.ZERO_VARIANCE
        used = scale.used[..., None] & (scale.reasons == Reason.VALID)
        bounds = np.where(used, bound, np.where(equal, 0.0, np.inf))
        per_tile = np.nanmax(np.where(np.isnan(bounds), np.inf, bounds), axis=-1)
        # Tiles this scale must bound: those whose region is testable somewhere; its grid must reach them all.
        needed = _covering(finest, scale, per_tile, np.inf)
        needed = np.where(uncovered, 0.0, needed)
        ruled_out[scale.tile] = float(needed.max()) if (~uncovered).any() else float("inf")
    within = [tile for tile, bound in ruled_out.items() if bound <= tolerance]
    return Equivalence(tolerance, ruled_out, min(within) if within else None)
