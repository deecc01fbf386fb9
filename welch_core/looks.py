"""Render until decided: look at the data after every chunk of passes and stop at `biased` or `equivalent`,
with the false-positive rate of either verdict at most alpha however many looks it takes.

The hypotheses are the tile-channels of every tile scale (see `comparison`). Each gets a Bonferroni share of
alpha, ``alpha / (scales * tile-channels of its scale)``, and two group-sequential boundaries that split that
share (`sequential.boundaries`, Lan-DeMets alpha spending, Pocock shape by default): an early design's over the
first `EARLY_PASSES` passes and the main design's over the whole budget (`biased_levels`). At look k a hypothesis is
rejected when its exact two-sided p-value (the paired t-test, or Welch's t with the conservative n - 1 degrees
of freedom of the smaller side: see `conservative`) is at most the boundary's nominal level; by the union bound
over hypotheses and the spending over looks, the chance that an unbiased pair is ever called `biased` is at most
alpha (measured: 4.5 % at alpha = 0.05 over 2000 sequences of skewed Welch samples with variances 1:9, against
40 % when stopping at the first `compare` with p <= alpha). The same boundaries give repeated confidence
intervals of the relative difference, which cover every tile's true difference at every look simultaneously
with probability 1 - alpha (Jennison and Turnbull 2000, ch. 9): those of the largest and the most significant
tile. `equivalent` is an intersection-union claim with its own level per tile-channel of the claim scale (2 alpha
for its two one-sided tests, spent over the looks in the same way): see `welch_core.decision` and
`sequential_look`; the rules of the verdict are those of a fixed design, with these levels.

Why Pocock's shape, not O'Brien-Fleming's: a renderer that is biased should be caught after a few chunks, and
one that is not should be cleared as soon as possible. O'Brien-Fleming spends almost nothing early, so a bias that
a fixed design finds at 4 passes took 38 passes with a 512-pass budget (simulated: 9.5x); Pocock-type spending
keeps the boundaries nearly flat and found it at 5 (1.25x), at the price of a final boundary 0.4 higher in z
than the fixed test's (`docs/benchmarks`). O'Brien-Fleming's shape is also not calibrated in this design with
skewed tile sums: 500 unbiased sequences as `tests/core/test_looks.py` draws them (skewness 1, standard deviations
1:3, 64 passes, alpha 0.05) were called `biased` in 37 (7.4 %; 34 without the early design, 29 with a Pocock early
design) against Pocock's 18 (3.6 %), spending nearly all of alpha at the last looks (why it fails there was not
measured). `spending` stays for what-if studies; `check` offers no other.
The looks come at 2 passes a side and then every 15 % more passes.

Why an early design beside it: a t with few degrees of freedom pays for a small level in passes. At n = 2 a side
(one degree of freedom) the critical |t| grows as 1 / level, at n = 100 only as sqrt(log(1 / level)); yet
Pocock over a 512-pass budget gives the look at 2 passes under 1 % of the level. So `EARLY_SHARE` of each `biased`
level has a design of its own that ends at `EARLY_PASSES` passes a side (Pocock over its information fractions
scaled by max_passes / EARLY_PASSES: the correlation of the looks is unchanged), the rest is spent over the whole
budget; a hypothesis is rejected when it crosses either boundary, so by the union bound its level is kept. With a
512-pass budget the look at 2 passes then has 16x the level (the critical |t| of one degree of freedom falls as
much), the last looks half of it (about 0.1 higher in z at the levels used). Simulated on the pools of
`benchmarks.studies.power` (17 case-test pairs, 200 runs each): the median passes to `biased` fell in 10 (by up to 22 %:
clamp unpaired 9 -> 7 passes, walls unpaired 5 -> 4, glossy paired 18 -> 15), stayed in 5, and rose by one look
in the 2 that take 29 and 170 passes (to 34 and 196).

A budget can grow after its last look (an `inconclusive` check resumed with more passes): the plan keeps
`EXTENSION_RESERVE` of each level for that from the start (`sequential.boundaries`' reserve), and the looks past
the budget continue its schedule (`look_schedule`), so neither depends on a choice made after seeing the data.

Why not Holm or the KS test of `compare`: neither has a group-sequential form with proven error control here;
the coarsest scale (the whole image, or large tiles) takes the KS test's part of finding a weak bias spread over
the image.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from .comparison import check_claim_tile, check_tolerance, pixel_share, scale_tests
from .decision import FUTILITY_LOSS, Claim, Evidence, Outcome, decide, equivalence_alpha, identical_passes
from .effect import DETECTION_POWER
from .errors import WelchInputError, check_alpha, check_int
from .multitest import bonferroni
from .permutation import permutation_max_t
from .pixels import PIXEL_MODES, PixelMoments, PixelUse
from .sequential import SPENDING, boundaries, nominal_levels
from .tile_test import TileTest
from .tiles import TileStats
from .ttest import Reason, pvalue_exact
from .verdict import Verdict

__all__ = [
    "EARLY_PASSES",
    "EARLY_SHARE",
    "FIRST_LOOK",
    "LOOK_GROWTH",
    "Look",
    "SequentialPlan",
    "biased_levels",
    "conservative",
    "information_fraction",
    "look_schedule",
    "promise",
    "sequential_look",
]

#: The first look, in passes a side: two are the fewest with a variance.
FIRST_LOOK = 2

#: The share of alpha a check keeps for looks past its budget (`sequential.boundaries`): an `inconclusive` check
#: can be given more passes and keep its level. It costs little at the budget: Pocock's last boundary at
#: 0.9 alpha instead of alpha is about 0.04 higher in z for the levels of a few thousand tile-channels.
EXTENSION_RESERVE = 0.1

#: Each look comes after this many times the passes of the one before (at least one more pass): the overshoot
#: past the pass count where the evidence first suffices is at most 15 %.
LOOK_GROWTH = 1.15

#: The share of each `biased` level spent by the early design, and the passes a side where that design ends (see
#: the module's docstring); a budget of at most EARLY_PASSES has no early design (it would be the main one again).
EARLY_SHARE = 0.5
EARLY_PASSES = 16


@dataclass(frozen=True)
class SequentialPlan:
    """The design: alpha, the most passes a side, the tolerance (None: never `equivalent`), the spending."""

    max_passes: int
    alpha: float = 0.01
    tolerance: float | None = 0.01
    spending: str = "pocock"
    test_kind: str = "auto"
    equivalence_tile: int | None = None  # claim `equivalent` at this tile size (default: sized for the budget)
    reserve: float = EXTENSION_RESERVE  # the share of alpha kept for looks past max_passes (a grown budget)
    early_share: float = EARLY_SHARE  # the share of each `biased` level spent by the early design (0: none)
    futility: bool = True  # stop once neither claim is within the budget's reach (`decision`)
    futility_loss: float = FUTILITY_LOSS  # ...and no tile-channel has this chance left to reach `biased`
    pixel_variance: str = "off"  # test tiles by their pixels' variances where allowed (`welch_core.pixels`)

    def __post_init__(self):
        check_int("max_passes", self.max_passes, minimum=FIRST_LOOK)
        check_alpha(self.alpha)
        check_tolerance(self.tolerance)
        if self.spending not in SPENDING:
            raise WelchInputError(f"`spending` must be one of {tuple(SPENDING)}, got {self.spending!r}")
        if not 0 <= self.reserve < 1:
            raise WelchInputError(f"`reserve` must lie in [0, 1), got {self.reserve!r}")
        if not 0 <= self.early_share < 1:
            raise WelchInputError(f"`early_share` must lie in [0, 1), got {self.early_share!r}")
        if not 0 < self.futility_loss < 1:
            raise WelchInputError(f"`futility_loss` must lie in (0, 1), got {self.futility_loss!r}")
        if self.pixel_variance not in PIXEL_MODES:
            raise WelchInputError(f"`pixel_variance` must be one of {PIXEL_MODES}, got {self.pixel_variance!r}")

    @property
    def early(self) -> float:
        """The share of the early design in this plan: none when the budget ends where it would."""
        return self.early_share if self.max_passes > EARLY_PASSES else 0.0


def look_schedule(
    max_passes: int, first: int = FIRST_LOOK, growth: float = LOOK_GROWTH, budget: int | None = None
) -> list[int]:
    """Passes a side at each look: `first`, then `growth` times more (at least one more), ending at `max_passes`;
    with a larger `budget` (a check given more passes after its last planned look), the looks go on from
    `max_passes` in the same steps, up to the last that fits the budget. The looks past `max_passes` depend on it
    alone, never on the budget asked for after seeing the data."""
    passes, n = [], first
    while n < max_passes:
        passes.append(n)
        n = max(n + 1, math.ceil(n * growth))
    passes.append(max_passes)
    n = max_passes
    while budget is not None and (n := max(n + 1, math.ceil(n * growth))) <= budget:
        passes.append(n)
    return passes


def information_fraction(passes: int, max_passes: int, reference_passes: int | None = None) -> float:
    """The information of a look at `passes` (test side) relative to the last planned look's at `max_passes`
    (above 1 past it: a grown budget).

    Information is the inverse variance of a difference of means, 1 / (1/n_ref + 1/n_test) up to a constant:
    n / max_passes when both sides grow together; with a fixed reference of `reference_passes` (a suite's blessed
    reference), the early looks already hold the reference's share. Estimates of the difference at successive
    looks then have Cov(d_j, d_k) = Var(d_k) for j < k either way, the structure the boundaries assume (Jennison
    and Turnbull 2000, §3.1)."""

    def information(n: int) -> float:
        n_ref = n if reference_passes is None else reference_passes
        return 1.0 / (1.0 / n_ref + 1.0 / n)

    return information(passes) / information(max_passes)


@dataclass(frozen=True)
class Look:
    """What one look found: its `outcome` (the verdict and its numbers), and the strongest hypothesis against its
    boundary (for a progress line)."""

    passes: int  # a side
    fraction: float  # information fraction: passes / max_passes (1 at the last look)
    outcome: Outcome
    p_value: float  # the most significant tested tile-channel's p-value...
    threshold: float  # ...and the nominal level it had to reach at this look (at its scale)
    crossed: int  # tile-channels past their boundary
    pixel_use: PixelUse | None = None  # whether tiles were tested by their pixel variances, and why

    @property
    def verdict(self) -> Verdict | None:
        """`biased` or `equivalent` (stop), or None (go on); at the last look the outcome's verdict."""
        return self.outcome.verdict if self.outcome.decided else None

    @property
    def ruled_out(self) -> float:
        """The bias ruled out in every tile of the claim scale (the finest, unless another was asked for)."""
        bound = self.bound_scale.ruled_out
        return math.inf if bound is None else bound

    @property
    def ruled_out_tile(self) -> int:
        return self.bound_scale.tile

    @property
    def bound_scale(self):
        return self.outcome.claim or self.outcome.finest

    @property
    def uncovered(self) -> int:
        return self.outcome.untestable


