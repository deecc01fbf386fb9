"""Compare two runs: the per-tile test, the diagnostics, the effect sizes and one verdict.

Verdicts: ``biased`` (the global p-value is at most alpha, or a tile differs deterministically), ``no_evidence``,
or ``inconclusive`` (nothing testable, or too many tiles whose Welch samples are clearly not normal for the
remaining ones to speak for the image).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .diagnostics import MIN_PASSES_FOR_NORMALITY, normality
from .effect import Effect, effect_sizes
from .errors import SeedOverlapError, WelchInputError, check_alpha
from .multitest import GlobalTest, combine_channels, global_test
from .tiles import TileStats
from .ttest import Reason, TTestResult, paired_from_stats, welch_from_stats
from .verdict import Verdict

__all__ = ["MAX_UNTRUSTED_SHARE", "TESTS", "Comparison", "compare", "seed_relation"]

TESTS = ("auto", "welch", "paired")

#: Above this share of untrusted tiles a run without significant trusted tiles is `inconclusive`, not
#: `no_evidence`: the untested part of the image is too large to speak for the whole.
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
    effect: Effect
    n_ref: int
    n_test: int
    width: int
    height: int
    tile: int

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


def compare(
    ref: TileStats,
    test: TileStats,
    alpha: float = 0.01,
    test_kind: str = "auto",
    pvalue_method: str = "exact",
) -> Comparison:
    """Test whether `test` converges to the same image as `ref`, per tile and as a whole.

    Parameters
    ----------
    ref, test : TileStats
        The two runs, on the same grid.
    alpha : float
        The false-positive rate of a `biased` verdict.
    test_kind : {"auto", "welch", "paired"}
        "auto" picks the paired test when both runs used the same seeds and Welch's test when they are disjoint.
    pvalue_method : {"exact", "gauss", "as_erf"}
        See `welch_core.ttest.two_sided_pvalue`.
    """
    alpha = check_alpha(alpha)
    ref.same_grid(test)
    relation = seed_relation(ref.seeds, test.seeds)
    kind = _choose_test(test_kind, relation, len(set(ref.seeds) & set(test.seeds)))
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
        suspect = normality(diffs).suspect
        checked = diffs.n >= MIN_PASSES_FOR_NORMALITY
    else:
        result = welch_from_stats(
            ref.mean, ref.variance, ref.n, test.mean, test.variance, test.n, pvalue_method=pvalue_method
        )
        suspect = normality(ref).suspect | normality(test).suspect
        checked = min(ref.n, test.n) >= MIN_PASSES_FOR_NORMALITY
    return _decide(ref, test, kind, pvalue_method, alpha, result, suspect, checked)


def _decide(ref, test, kind, pvalue_method, alpha, result, suspect, checked) -> Comparison:
    tile_p = combine_channels(result.pvalue)
    trusted = ~suspect.any(axis=-1)
    used = np.isfinite(tile_p) & trusted
    glob = global_test(np.where(used, tile_p, np.nan), alpha)
    effect = effect_sizes(result, ref.mean, alpha, int(used.sum()))
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
        test=kind,
        pvalue_method=pvalue_method,
        result=result,
        tile_pvalues=tile_p,
        trusted=trusted,
        normality_checked=checked,
        global_test=glob,
        effect=effect,
        n_ref=ref.n,
        n_test=test.n,
        width=ref.width,
        height=ref.height,
        tile=ref.tile,
    )
