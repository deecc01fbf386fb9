"""The tile tests, registered once: each kind's name and the `TileTestMethod` that tests it (see
`welch_core.tile_test`). Adding a test is a module with its method and a line here.
"""

from __future__ import annotations

import enum

from .errors import SeedOverlapError, WelchInputError
from .paired_test import PairedTest
from .pixels import PixelMoments
from .tile_test import TileTest, TileTestMethod
from .tiles import TileStats
from .welch_test import WelchTest

__all__ = ["TESTS", "TILE_TESTS", "TileTestKind", "choose_test", "seed_relation", "test_tiles", "tile_test_of"]


class TileTestKind(enum.StrEnum):
    """The test of a tile-channel's passes: Welch's t-test of two runs with disjoint seeds, or the paired t-test of
    their per-pass differences where both runs have the same seeds (the value is its key in report files)."""

    WELCH = "welch"
    PAIRED = "paired"


#: Every kind's method; "auto" picks the first whose seeds fit the runs'.
TILE_TESTS: dict[TileTestKind, TileTestMethod] = {
    TileTestKind.WELCH: WelchTest(TileTestKind.WELCH),
    TileTestKind.PAIRED: PairedTest(TileTestKind.PAIRED),
}

TESTS = ("auto", *(kind.value for kind in TILE_TESTS))


def tile_test_of(kind: str) -> TileTestMethod:
    """The registered method of `kind` (a `TileTestKind` or its value)."""
    if kind not in TILE_TESTS:
        raise WelchInputError(f"`test_kind` must be one of {TESTS[1:]}, got {kind!r}")
    return TILE_TESTS[TileTestKind(kind)]


def seed_relation(ref_seeds, test_seeds) -> str:
    """'disjoint', 'identical' (the same set of seeds) or 'overlap' (some shared, some not)."""
    a, b = set(ref_seeds), set(test_seeds)
    if not a or not b:
        raise WelchInputError("seed lists must not be empty")
    if a == b:
        return "identical"
    return "disjoint" if a.isdisjoint(b) else "overlap"


def choose_test(ref: TileStats, test: TileStats, test_kind: str = "auto") -> TileTestMethod:
    """The method `test_kind` names, or for "auto" the one these runs' seeds call for; raises when the seeds fit
    neither that one nor any."""
    relation = seed_relation(ref.seeds, test.seeds)
    if test_kind not in TESTS:
        raise WelchInputError(f"`test_kind` must be one of {TESTS}, got {test_kind!r}")
    if relation == "overlap":
        shared = len(set(ref.seeds) & set(test.seeds))
        raise SeedOverlapError(
            f"the runs share {shared} seeds but not all: the unpaired test needs disjoint seeds and the paired "
            "test identical ones; render one run again with a fitting seed range"
        )
    if test_kind == "auto":
        return next(method for method in TILE_TESTS.values() if method.seeds == relation)
    method = TILE_TESTS[TileTestKind(test_kind)]
    if method.seeds != relation:
        raise SeedOverlapError(method.wrong_seeds)
    return method


def test_tiles(
    ref: TileStats, test: TileStats, kind: str, pvalue_method: str = "exact", pixels: bool = False,
    pairs: PixelMoments | None = None,
) -> TileTest:  # fmt: skip
    """`kind`'s test of every tile-channel of `ref` and `test` (see `TileTestMethod.test`)."""
    return tile_test_of(kind).test(ref, test, pvalue_method, pixels, pairs)