def conservative(tested: TileTest, n: int) -> TileTest:
    """Welch's test with n - 1 degrees of freedom (n the smaller side's passes) instead of Welch-Satterthwaite's
    real-valued nu: a boundary's level is far out in the tail, where nu overstates the evidence of small runs
    with unequal variances (at n = 10 a side, variances 1:9 and normal samples, the 3e-4 tail is 1.7x its
    nominal size; with n - 1, at most 1.14x for skewness up to 0.5, measured). A paired test already has n - 1:
    its p-values are unchanged. Tile-channels tested by their pixel variances keep their df (at least
    `pixels.MIN_PIXEL_DF`; calibrated under the looks: docs/findings/pixel_variance.md)."""
    result = tested.result
    valid = result.reason == Reason.VALID
    by_pixels = tested.pixel if tested.pixel is not None else False
    df = np.where(valid, np.where(by_pixels, result.df, n - 1.0), np.nan)
    pvalue = np.where(valid, pvalue_exact(result.statistic, df), np.nan)
    return dataclasses.replace(tested, result=dataclasses.replace(result, df=df, pvalue=pvalue))


@functools.lru_cache(maxsize=256)
def _levels(fractions: tuple[float, ...], shares: tuple[float, ...], spending: str, reserve: float) -> np.ndarray:
    """Nominal levels of the last look's boundaries (cached: a run and its resumption ask for the same ones)."""
    levels = nominal_levels(boundaries(fractions, shares, spending, reserve)[-1])
    levels.flags.writeable = False
    return levels


