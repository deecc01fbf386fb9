"""The claim of `equivalent` sized to a check's budget (welch_core.sizing) and the futility stop's price: the
projection against a direct computation and a simulation, the size chosen once from the variances and kept, a
claim that is never wrong where a tile of its size is off, and the power the stop gives up."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import special, stats

from welch_core import SequentialPlan, TileStats, compare, information_fraction, look_schedule, sequential_look
from welch_core.decision import FUTILITY_LOSS, identical_passes
from welch_core.looks import promise
from welch_core.sizing import PRECISION, SIZING_CHANCE, bound_chance, choose_claim, passes_to_bound
from welch_core.tile_tests import choose_test
from welch_core.tile_tests import test_tiles as tile_test
from welch_core.ttest import Reason

TILE = 16


def runs(rng, n, mean, sd, shift=1.0, seeds=0):
    """Normal tile sums of `n` passes (n, ty, tx, 3): `mean` per tile-channel, `sd` per pass, times `shift`."""
    sums = rng.normal(mean, sd, (n, *mean.shape)) * shift
    ty, tx = mean.shape[:2]
    return TileStats.from_sums(sums, list(range(seeds, seeds + n)), ty * TILE, tx * TILE, TILE)


def tile_test_of(rng, n, mean, sd):
    ref, test = runs(rng, n, mean, sd), runs(rng, n, mean, sd, seeds=10**6)
    return choose_test(ref, test).test(ref, test)


def test_the_chance_is_the_product_of_each_tile_channels_and_matches_a_simulation():
    """2 Phi(tol / se - c) - 1 per tile-channel, se shrinking as sqrt(n / N), the product over them; and the share
    of simulated normal estimates whose |D| + c se lies within the tolerance."""
    rng = np.random.default_rng(1)
    mean = rng.uniform(50, 150, (2, 2, 3))
    t = tile_test_of(rng, 20, mean, 1.0)
    level, tol, passes = 0.01, 0.01, 400
    c = special.stdtrit(passes - 1, 1 - level / 2)
    se = t.result.standard_error * np.sqrt(20 / passes) / np.abs(t.ref_mean)
    expected = np.prod(2 * special.ndtr(tol / se - c) - 1)
    assert bound_chance(t, 20, 20, passes, level, tol) == pytest.approx(expected, rel=1e-12)
    d = rng.normal(0.0, se, (20_000, *se.shape))
    simulated = np.mean(np.all(np.abs(d) + c * se < tol, axis=(1, 2, 3)))
    assert simulated == pytest.approx(expected, abs=0.01)


def test_the_projection_is_the_first_pass_count_that_reaches_the_chance():
    rng = np.random.default_rng(2)
    t = tile_test_of(rng, 20, rng.uniform(50, 150, (2, 2, 3)), 5.0)
    need = passes_to_bound(t, 20, 20, 0.01, 0.01, floor=44)
    below = int(need * (1 - PRECISION)) - 1  # a planning figure: the first to within PRECISION
    assert bound_chance(t, 20, 20, need, 0.01, 0.01) >= SIZING_CHANCE > bound_chance(t, 20, 20, below, 0.01, 0.01)
    assert passes_to_bound(t, 20, 20, 0.01, 0.5, floor=44) == 44  # a loose tolerance: the floor


def test_a_fixed_reference_too_noisy_and_a_deterministic_tile_are_out_of_reach():
    rng = np.random.default_rng(3)
    mean = np.full((2, 2, 3), 100.0)
    ref, test = runs(rng, 16, mean, 20.0), runs(rng, 16, mean, 20.0, seeds=100)
    fixed = tile_test(ref, test, "welch")  # the reference's 16 passes alone leave an se of 5 % of the mean
    assert passes_to_bound(fixed, 16, 8, 0.01, 0.01, floor=44) is None
    broken = dataclasses.replace(fixed, result=dataclasses.replace(
        fixed.result, reason=np.where(np.arange(12).reshape(2, 2, 3) == 0, Reason.DETERMINISTIC_DIFFERENCE,
                                      fixed.result.reason)))  # fmt: skip
    assert bound_chance(broken, 16, 16, 10**6, 0.01, 0.01) == 0.0


def test_an_untrusted_tile_counts_from_the_passes_where_its_shape_no_longer_matters():
    rng = np.random.default_rng(4)
    t = tile_test_of(rng, 40, np.full((2, 2, 3), 100.0), 1.0)
    suspect = np.zeros(t.suspect.shape, bool)
    suspect[0, 0, 0] = True
    excess = np.where(suspect, 30.0, 0.0)  # g1^2 + |g2| = 30: trusted from 300 passes on (SHAPE_LIMIT 0.1)
    firefly = dataclasses.replace(t, suspect=suspect, excess=excess)
    assert bound_chance(firefly, 40, 40, 299, 0.01, 0.01) == 0.0
    assert bound_chance(firefly, 40, 40, 300, 0.01, 0.01) == pytest.approx(bound_chance(t, 40, 40, 300, 0.01, 0.01))


def test_the_claim_is_the_finest_size_within_the_budget_else_the_coarsest():
    assert choose_claim([(16, 900), (32, 300), (64, 60)], 512) == 32
    assert choose_claim([(16, None), (32, 44), (64, 44)], 512) == 32
    assert choose_claim([(16, 9000), (32, 3000), (64, None)], 512) == 64


def looks_of(ref_sums, test_sums, plan, claim=None, paired=False):
    """Every look of `check` on these sums until a verdict, the claim's size carried from look to look."""
    ty, tx = ref_sums.shape[1:3]
    schedule = look_schedule(plan.max_passes)
    fractions = [information_fraction(n, plan.max_passes) for n in schedule]
    seeds = range(len(test_sums)) if paired else range(10**6, 10**6 + len(test_sums))
    looks = []
    for k, n in enumerate(schedule):
        ref = TileStats.from_sums(ref_sums[:n], range(n), ty * TILE, tx * TILE, TILE)
        test = TileStats.from_sums(test_sums[:n], list(seeds)[:n], ty * TILE, tx * TILE, TILE)
        looks.append(sequential_look(ref, test, plan, fractions[: k + 1], final=k == len(schedule) - 1,
                                     claim_tile=looks[-1].outcome.target_tile if looks else claim))  # fmt: skip
        if looks[-1].verdict is not None:
            break
    return looks


