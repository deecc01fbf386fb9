"""What a budget can bound: the passes a side that would show every tile of a size within the tolerance if the
two sides agree, projected from the variances alone, and the claim of `equivalent` sized to a check's budget.

A user who asks "are these the same?" rarely knows which tile size the budget can speak for: 16x16 tiles of a dark
corner may need thousands of passes where 64x64 tiles need a hundred. So a check that is given no
`--equivalence-tile` fixes the size of its claim at one look, the first at which any claim could be made (both sides
at `decision.identical_passes`: 44 passes at alpha 0.01), from the tile-channels' variances and nothing else: the
finest size whose every tile-channel the budget bounds within the tolerance with probability `SIZING_CHANCE` if the
sides agree (`choose_claim`).

Why this keeps the error rate of `equivalent` at alpha: the claim at a size S holds only where every tile-channel
of S *and of every coarser size* is bounded (`welch_core.decision`). A coarser tile's relative difference is the
reference-weighted mean of its finer tiles' (radiance is not negative), so if some tile of a size is off by the
tolerance or more, so is some tile of every finer size: the sizes whose claim would be wrong are the finest ones,
up to the coarsest wrong size c*. A wrong claim at any size S <= c* then needs c*'s off tile bounded, which its
repeated interval allows with probability at most alpha over all looks. That holds however S was chosen (a fixed
sequence of hypotheses tested coarse to fine, each at alpha: Maurer, Hothorn and Lehmacher 1995), so choosing S
from the variances, or falling back to a coarser size at the budget, never raises the rate; choosing it from the
variances alone, not the differences, keeps the chosen size from leaning towards where the data happen to agree.

The projection (`passes_to_bound`): with n passes a side a tile-channel's estimate has standard error se, and at N
passes se sqrt(n / N) (both sides grow; with a fixed reference only the test side's part shrinks). If the sides
agree its estimate D is normal about 0, and the tile-channel is bounded when |D| + c se_N < tolerance |mu_ref|, c
the equivalence interval's critical value at the budget's last look: probability 2 Phi(tol / se_rel - c) - 1.
Tile-channels are independent enough (disjoint pixels) that the chance every one is bounded is the product.
Tile-channels that no number of passes bounds (a deterministic difference, no finite value) make their size
unreachable; identical ones (zero variance) are bounded already. A tile whose Welch
samples are not normal yet (fireflies) counts from the passes where its shape no longer matters for a mean
(`diagnostics.SHAPE_LIMIT`), as its skewness and kurtosis now say: a planning figure, since a few passes
understate a heavy tail.

Reference: W. Maurer, L. A. Hothorn, W. Lehmacher, "Multiple comparisons in drug clinical trials and preclinical
assays: a-priori ordered hypotheses", Biometrie in der chemisch-pharmazeutischen Industrie 6, 1995.
"""

from __future__ import annotations

import math

import numpy as np

from .diagnostics import SHAPE_LIMIT
from .ttest import Reason

__all__ = ["MAX_PROJECTED", "SIZING_CHANCE", "bound_chance", "choose_claim", "passes_to_bound"]

#: A size is within the budget where, if the sides agree, the budget bounds every tile-channel of it with at
#: least this probability: the power of `equivalent` the plan aims for (the usual 80 % of a sample-size plan).
SIZING_CHANCE = 0.8

#: Projections beyond this many passes a side say "not within reach" (None): nobody renders them.
MAX_PROJECTED = 10**8

#: A projection is a planning figure, "about N passes": found to within this share of N.
PRECISION = 0.005