def biased_levels(fractions, shares, plan: SequentialPlan) -> np.ndarray:
    """The nominal levels at the last of the looks at information `fractions` of hypotheses with the `biased`
    levels `shares`: the larger of the main design's (1 - early share of each, spent over the whole budget) and
    the early design's (the early share, spent by EARLY_PASSES; 0 after its end)."""
    fractions = tuple(np.asarray(fractions, dtype=float).tolist())
    shares = np.asarray(shares, dtype=float)
    main = _levels(fractions, tuple((shares * (1.0 - plan.early)).tolist()), plan.spending, plan.reserve)
    if not plan.early:
        return main
    early = np.asarray(fractions) * (plan.max_passes / EARLY_PASSES)
    if early.size > 1 and early[-2] >= 1.0:  # the early design ended at an earlier look
        return main
    ended = tuple(np.minimum(early, 1.0).tolist())
    return np.maximum(main, _levels(ended, tuple((shares * plan.early).tolist()), plan.spending, 0.0))


def spent(fraction: float, plan: SequentialPlan) -> float:
    """The share of alpha the `biased` claim has spent by information `fraction`, over the whole family: the main
    design's (1 - early share, keeping `reserve` for a grown budget) and the early design's (the early share, by
    EARLY_PASSES), as `biased_levels` spends them per tile-channel."""
    spending = SPENDING[plan.spending]
    if fraction <= 1.0:
        main = (1.0 - plan.reserve) * float(spending(fraction, plan.alpha))
    else:
        main = plan.alpha * (1.0 - plan.reserve / fraction)
    early = float(spending(min(fraction * plan.max_passes / EARLY_PASSES, 1.0), plan.alpha)) if plan.early else 0.0
    return (1.0 - plan.early) * main + plan.early * early