def a_scene(rng, n, shift=1.0):
    """8x8 tiles whose means fall from 400 to 10 (dark corners: their relative noise is large)."""
    y, x = np.mgrid[0:8, 0:8]
    mean = (10 + 390 * np.exp(-((x - 2) ** 2 + (y - 2) ** 2) / 12.0))[..., None] * np.array([1.0, 0.9, 0.8])
    return rng.normal(mean, 0.15 * np.sqrt(mean) * 4, (n, 8, 8, 3)) * shift, mean


def test_the_size_is_chosen_once_from_the_variances_at_the_first_look_that_can_claim_and_kept():
    rng = np.random.default_rng(5)
    ref, _ = a_scene(rng, 512)
    test, _ = a_scene(rng, 512)
    plan = SequentialPlan(max_passes=512, tolerance=0.01)
    looks = looks_of(ref, test, plan)
    first = identical_passes(0.01)
    assert all(look.outcome.target_tile is None for look in looks if look.passes < first)
    sized = [look for look in looks if look.passes >= first]
    target = sized[0].outcome.target_tile
    assert target is not None and all(look.outcome.target_tile == target for look in sized)
    projected = [look.outcome.target.projected for look in sized]
    assert projected[0] <= 512 and max(projected) <= 1.5 * min(projected)  # look to look, the same figure
    finer = [s for s in sized[0].outcome.scales if s.tile < target]
    assert finer and all(s.projected is None or s.projected > 512 for s in finer)  # the finest the budget bounds
    last = looks[-1]
    assert last.verdict == "equivalent" and last.outcome.claim_tile >= target, last.outcome.reason
    # The same passes with the user's size keep it: strict, no fallback.
    given = looks_of(ref, test, dataclasses.replace(plan, equivalence_tile=TILE))
    assert given[-1].outcome.target_tile is None and given[-1].outcome.claim_tile == TILE


@pytest.mark.slow
def test_equivalent_is_never_claimed_at_a_size_where_a_tile_is_off():
    """300 sequences whose test side is off by exactly the tolerance (2 %) in one 2x2 block of the base tiles
    (a 32x32 tile), alpha = 0.05, the claim sized for a budget of 256: `equivalent` at 32x32 or finer (wrong) in
    at most alpha of them; a claim at 64x64 (the whole image) is right, the block's bias averaging out there.
    Measured: wrong in 0 of 300 (`biased` in all 300: a bias of the tolerance in a size the budget bounds is a
    bias the budget finds)."""
    rng = np.random.default_rng(6)
    mean = rng.uniform(300.0, 500.0, (4, 4, 3))
    plan = SequentialPlan(max_passes=256, alpha=0.05, tolerance=0.02)
    factor = np.ones_like(mean)
    factor[:2, :2] = 1.02
    verdicts = []
    for _ in range(300):
        ref = rng.normal(mean, 0.02 * mean, (256, 4, 4, 3))
        test = rng.normal(mean * factor, 0.02 * mean, (256, 4, 4, 3))
        last = looks_of(ref, test, plan)[-1]
        verdicts.append((last.verdict, last.outcome.claim_tile))
    wrong = sum(v == "equivalent" and tile <= 2 * TILE for v, tile in verdicts)
    print(f"wrong {wrong} of 300; biased {sum(v == 'biased' for v, _ in verdicts)}")
    assert wrong <= stats.binom.ppf(0.999, 300, 0.05), wrong
    assert sum(v == "biased" for v, _ in verdicts) > 250


