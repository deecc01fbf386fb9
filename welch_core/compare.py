"""Compare two runs: the per-tile test, the diagnostics, the effect sizes and one verdict.

Verdicts: ``biased`` (the global p-value is at most alpha, or a tile differs deterministically), ``no_evidence``,
or ``inconclusive`` (nothing testable, or too many tiles whose Welch samples are clearly not normal for the
remaining ones to speak for the image).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .diagnostics import MIN_PASSES_FOR_NORMALITY, normality
from .effect import Effect, effect_sizes
from .errors import SeedOverlapError, WelchInputError, check_alpha
from .multitest import GlobalTest, combine_channels, global_test
from .tiles import RunInfo, TileStats
from .ttest import Reason, TTestResult, paired_ttest, welch_from_stats

__all__ = ["MAX_UNTRUSTED_SHARE", "TESTS", "Comparison", "compare", "info_differences", "seed_relation"]

TESTS = ("auto", "welch", "paired")

#: Above this share of untrusted tiles a run without significant trusted tiles is `inconclusive`, not
#: `no_evidence`: the untested part of the image is too large to speak for the whole.
MAX_UNTRUSTED_SHARE = 0.25

#: How many of the most significant tiles the report lists.
TOP_TILES = 10


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


@dataclass(frozen=True)
class Comparison:
    """Everything `compare` found. Arrays are (tiles_y, tiles_x[, channels]), row 0 at the top of the image."""

    verdict: str
    alpha: float
    p_value: float
    test: str
    pvalue_method: str
    result: TTestResult
    tile_pvalues: np.ndarray  # channels combined; NaN where no channel has a p-value
    trusted: np.ndarray  # tiles whose Welch samples pass the normality check (or were too few to check)
    global_test: GlobalTest
    effect: Effect
    n_ref: int
    n_test: int
    width: int
    height: int
    tile: int
    notes: tuple[str, ...]

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
        return int(np.isfinite(self.tile_pvalues).sum())

    @property
    def reason_counts(self) -> dict[str, int]:
        """Tile-channels per reason (valid included)."""
        return {r.label: int((self.reasons == r).sum()) for r in Reason}

    @property
    def method(self) -> str:
        name = "paired t-test on per-pass differences" if self.test == "paired" else "Welch's t-test"
        return (
            f"{name} per {self.tile}x{self.tile} tile and channel (p: {self.pvalue_method}); channels combined by "
            "Bonferroni; tiles by Holm and a one-sided Kolmogorov-Smirnov test of uniformity, Bonferroni-combined"
        )

    @property
    def top_tiles(self) -> list[dict[str, Any]]:
        """The most significant tiles with their effect sizes (the channel with the smallest p)."""
        flat = np.where(np.isfinite(self.tile_pvalues), self.tile_pvalues, np.inf).ravel()
        order = np.argsort(flat, kind="stable")[: min(TOP_TILES, self.n_valid)]
        tiles = []
        for index in order:
            row, col = np.unravel_index(index, self.tile_pvalues.shape)
            p = self.pvalues[row, col]
            ch = int(np.nanargmin(p))
            tiles.append(
                {
                    "row": int(row),
                    "col": int(col),
                    "x": int(col * self.tile),
                    "y": int(row * self.tile),
                    "size": self.tile,
                    "pvalue": _num(self.tile_pvalues[row, col]),
                    "adjusted_pvalue": _num(self.global_test.adjusted[row, col]),
                    "qvalue": _num(self.qvalues[row, col]),
                    "significant": bool(self.significant[row, col]),
                    "trusted": bool(self.trusted[row, col]),
                    "channel": "RGB"[ch] if self.pvalues.shape[-1] == 3 else ch,
                    "rel_diff": _num(self.effect.rel_diff[row, col, ch]),
                    "ci_low": _num(self.effect.ci_low[row, col, ch]),
                    "ci_high": _num(self.effect.ci_high[row, col, ch]),
                    "min_detectable": _num(self.effect.min_detectable[row, col, ch]),
                }
            )
        return tiles

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready summary (the core of report.json)."""
        finite = np.isfinite(self.effect.min_detectable) & (self.reasons == Reason.VALID)
        return {
            "verdict": self.verdict,
            "alpha": self.alpha,
            "p_value": _num(self.p_value),
            "test": self.test,
            "method": self.method,
            "pvalue_method": self.pvalue_method,
            "components": {
                "holm_min_pvalue": _num(self.global_test.holm_pvalue),
                "uniformity_pvalue": _num(self.global_test.uniformity_pvalue),
            },
            "n_ref": self.n_ref,
            "n_test": self.n_test,
            "grid": {
                "width": self.width,
                "height": self.height,
                "tile": self.tile,
                "tiles_x": int(self.tile_pvalues.shape[1]),
                "tiles_y": int(self.tile_pvalues.shape[0]),
            },
            "tiles": {
                "total": int(self.tile_pvalues.size),
                "valid": self.n_valid,
                "used": int(self.used.sum()),
                "untrusted": int((np.isfinite(self.tile_pvalues) & ~self.trusted).sum()),
                "significant": int(self.significant.sum()),
            },
            "tile_channels": self.reason_counts,
            "median_min_detectable_rel_bias": _num(np.median(self.effect.min_detectable[finite]))
            if finite.any()
            else None,
            "top_tiles": self.top_tiles,
            "notes": list(self.notes),
        }


