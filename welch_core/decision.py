"""The verdict and every number a person reads about it, decided once: for a fixed number of passes (`compare`)
and at each look of a run that renders until decided (`looks`). Everything that shows a comparison (the command
line, report.json and report.html, a suite's JUnit and dashboard, the Blender panel) reads the `Outcome` made
here and decides nothing itself.

The claims and the hypotheses they reject
-----------------------------------------
``biased`` rejects H0: "every tile-channel of every tested tile size has the same mean on both sides". It is a
union-intersection test (any one tile-channel's rejection rejects H0), and its family is every tile-channel of
every scale: with a fixed number of passes each scale is tested by Holm over its tiles and a one-sided
Kolmogorov-Smirnov test of uniformity (Bonferroni over the two), and the scales by Bonferroni (`multitest`); at
looks each tile-channel gets the Bonferroni share ``alpha / (S * m_s)`` of its scale, spent over the looks
(`looks`). Either way P(``biased`` | H0) <= alpha.

``equivalent`` rejects H0: "some tile-channel of the claim scale differs by at least the tolerance", |mu_test /
mu_ref - 1| >= delta. The claim scale is the one the user names (`--equivalence-tile`), the one a check sized to its
budget (below), or in a fixed design the finest tested tile size. "Every tile is within +-delta" is an
intersection-union statement (Berger 1982): it holds when each tile-channel's two one-sided tests reject at level
alpha, that is when its (1 - 2 alpha) interval lies inside (-delta, delta), and no correction over tiles or channels
is needed (the worst case is one tile at the boundary and all others deep inside, which is rejected with probability
at most alpha). Over looks the interval is a repeated confidence interval for ``2 alpha`` spent over the looks
(Jennison and Turnbull 2000, ch. 9), so the chance of ever calling a pair equivalent whose some tile is at the
tolerance stays at most alpha (up to the chance of a path crossing both one-sided boundaries, which is negligible:
see `looks`). The same reasoning makes the largest such bound over a scale's tiles a (1 - alpha) upper confidence
bound on the largest |relative bias| of that scale: "a bias beyond B is ruled out in every tile" at each scale on
its own.

A tile-channel counts as bounded only when it is tested and trusted (its Welch samples pass the normality
check), or equal on both sides in every pass (zero variance: bounded at 0), and only once both sides have
`identical_passes(alpha)` passes (44 at alpha = 0.01): enough to rule out at 1 - alpha that a change which alters
one pass in ten (`IDENTICAL_SHARE`: a rare light path, a clamp that bites now and then) went unseen. Before that
no t interval is evidence of equivalence: the Welch samples of a tile whose change shows in a few passes look
normal and equal until the first such pass arrives, and at 2-7 passes a caustic or firefly tile's interval
covers nothing (the normality check itself needs `MIN_PASSES_FOR_NORMALITY`). No finite number of passes rules
out a change rarer than that; the threshold is the price of saying so at a stated rate.

``equivalent (bit-identical)``: every pass identical on both sides (a setting without effect in this scene, a
no-op override), for at least `identical_passes(alpha)` passes.

Sides of different pass counts (Welch's test): ``biased`` also needs the permutation max-T test of the same family
to reject (`permutation`), an intersection of the two rejections, so its level is at most either's: alpha under
normal tile sums by the t-tests, alpha under exchangeable passes (one distribution for both sides, as two unbiased
renders of one setting are) whatever the shape of the tile sums and the pass counts. Welch's t alone is not
calibrated there: with skewed tile sums (fireflies) the smaller side usually misses the bright passes and looks
darker with a tiny variance. A tile-channel is significant where both families reject it. Where the permutation
test cannot reach the level at all (too few passes: 2 v 8 have 45 distinct splits), the outcome is
``inconclusive`` ("unreachable"), never ``no_evidence``: nothing could have been found.

``no_evidence`` (no tolerance asked for): nothing rejected; the minimum detectable bias says what could hide.
``inconclusive``: with a tolerance, neither claim holds at the budget (the claim scale is not bounded yet: the
outcome says where and how many passes would bound it); or too much of the image is testable at no scale.

The claim's size (`check` without `--equivalence-tile`): the size the budget can bound, chosen at one early look
from the variances alone (`welch_core.sizing`); a claim at that size S then needs every tile-channel of S and of
every coarser size bounded, and where S is not bounded at the budget (or at a futility stop) the finest coarser
size whose tiles and coarser ones are all bounded is claimed instead. Both keep P(``equivalent`` | some tile of
the claimed size off by the tolerance) <= alpha, whatever size is chosen: see `welch_core.sizing`.

Futility (`check`, with a tolerance): a look before the last, from `FUTILITY_PASSES` passes a side on, stops when
the claim's size is out of the budget's reach at the current estimates (`ScaleResult.passes_needed` beyond the
budget, or none) *and* no tile-channel could still reach `biased` by the budget with probability
`Evidence.futility_loss` (the plan's, ``check --futility-loss``; `FUTILITY_LOSS` by default) if it held the bias
the budget detects there with 80 % power (its minimum detectable bias): the largest conditional power over the
tile-channels of the `biased` family (`Evidence.promise`, computed by `welch_core.looks.promise`). Stopping only
then gives up at most that share of the power against any such bias (each stop forgoes a rejection with
conditional probability below it: Lan, Simon and Halperin 1982). The
stop is non-binding and only ever turns a later verdict into ``inconclusive`` (or a coarser ``equivalent``,
which the fixed-sequence rule above allows at any look), so neither error rate grows; what it saves and costs is
measured in `benchmarks.studies.same`.

References: R. L. Berger, "Multiparameter hypothesis testing and acceptance sampling", Technometrics 24(4),
1982; C. Jennison and B. W. Turnbull, "Group Sequential Methods with Applications to Clinical Trials", 2000;
K. K. G. Lan, R. Simon and M. Halperin, "Stochastically curtailed tests in long-term clinical trials", Sequential
Analysis 1(3), 1982.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .diagnostics import MIN_PASSES_FOR_NORMALITY
from .effect import effect_sizes, relative_interval
from .sizing import choose_claim, passes_to_bound
from .ttest import Reason
from .verdict import Verdict, VerdictReason

__all__ = [
    "FUTILITY_LOSS",
    "IDENTICAL_SHARE",
    "MAX_UNTRUSTED_SHARE",
    "Claim",
    "Difference",
    "Evidence",
    "Outcome",
    "ScaleResult",
    "decide",
    "identical_passes",
]

#: Above this share of the image untestable at every scale (the Welch samples of its tiles clearly not normal),
#: a run without a finding is `inconclusive`, not `no_evidence`: the untested part is too large to speak for the
#: whole.
MAX_UNTRUSTED_SHARE = 0.25

#: Identical passes on both sides count as evidence of no difference once a change that alters this share of
#: the passes (or more) would have shown in one of them at 1 - alpha: (1 - share)^n <= alpha.
IDENTICAL_SHARE = 0.1

#: Futility (`check`): from this many passes a side, once the claim's size is fixed (at `identical_passes`)...
FUTILITY_PASSES = 16
#: ...a look stops where the claim's size is out of reach and the most promising tile-channel's conditional power
#: to reach `biased` by the budget, under the bias the budget detects there, is below this: the most power the
#: stop gives up against such a bias (see the module docstring).
FUTILITY_LOSS = 0.05

#: Bounds on a relative difference beyond this say nothing a person can use (an early look's interval of a
#: tile whose reference mean is nearly 0): shown as "not bounded".
MAX_SHOWN_BOUND = 10.0


def equivalence_alpha(alpha: float) -> float:
    """The two-sided level of a tile-channel's equivalence interval: 2 alpha, its two one-sided tests at alpha each
    (an intersection-union test, see above); at most 0.5, beyond which an interval would not be two-sided."""
    return min(2.0 * alpha, 0.5)


def identical_passes(alpha: float, share: float = IDENTICAL_SHARE) -> int:
    """The fewest identical passes that rule out, at 1 - alpha, a change altering `share` of the passes."""
    return max(MIN_PASSES_FOR_NORMALITY, math.ceil(math.log(alpha) / math.log1p(-share)))


@dataclass(frozen=True)
class Claim:
    """The tile size an `equivalent` speaks of, and how it was chosen: `sized` for a check's budget from the
    variances (`welch_core.sizing`: the claim then needs every coarser size bounded too, and falls back to the
    finest coarser size that is at the end), else as given (`--equivalence-tile`, or a fixed design's finest).
    A sized claim's `tile` is None until its sizing look."""

    tile: int | None
    sized: bool = False


@dataclass(frozen=True)
class Difference:
    """A relative difference, (test - reference) / |reference|, with its interval at `confidence`.

    `simultaneous` names the family the interval holds jointly with ("" for an interval that holds on its own):
    the largest and the most significant tile are chosen by the data, and only an interval simultaneous over
    every candidate covers the chosen one at its stated confidence."""

    estimate: float | None
    low: float | None
    high: float | None
    confidence: float
    simultaneous: str = ""
    tile: int | None = None  # tile size in pixels; None for the whole image
    x: int | None = None
    y: int | None = None
    width: int | None = None
    height: int | None = None
    channel: str | None = None
    p_value: float | None = None
    trusted: bool = True

    def to_json(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class ScaleResult:
    """One tile size: its tile counts, what it found and what it bounds."""

    tile: int
    tiles: int  # tiles of the grid
    tested: int  # tiles with a p-value that enter the `biased` test (trusted)
    untrusted: int  # tiles with a p-value left out (Welch samples clearly not normal)
    unpaired: int  # paired runs: tiles tested by Welch's test on the two sides (their differences not normal)
    sparse: int  # paired runs: tiles whose per-pass differences are mostly exact zeros (a change of a few paths)
    significant: int  # tiles with a tile-channel found significant
    p_value: float | None  # this scale's own p-value (fixed design only)
    ruled_out: float | None  # the largest |relative bias| left open over its tiles; None: some tile is unbounded
    bounded: int  # tiles bounded within the tolerance (all, when there is no tolerance and every tile is bounded)
    unbounded_box: tuple[int, int, int, int] | None  # x, y, width, height around the tiles not bounded
    passes_needed: int | None  # passes a side that would bound them at the current rate (None: can't tell)
    #: passes a side that bound every tile here with probability `sizing.SIZING_CHANCE` if both sides had the
    #: same mean, from the variances alone (None: no tolerance, or no number of passes would: untrusted tiles, a
    #: fixed reference too noisy)
    projected: int | None = None

    def to_json(self) -> dict[str, Any]:
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        box = self.unbounded_box
        out["unbounded_box"] = None if box is None else dict(zip(("x", "y", "width", "height"), box, strict=True))
        return out


@dataclass(frozen=True)
class Evidence:
    """What a design contributes to a decision: which tile-channels it found significant per scale, the global
    p-value (a fixed number of passes only), and the two-sided error levels of its intervals: `simultaneous` per
    scale (the level at which a tile-channel is significant: intervals that hold over the whole family of the
    `biased` claim), `equivalence` per tile-channel (2 alpha, or its share spent by this look), and `whole` for
    the whole image."""

    design: str  # "fixed" or "sequential"
    significant: list[np.ndarray]  # per scale, (ty, tx, channels) bool
    simultaneous: list[float]
    equivalence: float
    whole: float
    p_value: float | None = None
    final: bool = True  # the last look (a fixed design always is): undecided means inconclusive or no evidence
    family: str = "every tile-channel of every tile size"
    budget: int | None = None  # passes a side a check may render (None: a fixed design; no futility stop)
    #: the permutation test that `biased` between sides of different pass counts also needs (`permutation`)
    resampling: Any = None
    #: the two-sided level of an equivalence interval at the budget's last look (what projections plan for;
    #: None: `equivalence`, a fixed design's)
    planning: float | None = None
    #: the largest conditional power of a tile-channel of the `biased` family to cross its boundary by the budget
    #: under the bias the budget detects there (`looks.promise`; None: not computed, no futility stop)
    promise: float | None = None
    #: the futility stop's price: it stops where `promise` is below this (`FUTILITY_LOSS` unless the plan says)
    futility_loss: float = FUTILITY_LOSS


@dataclass(frozen=True)
class Outcome:
    """A comparison's verdict and the numbers that go with it. `decided` is False at a look that goes on."""

    verdict: Verdict
    decided: bool
    design: str
    alpha: float
    tolerance: float | None
    test: str
    claim_tile: int | None  # the tile size `equivalent` speaks of (None: no tolerance)
    identical: bool  # every pass identical on both sides
    p_value: float | None  # the global p-value of a fixed design (None at looks: after peeking it is not one)
    n_ref: int
    n_test: int
    whole_image: Difference | None
    largest: Difference | None
    most_significant: Difference | None
    scales: tuple[ScaleResult, ...]
    deterministic: int  # tile-channels constant on both sides but different
    untestable: int  # finest tiles no scale tests (untrusted or non-finite everywhere)
    untestable_box: tuple[int, int, int, int] | None
    relevant: int  # finest tiles that are not constant on both sides
    normality_checked: bool
    min_detectable: float | None  # median over tiles of the smallest bias a tile finds with 80 % power
    identical_needed: int  # identical passes that make identical sides `equivalent (bit-identical)`
    reason: VerdictReason  # why the verdict (its key in report files)
    significant: np.ndarray = field(repr=False, compare=False, default=None)  # finest tiles outlined (_found_where)
    #: per tile size, finest first: the tiles the family of `biased` found significant themselves ((ty, tx) bool)
    found: tuple = field(repr=False, compare=False, default=())
    #: the permutation test of the family, where the pass counts differ (`welch_core.permutation`); else None
    resampling: Any = field(repr=False, compare=False, default=None)
    budget: int | None = None  # a check's passes a side (None: a fixed design)
    #: the size a check chose for its budget from the variances (`welch_core.sizing`; None: given by the user, a
    #: fixed design, or not chosen yet); `claim_tile` differs from it where the claim fell back to a coarser size
    target_tile: int | None = None
    promise: float | None = None  # `Evidence.promise` at this look
    futility_loss: float = FUTILITY_LOSS  # `Evidence.futility_loss`: the most power the futility stop gives up

    @property
    def target(self) -> ScaleResult | None:
        """The scale the check aimed its claim at (its budget's size), where it sized one."""
        return next((s for s in self.scales if s.tile == self.target_tile), None)

    @property
    def claim(self) -> ScaleResult | None:
        """The scale the `equivalent` claim is about."""
        return next((s for s in self.scales if s.tile == self.claim_tile), None)

    @property
    def finest(self) -> ScaleResult:
        return self.scales[0]

    @property
    def verdict_text(self) -> str:
        if self.verdict == Verdict.EQUIVALENT and self.identical:
            return "equivalent (bit-identical)"
        return self.verdict.text

    def to_json(self) -> dict[str, Any]:
        """The outcome as JSON (report.json's ``outcome``): every number a person reads about the verdict."""
        box = self.untestable_box
        return {
            "verdict": self.verdict.label,
            "verdict_text": self.verdict_text,
            "decided": self.decided,
            "design": self.design,
            "alpha": self.alpha,
            "tolerance": self.tolerance,
            "test": self.test,
            "claim_tile": self.claim_tile,
            "identical": self.identical,
            "identical_needed": self.identical_needed,
            "p_value": self.p_value,
            "n_ref": self.n_ref,
            "n_test": self.n_test,
            "whole_image": None if self.whole_image is None else self.whole_image.to_json(),
            "largest": None if self.largest is None else self.largest.to_json(),
            "most_significant": None if self.most_significant is None else self.most_significant.to_json(),
            "scales": [s.to_json() for s in self.scales],
            "deterministic": self.deterministic,
            "untestable": self.untestable,
            "untestable_box": None if box is None else dict(zip(("x", "y", "width", "height"), box, strict=True)),
            "relevant": self.relevant,
            "normality_checked": self.normality_checked,
            "min_detectable": self.min_detectable,
            "reason": self.reason.value,
            "resampling": None if self.resampling is None else self.resampling.to_json(),
            "budget": self.budget,
            "target_tile": self.target_tile,
            "promise": self.promise,
            "futility_loss": self.futility_loss,
        }


# -- the decision -------------------------------------------------------------------------------------------


def decide(scales, tests, runs, evidence: Evidence, alpha: float, tolerance: float | None,
           claim: Claim | int | None, identical: bool, whole, untestable: np.ndarray) -> Outcome:  # fmt: skip
    """The outcome of one comparison (see the module docstring for the claims).

    `scales` and `tests` are the per-scale comparisons and tile tests, finest first (`comparison.assess_scales`);
    `runs` the per-scale (reference, test) TileStats; `claim` the size `equivalent` speaks of (a tile size as
    given, None for the finest, or a `Claim` a check sized for its budget: chosen here at its sizing look);
    `whole` the whole image's tile test; `untestable` the finest tiles no scale tests."""
    finest, finest_test = scales[0], tests[0]
    n_ref, n_test = finest.n_ref, finest.n_test
    n = min(n_ref, n_test)
    needed_identical = identical_passes(alpha)
    checked = n >= MIN_PASSES_FOR_NORMALITY
    enough = n >= needed_identical  # the fewest passes that bound a tile (see the module docstring)
    if not isinstance(claim, Claim):
        claim = Claim(claim)
    bounds = [
        _bounds(scale, tested, evidence.equivalence, enough)
        for scale, tested, run in zip(scales, tests, runs, strict=True)
    ]
    whole_image = _whole_difference(whole, evidence.whole, alpha)
    planning = evidence.planning if evidence.planning is not None else evidence.equivalence
    results = tuple(
        _scale_result(scale, sig, bound, tolerance, n, run[0], p, needed_identical,
                      _projected(scale, tested, planning, tolerance, needed_identical))
        for scale, tested, sig, bound, run, p in zip(
            scales, tests, evidence.significant, bounds, runs, _scale_pvalues(scales, evidence), strict=True
        )
    )  # fmt: skip
    deterministic = sum(int((s.reasons == Reason.DETERMINISTIC_DIFFERENCE).sum()) for s in scales)
    crossed = any(bool(np.any(sig)) for sig in evidence.significant)
    relevant = ~(finest.reasons == Reason.ZERO_VARIANCE).all(axis=-1)
    target_tile = _sized(claim, results, evidence, enough) if tolerance is not None else None
    claim_tile = None if tolerance is None else (target_tile or claim.tile or finest.tile)

    def holds(tile: int) -> bool:
        """`equivalent` at `tile`: its tiles bounded (a sized claim: every coarser size's too), and no finer tile
        found biased beyond the tolerance (which a coarser claim would hide)."""
        sizes = [r for r in results if r.tile == tile or (claim.sized and r.tile > tile)]
        within = all(r.ruled_out is not None and r.ruled_out <= tolerance for r in sizes)
        return within and not _beyond(scales, tests, evidence.significant, tile, tolerance)

    bounded = tolerance is not None and holds(claim_tile)
    claimed = next((r for r in results if r.tile == claim_tile), None)
    beyond = (
        tolerance is not None and claimed.ruled_out is not None and claimed.ruled_out <= tolerance
        and _beyond(scales, tests, evidence.significant, claim_tile, tolerance)
    )  # fmt: skip
    futile = _futile(claimed, bounded, evidence, tolerance, n) and (not claim.sized or target_tile is not None)
    # A sized claim not bounded at its own size: at the end (or a futility stop), the finest coarser size that holds
    fallback = (
        next((r.tile for r in results if r.tile > claim_tile and holds(r.tile)), None)
        if claim.sized and tolerance is not None and not bounded and (evidence.final or futile)
        else None
    )
    too_untested = int(untestable.sum()) > MAX_UNTRUSTED_SHARE * int(relevant.sum())
    testable = any(s.used.any() for s in scales)

    decided = True
    if deterministic:
        verdict, reason = Verdict.BIASED, VerdictReason.DETERMINISTIC
    elif identical and n >= needed_identical:
        verdict, reason = Verdict.EQUIVALENT, VerdictReason.IDENTICAL
    elif bounded:
        verdict, reason = Verdict.EQUIVALENT, VerdictReason.BOUNDED
    elif identical:
        verdict, reason, decided = Verdict.INCONCLUSIVE, VerdictReason.IDENTICAL_TOO_FEW, evidence.final
    elif crossed or (evidence.p_value is not None and evidence.p_value <= alpha):
        verdict, reason = Verdict.BIASED, VerdictReason.SIGNIFICANT if crossed else VerdictReason.SPREAD
    elif futile and fallback is not None:
        verdict, reason, claim_tile = Verdict.EQUIVALENT, VerdictReason.BOUNDED, fallback
    elif futile:
        verdict, reason = Verdict.INCONCLUSIVE, VerdictReason.FUTILE
    elif not evidence.final:
        verdict, reason, decided = Verdict.INCONCLUSIVE, VerdictReason.UNDECIDED, False
    elif not any(s.n_valid for s in scales):
        verdict, reason = Verdict.INCONCLUSIVE, VerdictReason.UNTESTABLE
    elif evidence.resampling is not None and evidence.resampling.limited:
        verdict, reason = Verdict.INCONCLUSIVE, VerdictReason.UNREACHABLE
    elif too_untested or not testable:
        verdict, reason = Verdict.INCONCLUSIVE, VerdictReason.TOO_UNTESTED
    elif fallback is not None:
        verdict, reason, claim_tile = Verdict.EQUIVALENT, VerdictReason.BOUNDED, fallback
    elif tolerance is not None:
        verdict, reason = Verdict.INCONCLUSIVE, VerdictReason.BEYOND if beyond else VerdictReason.UNBOUNDED
    else:
        verdict, reason = Verdict.NO_EVIDENCE, VerdictReason.NOTHING_FOUND
    significant_finest = _found_where(scales, evidence.significant)
    return Outcome(
        verdict=verdict,
        decided=decided,
        design=evidence.design,
        alpha=alpha,
        tolerance=tolerance,
        test=finest_test.kind,
        claim_tile=claim_tile,
        identical=identical,
        p_value=_num(evidence.p_value) if evidence.p_value is not None else None,
        n_ref=n_ref,
        n_test=n_test,
        whole_image=whole_image,
        largest=_largest(scales[0], tests[0], runs[0][0], evidence.simultaneous[0], alpha, evidence.family),
        most_significant=_most_significant(scales, tests, runs, evidence, alpha),
        scales=results,
        deterministic=deterministic,
        untestable=int(untestable.sum()),
        untestable_box=_box(untestable, runs[0][0]),
        relevant=int(relevant.sum()),
        normality_checked=checked,
        min_detectable=_min_detectable(finest, finest_test, alpha),
        identical_needed=needed_identical,
        reason=reason,
        significant=significant_finest,
        found=tuple(np.asarray(sig).any(axis=-1) for sig in evidence.significant),
        resampling=evidence.resampling,
        budget=evidence.budget,
        target_tile=target_tile,
        promise=evidence.promise,
        futility_loss=evidence.futility_loss,
    )


def _scale_pvalues(scales, evidence: Evidence) -> list[float | None]:
    if evidence.design != "fixed":
        return [None] * len(scales)
    return [_num(s.p_value) for s in scales]


def _bounds(scale, tested, level: float, enough: bool):
    """Per tile-channel of one scale: the largest |relative difference| its (1 - level) interval leaves open
    (inf where it can't be bounded), the estimate and the interval's larger half-width (for the passes needed)."""
    low, high = relative_interval(tested, level)
    with np.errstate(invalid="ignore"):
        bound = np.maximum(np.abs(low), np.abs(high))
    reasons = scale.reasons
    valid = (reasons == Reason.VALID) & scale.trusted[..., None] & enough
    equal = (reasons == Reason.ZERO_VARIANCE) & enough
    bound = np.where(valid & np.isfinite(bound), bound, np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):  # inf - inf where a tile has no interval: NaN
        estimate = tested.result.mean_difference / np.abs(tested.ref_mean)
        half = np.maximum(high - estimate, estimate - low)
    return np.where(equal, 0.0, bound), estimate, half


def _sized(claim: Claim, results, evidence: Evidence, enough: bool) -> int | None:
    """The size a sized claim aims at: the one chosen at an earlier look, else chosen now from this look's
    projections where this is its sizing look: the first at which a claim could be made (`enough` passes: the
    variances then have as many degrees of freedom as the choice can have for free), or the last look."""
    if not claim.sized:
        return None
    if claim.tile is not None:
        return claim.tile
    if evidence.budget is None or not (enough or evidence.final):
        return None
    return choose_claim([(r.tile, r.projected) for r in results], evidence.budget)


def _futile(claimed: ScaleResult | None, bounded: bool, evidence: Evidence, tolerance: float | None, n: int) -> bool:
    """Whether a check stops for futility (see the module docstring): a look before the last, with a tolerance,
    from FUTILITY_PASSES passes a side on, whose claim is out of the budget's reach at the current estimates while
    no tile-channel's conditional power to reach `biased` by the budget is `Evidence.futility_loss` (by default
    FUTILITY_LOSS) or more."""
    if tolerance is None or evidence.budget is None or evidence.final or claimed is None or bounded:
        return False
    if n < FUTILITY_PASSES or evidence.promise is None or claimed is None:
        return False
    out_of_reach = claimed.passes_needed is None or claimed.passes_needed > evidence.budget
    return out_of_reach and evidence.promise < evidence.futility_loss


def _projected(scale, tested, level: float, tolerance: float | None, floor: int) -> int | None:
    """Passes a side that bound every tile-channel of the scale within the tolerance with probability
    `sizing.SIZING_CHANCE` if both sides had the same mean (`sizing.passes_to_bound`: the variances alone, not the
    differences, so a plan or a stop made from it does not shape what it leaves)."""
    if tolerance is None:
        return None
    return passes_to_bound(tested, scale.n_ref, scale.n_test, level, tolerance, floor)


def _scale_result(scale, significant, bounds, tolerance, n: int, run, p_value, identical_needed: int,
                  projected: int | None = None) -> ScaleResult:  # fmt: skip
    bound, estimate, half = bounds
    per_tile = bound.max(axis=-1)
    worst = float(per_tile.max()) if per_tile.size else math.inf
    within = per_tile <= (tolerance if tolerance is not None else math.inf)
    if tolerance is None:
        within = np.isfinite(per_tile)
    unbounded = ~within
    return ScaleResult(
        tile=scale.tile,
        tiles=int(scale.tile_pvalues.size),
        tested=int(scale.used.sum()),
        untrusted=scale.n_untrusted,
        unpaired=0 if scale.tested.unpaired is None else int(scale.tested.unpaired.any(axis=-1).sum()),
        sparse=0 if scale.tested.sparse is None else int(scale.tested.sparse.any(axis=-1).sum()),
        significant=int(np.asarray(significant).any(axis=-1).sum()),
        p_value=p_value,
        ruled_out=worst if worst <= MAX_SHOWN_BOUND else None,
        bounded=int(within.sum()),
        unbounded_box=_box(unbounded, run),
        passes_needed=_passes_needed(scale, estimate, half, bound, tolerance, n, identical_needed)
        if unbounded.any()
        else None,
        projected=projected,
    )


def _passes_needed(scale, estimate, half, bound, tolerance, n: int, identical_needed: int) -> int | None:
    """Passes a side that would bound every tile-channel of the scale within the tolerance if its estimate e
    stayed and its interval's half-width h shrank like 1 / sqrt(passes): n (h / (delta - |e|))^2. A planning
    figure: an estimate that moves changes it. None without a tolerance, or where more passes alone can't bound a
    tile as things stand (an estimate at or beyond the tolerance, samples that are not normal, non-finite
    values)."""
    if tolerance is None:
        return None
    open_ = bound > tolerance
    valid = scale.reasons == Reason.VALID
    equal = scale.reasons == Reason.ZERO_VARIANCE
    if np.any(open_ & ~valid & ~equal) or np.any(open_ & valid & ~scale.trusted[..., None]):
        return None
    need = max(identical_needed, n + 1)
    sel = open_ & valid
    if sel.any():
        e, h = np.abs(estimate[sel]), half[sel]
        if not (np.all(np.isfinite(h)) and np.all(e < tolerance)):
            return None
        need = max(need, int(math.ceil(n * float(np.max((h / (tolerance - e)) ** 2)))))
    return need


def _beyond(scales, tests, significant, claim_tile, tolerance) -> bool:
    """A tile-channel finer than the claim scale found significant whose estimate lies beyond the tolerance: a
    coarser claim would hide a local bias several times the tolerance under a region's mean."""
    for scale, tested, sig in zip(scales, tests, significant, strict=True):
        if scale.tile >= claim_tile:
            continue
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.abs(tested.result.mean_difference / np.abs(tested.ref_mean))
        if np.any(np.asarray(sig) & (rel > tolerance)):
            return True
    return False


def _found_where(scales, significant) -> np.ndarray:
    """The finest tiles the map outlines: those found significant at the finest size where anything was found
    (the finest tiles themselves if any of them; a bias found only in larger tiles outlines the finest tiles
    inside those, so a `biased` verdict never comes with an empty map), less the tiles with nothing to test
    (identical on both sides in every pass, a black background, or untestable)."""
    finest = scales[0]
    ty, tx = finest.tile_pvalues.shape
    tested = (finest.reasons == Reason.VALID).any(axis=-1)  # not a tile identical on both sides, or untestable
    for scale, sig in zip(scales, significant, strict=True):
        tiles = np.asarray(sig).any(axis=-1)
        if tiles.any():
            f = scale.tile // finest.tile
            inside = np.repeat(np.repeat(tiles, f, axis=0), f, axis=1)[:ty, :tx]
            return inside & tested if (inside & tested).any() else inside
    return np.zeros((ty, tx), bool)


def _channel_name(channels: int, ch: int) -> str:
    return "RGB"[ch] if channels == 3 else str(ch)


def _difference(tested, run, level: float, confidence: float, simultaneous: str, index, trusted=True,
                p_value=None) -> Difference:  # fmt: skip
    row, col, ch = index
    low, high = relative_interval(tested, level)
    with np.errstate(divide="ignore", invalid="ignore"):  # a black reference tile: no relative difference
        rel = tested.result.mean_difference[row, col, ch] / abs(tested.ref_mean[row, col, ch])
    x, y, w, h = run.tile_box(row, col)
    channels = tested.ref_mean.shape[-1]
    return Difference(
        estimate=_num(rel),
        low=_num(low[row, col, ch]) if np.ndim(low) else _num(low),
        high=_num(high[row, col, ch]) if np.ndim(high) else _num(high),
        confidence=confidence,
        simultaneous=simultaneous,
        tile=run.tile,
        x=x,
        y=y,
        width=w,
        height=h,
        channel=_channel_name(channels, ch),
        p_value=_num(p_value) if p_value is not None else None,
        trusted=bool(trusted),
    )


def _largest(scale, tested, run, level: float, alpha: float, family: str) -> Difference | None:
    """The tested finest tile-channel with the largest |relative difference|, with its interval simultaneous over
    the family of the `biased` claim (it was chosen for its size: a pointwise interval would not cover it)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.abs(tested.result.mean_difference / np.abs(tested.ref_mean))
    usable = (scale.reasons == Reason.VALID) & scale.used[..., None] & np.isfinite(rel)
    if not usable.any():
        return None
    index = np.unravel_index(int(np.argmax(np.where(usable, rel, -1.0))), rel.shape)
    return _difference(tested, run, level, 1 - alpha, family, index, True, scale.pvalues[index])


def _most_significant(scales, tests, runs, evidence: Evidence, alpha: float) -> Difference | None:
    """The tile-channel, at any scale, whose p-value is strongest against the level it had to reach (the
    Bonferroni-adjusted p of a fixed design), with its simultaneous interval; untrusted tiles count too (their
    p is shown with a word that it is not trusted)."""
    best, best_ratio = None, -math.inf
    for k, (scale, level) in enumerate(zip(scales, evidence.simultaneous, strict=True)):
        valid = scale.reasons == Reason.VALID
        if not valid.any() or not level > 0:
            continue
        p = np.where(valid, scale.pvalues, np.nan)
        index = np.unravel_index(int(np.nanargmin(p)), p.shape)
        with np.errstate(divide="ignore"):
            ratio = math.log(max(float(p[index]), 1e-320)) / math.log(level)
        if ratio > best_ratio:
            best, best_ratio = (k, index), ratio
    if best is None:
        return None
    k, index = best
    scale = scales[k]
    trusted = bool(scale.trusted[index[:2]])
    return _difference(tests[k], runs[k][0], evidence.simultaneous[k], 1 - alpha, evidence.family, index, trusted,
                       scale.pvalues[index])  # fmt: skip


def _whole_difference(whole, level: float, alpha: float) -> Difference | None:
    """The whole image's relative difference (all tiles and channels summed per pass) and its interval: one
    hypothesis, so the interval holds on its own (over the looks at a run that renders until decided)."""
    if whole is None:
        return None
    result = whole.result
    if result.reason.ravel()[0] == Reason.ZERO_VARIANCE:
        return Difference(0.0, 0.0, 0.0, 1 - alpha)
    if result.reason.ravel()[0] != Reason.VALID:
        return None
    low, high = relative_interval(whole, level)
    rel = result.mean_difference / np.abs(whole.ref_mean)
    return Difference(_num(rel.ravel()[0]), _num(low.ravel()[0]), _num(high.ravel()[0]), 1 - alpha,
                      p_value=_num(result.pvalue.ravel()[0]))  # fmt: skip


def _min_detectable(scale, tested, alpha: float) -> float | None:
    """Median over the finest tested tile-channels of the smallest |relative bias| found with 80 % power at the
    Bonferroni level a tile must reach on its own (`effect.effect_sizes`)."""
    detectable = effect_sizes(tested, alpha, int(scale.used.sum())).min_detectable
    usable = (scale.reasons == Reason.VALID) & scale.used[..., None] & np.isfinite(detectable)
    return _num(np.median(detectable[usable])) if usable.any() else None


def _box(mask: np.ndarray, run) -> tuple[int, int, int, int] | None:
    """The pixel box (x, y, width, height) around the tiles of `mask`, or None if there are none."""
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return None
    x0, y0, _, _ = run.tile_box(int(rows.min()), int(cols.min()))
    x1, y1, w1, h1 = run.tile_box(int(rows.max()), int(cols.max()))
    return x0, y0, x1 + w1 - x0, y1 + h1 - y0


def _num(x) -> float | None:
    """JSON has no NaN: None stands for 'not defined'."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None