def test_the_promise_is_the_conditional_power_under_the_bias_the_budget_detects():
    """One tile-channel with z now at information t: Phi((z sqrt(t) + z_b (1 - t) - c t) / sqrt(1 - t))."""
    rng = np.random.default_rng(7)
    ref, test = runs(rng, 20, np.full((1, 1, 3), 100.0), 5.0), runs(rng, 20, np.full((1, 1, 3), 100.0), 5.0, 100)
    scale = compare(ref, test, tile=TILE).scales[0]
    level, t = 1e-3, 0.5
    p = float(np.min(scale.pvalues))
    z, c, zb = special.ndtri(1 - p / 2), special.ndtri(1 - level / 2), special.ndtri(0.8)
    expected = special.ndtr((z * np.sqrt(t) + zb * (1 - t) - c * t) / np.sqrt(1 - t))
    assert promise([scale], [level], t) == pytest.approx(expected, rel=1e-12)
    assert promise([scale], [level], 1.0) == 1.0


def test_the_futility_stop_gives_up_the_power_its_plan_allows():
    """The stop's price is the plan's: a look whose most promising tile-channel still has a 38 % chance to reach
    `biased` by the budget goes on at the default 5 % and stops at 50 %, and the outcome says which price it paid."""
    rng = np.random.default_rng(8)
    mean = np.full((2, 2, 3), 100.0)
    ref_sums, test_sums = rng.normal(mean, 4.0, (100, 2, 2, 3)), rng.normal(mean, 4.0, (100, 2, 2, 3))
    ref = TileStats.from_sums(ref_sums[:48], range(48), 2 * TILE, 2 * TILE, TILE)
    test = TileStats.from_sums(test_sums[:48], range(1000, 1048), 2 * TILE, 2 * TILE, TILE)
    fractions = [information_fraction(n, 100) for n in look_schedule(100) if n <= 48]
    looks = {}
    for loss in (FUTILITY_LOSS, 0.5):
        plan = SequentialPlan(max_passes=100, alpha=0.01, tolerance=0.001, futility_loss=loss)
        looks[loss] = sequential_look(ref, test, plan, fractions).outcome
    assert looks[0.5].promise == looks[FUTILITY_LOSS].promise == pytest.approx(0.38, abs=0.01)
    assert looks[FUTILITY_LOSS].reason == "undecided" and looks[0.5].reason == "futile"
    assert [looks[loss].to_json()["futility_loss"] for loss in looks] == [FUTILITY_LOSS, 0.5]


@pytest.mark.slow
def test_the_futility_stop_gives_up_at_most_its_share_of_power_against_the_bias_the_budget_detects():
    """200 sequences with one tile-channel biased by about its minimum detectable bias at the budget (80 % power at
    its level), the tolerance so tight that `equivalent` is out of reach: `biased` with the futility stop at most
    FUTILITY_LOSS (plus the binomial noise of 200 paired runs) below `biased` without it; and the stop does end
    runs early."""
    rng = np.random.default_rng(8)
    mean = np.full((2, 2, 3), 100.0)
    budget, sd = 100, 4.0
    plan = SequentialPlan(max_passes=budget, alpha=0.01, tolerance=0.001)
    scales, tile_channels = 2, 2 * 2 * 3
    level = 0.01 / (scales * tile_channels)  # about the finest scale's share at the last look
    drift = special.ndtri(1 - level / 2) + special.ndtri(0.8)
    shift = np.ones_like(mean)
    shift[1, 0, 0] = 1 + drift * sd * np.sqrt(2 / budget) / 100  # the bias the budget detects there
    found = {True: 0, False: 0}
    stopped = []
    for _ in range(200):
        ref, test = rng.normal(mean, sd, (budget, 2, 2, 3)), rng.normal(mean * shift, sd, (budget, 2, 2, 3))
        for stop in (True, False):
            last = looks_of(ref, test, dataclasses.replace(plan, futility=stop))[-1]
            found[stop] += last.verdict == "biased"
            if stop and last.outcome.reason == "futile":
                stopped.append(last.passes)
    print(found, len(stopped), min(stopped, default=None), max(stopped, default=None))
    assert found[False] - found[True] <= 200 * FUTILITY_LOSS + 3 * np.sqrt(200 * FUTILITY_LOSS)
    assert stopped  # the stop happens: it saves passes where nothing is found