def resampling_level(fractions, plan: SequentialPlan) -> float:
    """The level of the permutation test at the last of the looks at `fractions`: what the spending adds at this
    look. A crossing at look k counts only where the permutation test rejects at its level a_k, and the a_k sum
    to at most alpha over the looks, so by the union bound over looks an unbiased pair is called `biased` with
    probability at most alpha whatever the pass counts (and at most what the t-tests' boundaries allow)."""
    fractions = [float(f) for f in fractions]
    before = spent(fractions[-2], plan) if len(fractions) > 1 else 0.0
    return max(spent(fractions[-1], plan) - before, 0.0)


def planned_fractions(fractions, plan: SequentialPlan, passes: int, budget: int, reference_passes: int | None):
    """The information fractions of every look so far and of those the schedule still plans up to `budget` (a
    fixed reference of `reference_passes`: its information counted, as `information_fraction` does)."""
    so_far = tuple(float(f) for f in fractions)
    later = [information_fraction(m, plan.max_passes, reference_passes)
             for m in look_schedule(plan.max_passes, budget=budget) if m > passes]  # fmt: skip
    return so_far + tuple(f for f in later if f > so_far[-1])


def promise(scales, final_levels, fraction: float) -> float:
    """The largest conditional power, over the tile-channels of every scale, to cross the boundary of the
    budget's last look (its nominal level in `final_levels`, per scale) if the tile-channel held the bias the
    budget detects there with `DETECTION_POWER` (its minimum detectable bias: drift c + z_beta at the end), given
    its z now at information `fraction` of the budget's. On the Brownian scale B(t) = z sqrt(t) the rest of the
    path adds N(drift (1 - t), 1 - t), so the power is Phi((z sqrt(t) + z_beta (1 - t) - c t) / sqrt(1 - t))
    (Lan, Simon and Halperin 1982). It needs only each p-value and the boundary: any test's z serves."""
    from scipy import special

    if fraction >= 1.0:
        return 1.0
    z_beta = float(special.ndtri(DETECTION_POWER))
    best = 0.0
    for scale, level in zip(scales, final_levels, strict=True):
        # every tile-channel with a p-value, trusted or not: one not trusted now (a caustic's few passes) may be
        # trusted and cross later, and its p is the best guide to how far it is
        tested = scale.reasons == Reason.VALID
        if not tested.any() or not level > 0:
            continue
        p = max(float(np.min(scale.pvalues[tested])), 1e-300)
        z, c = float(special.ndtri(1.0 - p / 2.0)), float(special.ndtri(1.0 - level / 2.0))
        x = (z * math.sqrt(fraction) + z_beta * (1.0 - fraction) - c * fraction) / math.sqrt(1.0 - fraction)
        best = max(best, float(special.ndtr(x)))
    return best