class _Projection:
    """One size's tile-channels as they would be at N passes a side if the sides agree (see the module
    docstring): everything that does not depend on N computed once, so that the search for N is cheap."""

    def __init__(self, tested, n_ref: int, n_test: int, level: float, tolerance: float):
        from scipy import special  # here: the package is imported where scipy is not (a stock Blender)

        self.special, self.level, self.tolerance = special, level, tolerance
        reasons = tested.result.reason
        valid = reasons == Reason.VALID
        # the passes from which each tile-channel's tile is trusted (0: now; inf: never, a suspect tile whose
        # shape is unknown)
        with np.errstate(invalid="ignore", divide="ignore"):
            excess = tested.excess if tested.excess is not None else np.full(valid.shape, np.inf)
            trusted_from = np.where(tested.suspect, np.nan_to_num(excess / SHAPE_LIMIT, nan=np.inf), 0.0)
        self.trusted_from = np.broadcast_to(trusted_from.max(axis=-1)[..., None], valid.shape)[valid]
        self.blocked = bool(np.any(~valid & (reasons != Reason.ZERO_VARIANCE)))  # no number of passes bounds it
        self.count = int(valid.sum())
        pixel = tested.pixel if tested.pixel is not None else np.zeros(valid.shape, bool)
        self.pixel = pixel[valid]
        se2 = tested.result.standard_error[valid] ** 2
        scale2 = tested.ref_mean[valid] ** 2
        with np.errstate(invalid="ignore", divide="ignore"):
            if tested.method.both_sides_grow(n_ref, n_test):  # se^2 n / N
                self.fixed, self.growing = np.zeros_like(se2), se2 * n_test / scale2
            else:  # a fixed reference: only the test side's part shrinks
                ref_part = np.minimum(tested.ref_var[valid], se2)
                self.fixed, self.growing = ref_part / scale2, (se2 - ref_part) * n_test / scale2

    def chance(self, passes: int) -> float:
        if self.blocked or np.any(self.trusted_from > passes):
            return 0.0  # some tile-channel no number of passes (or not this one) bounds as things stand
        if not self.count:
            return 1.0
        special = self.special
        q = 1.0 - self.level / 2.0
        # the tile sums' test has n - 1 degrees of freedom at looks, the pixel test's are many
        c = np.where(self.pixel, special.ndtri(q), special.stdtrit(max(passes - 1, 1), q))
        with np.errstate(invalid="ignore", divide="ignore"):
            each = 2.0 * special.ndtr(self.tolerance / np.sqrt(self.fixed + self.growing / passes) - c) - 1.0
        if not np.all(np.isfinite(each)) or np.any(each <= 0.0):
            return 0.0
        return float(np.exp(np.sum(np.log(each))))

    def bracket(self, chance: float, floor: int) -> tuple[float, float]:
        """Pass counts below which the chance can't be reached (each tile-channel alone at `chance`) and from which
        it is with a normal critical value (each at chance^(1 / count)); a t quantile may need more than the
        second, never less than the first."""
        special = self.special
        z = special.ndtri(1.0 - self.level / 2.0)
        start = max(float(floor), float(np.max(self.trusted_from, initial=0.0)))

        def need(each: float) -> float:
            room = (self.tolerance / (z + special.ndtri((1.0 + each) / 2.0))) ** 2 - self.fixed
            with np.errstate(invalid="ignore", divide="ignore"):
                return float(np.max(np.where(room > 0, self.growing / room, np.inf), initial=start))

        return max(start, need(chance)), max(start, need(chance ** (1.0 / max(self.count, 1))))


def bound_chance(tested, n_ref: int, n_test: int, passes: int, level: float, tolerance: float) -> float:
    """The probability that every tile-channel of one size is bounded within `tolerance` at `passes` a side if the
    sides agree, its intervals at two-sided error `level` (see the module docstring). A tile whose Welch samples
    are not normal now is trusted there again where its shape allows it at `passes` (`diagnostics.SHAPE_LIMIT`)."""
    return _Projection(tested, n_ref, n_test, level, tolerance).chance(passes)


def passes_to_bound(tested, n_ref: int, n_test: int, level: float, tolerance: float, floor: int,
                    chance: float = SIZING_CHANCE) -> int | None:  # fmt: skip
    """The fewest passes a side (at least `floor`) at which every tile-channel of one size is bounded with
    probability `chance` if the sides agree (`bound_chance`); None where no number of passes up to MAX_PROJECTED
    reaches it (a fixed reference too noisy for the tolerance, untrusted tiles, a reference mean of 0)."""
    projection = _Projection(tested, n_ref, n_test, level, tolerance)

    def enough(passes: float) -> bool:
        return projection.chance(int(math.ceil(passes))) >= chance

    if enough(floor):
        return floor
    low, high = projection.bracket(chance, floor)
    if not (math.isfinite(low) and low <= MAX_PROJECTED and enough(MAX_PROJECTED)):
        return None
    high = min(max(high, low + 1.0), MAX_PROJECTED)
    while not enough(high):  # a t quantile's few degrees of freedom need more than the normal bracket
        low, high = high, min(2.0 * high, MAX_PROJECTED)
    while high - low > max(1.0, PRECISION * low):  # the chance grows with the passes: bisect to the first that does
        middle = (low + high) / 2.0
        low, high = (low, middle) if enough(middle) else (middle, high)
    return int(math.ceil(high))


def choose_claim(projected: list[tuple[int, int | None]], budget: int) -> int:
    """The tile size a check claims `equivalent` at, from (tile, projected passes) of every size, finest first:
    the finest the budget bounds (projection within it), else the coarsest (its best chance)."""
    within = [tile for tile, passes in projected if passes is not None and passes <= budget]
    return within[0] if within else projected[-1][0]