def _num(x) -> float | None:
    """JSON has no NaN: None stands for 'not defined'."""
    x = float(x)
    return x if np.isfinite(x) else None


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
        order = {seed: i for i, seed in enumerate(test.seeds)}
        test_sums = test.sums[[order[s] for s in ref.seeds]]
        result = paired_ttest(ref.sums, test_sums, axis=0, pvalue_method=pvalue_method)
        diffs = TileStats.from_sums(test_sums - ref.sums, ref.seeds, ref.height, ref.width, ref.tile)
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
    notes = []
    deterministic = int((result.reason == Reason.DETERMINISTIC_DIFFERENCE).sum())
    untrusted = int((np.isfinite(tile_p) & ~trusted).sum())
    valid = int(np.isfinite(tile_p).sum())
    if not checked:
        notes.append(
            f"fewer than {MIN_PASSES_FOR_NORMALITY} passes a side: the normality of the Welch samples is unchecked"
        )
    if untrusted:
        notes.append(
            f"{untrusted} of {valid} tiles have clearly non-normal Welch samples and are left out of the verdict"
        )
    p_value = glob.pvalue
    if deterministic:
        verdict, p_value = "biased", 0.0
        notes.append(f"{deterministic} tile-channels are constant on both sides but differ: a deterministic difference")
    elif not used.any():
        verdict = "inconclusive"
        notes.append("no tile can be tested (too few passes, zero variance or non-finite values everywhere)")
    elif glob.rejected:
        verdict = "biased"
    elif untrusted > MAX_UNTRUSTED_SHARE * valid:
        verdict = "inconclusive"
        notes.append("too much of the image has non-normal Welch samples: use larger tiles or more spp per pass")
    else:
        verdict = "no_evidence"
    return Comparison(
        verdict, alpha, p_value, kind, pvalue_method, result, tile_p, trusted, glob, effect,
        ref.n, test.n, ref.width, ref.height, ref.tile, tuple(notes),
    )  # fmt: skip


def info_differences(ref: RunInfo, test: RunInfo) -> list[str]:
    """Human-readable differences between what produced two runs (settings, overrides, renderer, spp)."""
    lines = []
    for name in ("renderer", "renderer_version", "device", "sampling_pattern", "scene", "spp"):
        a, b = getattr(ref, name), getattr(test, name)
        if a != b:
            lines.append(f"{name}: {a!r} -> {b!r}")
    for key in sorted(set(ref.settings) | set(test.settings)):
        a, b = ref.settings.get(key), test.settings.get(key)
        if a != b:
            lines.append(f"{key}: {a!r} -> {b!r}")
    if ref.overrides != test.overrides:
        lines.append(f"overrides: {list(ref.overrides)} -> {list(test.overrides)}")
    return lines