def sequential_look(
    ref: TileStats, test: TileStats, plan: SequentialPlan, fractions, final: bool | None = None,
    budget: int | None = None, pairs: PixelMoments | None = None, claim_tile: int | None = None,
) -> Look:  # fmt: skip
    """The decision at the last of the looks at information `fractions` (every look so far, increasing).

    The boundaries of the earlier looks shape this one's (alpha spent before is not spent again), so the
    fractions of every look so far are needed; they are recomputed identically on resume. `final` says this is
    the last look (default: its fraction is 1); a check stopped by its time budget passes True. `budget` is the
    passes a side the check may render (default the plan's; more once it was grown): the futility stop of
    `equivalent` compares the passes each scale needs with it (`welch_core.decision`). `pairs`: a paired run's
    moments of each pixel's difference (see `compare`). `claim_tile`: the size an earlier look sized the claim of
    `equivalent` at (its outcome's `target_tile`); None before its sizing look, which chooses it
    (`welch_core.sizing`); a plan's `equivalence_tile` is the user's and is kept as given.

    Each tile-channel of each scale has the Bonferroni share alpha / (S m_s) of `biased`, spent over the looks by
    the early and the main design (`biased_levels`);
    each tile-channel of the claim scale has 2 alpha for its equivalence interval (the two one-sided tests of an
    intersection-union test, see `welch_core.decision`), and the whole image alpha for its interval, each spent
    over the looks in the same way. The two one-sided boundaries of an equivalence interval come from one
    two-sided boundary at 2 alpha: each side is crossed with probability alpha + P(both are crossed, at
    different looks) / 2, and a path that crosses -c_j and then +c_k needs a swing of about 2c in W, of
    probability below 1e-4 alpha for the levels used here.
    """
    fractions = np.asarray(fractions, dtype=float)
    start = scale_tests(ref, test, plan.alpha, plan.test_kind, pixel_variance=plan.pixel_variance, pairs=pairs)
    method, scales, tests, runs, whole = start.method, start.scales, start.tests, start.runs, start.whole
    n = min(ref.n, test.n)
    if any(np.any(t.welch) for t in (*tests, whole)):  # Welch's test somewhere (a paired run's sparse tiles too)
        tests = [conservative(t, n) if np.any(t.welch) else t for t in tests]
        whole = conservative(whole, n) if np.any(whole.welch) else whole
        scales = tuple(dataclasses.replace(s, result=t.result) for s, t in zip(scales, tests, strict=True))
    shares = [bonferroni(plan.alpha, len(scales), scale.pvalues.size) for scale in scales]
    scale_levels = biased_levels(fractions, shares, plan)
    (whole_level,) = _levels(tuple(fractions.tolist()), (plan.alpha,), plan.spending, plan.reserve)
    budget = plan.max_passes if budget is None else budget
    fixed = ref.n if ref.n != test.n else None  # a fixed reference (a suite's blessed one): its passes stay
    ahead = planned_fractions(fractions, plan, test.n if fixed else n, budget, fixed)
    claimable = information_fraction(identical_passes(plan.alpha), plan.max_passes, fixed)
    equivalence_level = _equivalence_level(fractions, claimable, plan)
    # a budget too short for any claim plans as one look at the end would
    planning = _equivalence_level(ahead, claimable, plan) or equivalence_alpha(plan.alpha)
    significant = []
    crossed, best = 0, (0.0, 1.0, 1.0)  # (log ratio of p to its level, p, level) of the strongest hypothesis
    for scale, level in zip(scales, scale_levels, strict=True):
        tested = scale.used[..., None] & (scale.reasons == Reason.VALID)
        p = np.where(tested, scale.pvalues, np.nan)
        with np.errstate(invalid="ignore"):
            significant.append(p <= level)
        crossed += int(np.sum(significant[-1]))
        if np.isfinite(p).any() and level > 0:
            with np.errstate(divide="ignore"):
                ratio = np.log(np.nanmin(p)) / math.log(level)  # >= 1: crossed
            if ratio > best[0]:
                best = (float(ratio), float(np.nanmin(p)), float(level))
    resampling = None
    if method.needs_resampling(ref.n, test.n) and crossed:
        # Different pass counts (a fixed reference): a crossing counts where the permutation test, at this look's
        # increment of the spending, rejects the tile-channel too (see `resampling_level`).
        level = resampling_level(fractions, plan)
        resampling = permutation_max_t(runs, level) if level > 0 else None  # 0: this look spends nothing
        adjusted = resampling.adjusted if resampling is not None else [np.ones(s.shape) for s in significant]
        with np.errstate(invalid="ignore"):
            significant = [s & (a <= level) for s, a in zip(significant, adjusted, strict=True)]
        crossed = int(sum(np.sum(s) for s in significant))
    evidence = Evidence(
        design="sequential",
        significant=significant,
        simultaneous=[float(level) for level in scale_levels],
        equivalence=float(equivalence_level),
        whole=float(whole_level),
        final=bool(fractions[-1] >= 1.0) if final is None else final,
        family="every tile-channel of every tile size, at every look",
        resampling=resampling,
        budget=budget,
        planning=planning,
        promise=promise(scales, biased_levels(ahead, shares, plan), fractions[-1] / ahead[-1])
        if plan.futility and plan.tolerance is not None
        else None,
        futility_loss=plan.futility_loss,
    )
    outcome = decide(scales, tests, runs, evidence, plan.alpha, plan.tolerance, _claim(plan, scales, claim_tile),
                     start.identical, whole, start.uncovered)  # fmt: skip
    return Look(
        passes=n,
        fraction=float(fractions[-1]),
        outcome=outcome,
        p_value=best[1],
        threshold=best[2],
        crossed=crossed,
        pixel_use=pixel_share(start.pixel_use, tests),
    )


def _equivalence_level(fractions, claimable: float, plan: SequentialPlan) -> float:
    """The two-sided level of the equivalence intervals at the last of the looks at `fractions`: 2 alpha spent over
    the looks from information `claimable` on, where `equivalent` can be claimed at all (both sides at
    `decision.identical_passes`); the looks before it spend nothing, which that rule, fixed in advance, allows (0
    at a look before it)."""
    spent = tuple(float(f) for f in fractions if f >= claimable)
    if not spent or float(fractions[-1]) < claimable:
        return 0.0
    return float(_levels(spent, (equivalence_alpha(plan.alpha),), plan.spending, plan.reserve)[0])


def _claim(plan: SequentialPlan, scales, sized: int | None) -> Claim | None:
    """The user's `equivalence_tile` as given, else the claim sized for the budget (`sized`: chosen already)."""
    if plan.equivalence_tile is not None or plan.tolerance is None:
        return Claim(check_claim_tile(plan.equivalence_tile, scales, plan.tolerance))
    if sized is not None and sized not in [s.tile for s in scales]:
        raise WelchInputError(f"`claim_tile` must be one of the tested tile sizes, got {sized!r}")
    return Claim(sized, sized=True)
