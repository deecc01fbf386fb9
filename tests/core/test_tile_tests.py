"""The tile tests behind one interface (welch_core.tile_test) and their registry (welch_core.tile_tests)."""

import numpy as np
import pytest

import welch_core as wc
from welch_core.errors import SeedOverlapError, WelchInputError
from welch_core.tile_tests import TILE_TESTS, TileTestKind, choose_test, tile_test_of
from welch_core.welch_test import WelchTest


def run(rng, seeds, scale=1.0):
    seeds = list(seeds)
    sums = rng.normal(100.0 * scale, 5.0, (len(seeds), 4, 4, 3))
    return wc.TileStats.from_sums(sums, seeds, 64, 64, 16)


def test_every_kind_is_registered_once_with_its_own_seeds():
    assert list(TILE_TESTS) == list(TileTestKind) and wc.TESTS == ("auto", "welch", "paired")
    for kind, method in TILE_TESTS.items():
        assert method.kind is kind and tile_test_of(kind.value) is method and isinstance(method, wc.TileTestMethod)
    assert sorted(method.seeds for method in TILE_TESTS.values()) == ["disjoint", "identical"]


def test_the_seeds_choose_the_test_and_refuse_the_other():
    rng = np.random.default_rng(1)
    ref, disjoint, same = run(rng, range(4)), run(rng, range(10, 14)), run(rng, [3, 2, 1, 0])
    assert choose_test(ref, disjoint) is TILE_TESTS[TileTestKind.WELCH]
    assert choose_test(ref, same) is TILE_TESTS[TileTestKind.PAIRED]
    with pytest.raises(SeedOverlapError, match=r"^the paired test needs the same seeds on both sides, but the seed"):
        choose_test(ref, disjoint, "paired")
    with pytest.raises(SeedOverlapError, match=r"^the runs use identical seeds, so their passes are not independent"):
        choose_test(ref, same, "welch")
    with pytest.raises(SeedOverlapError, match=r"^the runs share 2 seeds but not all"):
        choose_test(ref, run(rng, [2, 3, 4, 5]))
    with pytest.raises(WelchInputError, match=r"^`test_kind` must be one of \('auto', 'welch', 'paired'\), got 'z'$"):
        choose_test(ref, disjoint, "z")
    with pytest.raises(WelchInputError, match=r"^`test_kind` must be one of \('welch', 'paired'\), got 'auto'$"):
        tile_test_of("auto")


class Counting(WelchTest):
    """Welch's test that counts the tiles it tests: a test registered in place of another."""

    def __init__(self, kind):
        super().__init__(kind)
        self.tested = []

    def test(self, ref, test, pvalue_method="exact", pixels=False, pairs=None):
        self.tested.append(ref.tile)
        return super().test(ref, test, pvalue_method, pixels, pairs)


def test_the_registered_method_is_the_one_every_decision_uses(monkeypatch):
    """A method registered for a kind tests every scale and the whole image of `compare` and of a look, and what it
    returns is what they decide from: the registry is the one place a test is looked up."""
    rng = np.random.default_rng(2)
    ref, test = run(rng, range(8)), run(rng, range(10, 18), scale=1.05)
    expected = wc.compare(ref, test).outcome.to_json()
    counting = Counting(TileTestKind.WELCH)
    monkeypatch.setitem(TILE_TESTS, TileTestKind.WELCH, counting)
    assert wc.compare(ref, test).outcome.to_json() == expected
    assert counting.tested == [16, 32, 64, 64]  # every scale, then the whole image (one tile of the image)
    counting.tested.clear()
    wc.sequential_look(ref, test, wc.SequentialPlan(max_passes=64), [8 / 64])
    assert counting.tested == [16, 32, 64, 64]


def test_a_method_says_what_the_decision_asks_of_it():
    welch, paired = TILE_TESTS[TileTestKind.WELCH], TILE_TESTS[TileTestKind.PAIRED]
    assert welch.needs_resampling(4, 8) and not welch.needs_resampling(8, 8) and not paired.needs_resampling(4, 4)
    assert welch.both_sides_grow(8, 8) and not welch.both_sides_grow(4, 8) and paired.both_sides_grow(8, 8)
    rng = np.random.default_rng(3)
    ref, test = run(rng, range(4)), run(rng, range(4))
    assert welch.pixel_runs(ref, test, None) == (ref, test)
    assert paired.pixel_runs(ref, test, None) == "the paired runs' per-seed pixel differences were not kept"
    assert welch.differences(ref, test, None) is None and paired.differences(ref, test, None) is None
    assert not welch.identical_passes(ref, ref) and not paired.identical_passes(ref, test)
    tested = paired.test(ref, test)
    assert tested.kind is TileTestKind.PAIRED and tested.welch is tested.unpaired
    assert welch.test(ref, run(rng, range(9, 13))).welch is True
