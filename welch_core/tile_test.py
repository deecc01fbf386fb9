"""What a tile test is: one object per test kind behind one interface, and the per-tile result it returns.

A `TileTestMethod` says which seeds it needs, tests the two runs' tiles of one scale (its p-values, and in the
result the variances its intervals need, `welch_core.effect`), and answers what the decision asks of it: whether
`biased` needs the permutation test's confirmation, whether both sides' passes shrink the standard error, which
runs the pixel test's tripwire measures, whether two runs are one run twice. Each kind is a module of its own
(`welch_core.welch_test`, `welch_core.paired_test`) registered once in `welch_core.tile_tests`.
"""

from __future__ import annotations

import abc
import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .diagnostics import normality
from .pixels import MIN_PIXEL_DF
from .ttest import Reason, TTestResult

if TYPE_CHECKING:
    from .pixels import PixelMoments
    from .tile_tests import TileTestKind
    from .tiles import TileStats

__all__ = ["ROUNDING", "TileTest", "TileTestMethod", "take_pixels"]

#: A relative difference below this is the size of float rounding (float32: 2^-24, 6e-8, per operation; a path is
#: some hundreds of them), not a difference of the light. Two processes of one build can render the same passes
#: with different last bits (Cycles 4.5.4 always; 5.0.1's textured scene in a few tiles, the same in every pass).
ROUNDING = 1e-6


class TileTestMethod(abc.ABC):
    """One kind of tile test (see the module docstring). `kind` is its key in `welch_core.tile_tests.TILE_TESTS`
    and in report files."""

    #: the seeds the test needs, as `welch_core.tile_tests.seed_relation` names them: "disjoint" or "identical"
    seeds: ClassVar[str]
    #: what a user who asks for this test on other seeds is told
    wrong_seeds: ClassVar[str]

    def __init__(self, kind: TileTestKind) -> None:
        self.kind = kind

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.kind.value!r})"

    @abc.abstractmethod
    def test(
        self, ref: TileStats, test: TileStats, pvalue_method: str = "exact", pixels: bool = False,
        pairs: PixelMoments | None = None,
    ) -> TileTest:  # fmt: skip
        """The test of every tile-channel of `ref` and `test` (one scale), with the normality check of its Welch
        samples. `pixels`: take the pixel test's result where it has enough degrees of freedom
        (`welch_core.pixels`); `pairs`: a paired run's moments of each pixel's difference per seed."""

    @abc.abstractmethod
    def pixel_runs(self, ref: TileStats, test: TileStats, differences: TileStats | None) -> tuple | str:
        """The runs whose pixels the pixel test uses and its tripwire measures, or why there are none."""

    @abc.abstractmethod
    def both_sides_grow(self, n_ref: int, n_test: int) -> bool:
        """Whether more passes shrink both sides' part of the standard error (else the reference's is fixed)."""

    def differences(self, ref: TileStats, test: TileStats, pairs: PixelMoments | None) -> TileStats | None:
        """The runs' per-seed differences with their pixel moments, where the test has them (else None)."""
        return None

    def identical_passes(self, ref: TileStats, test: TileStats) -> bool:
        """Whether every pass of `test` is the reference's pass of the same seed (never, with other seeds)."""
        return False

    def needs_resampling(self, n_ref: int, n_test: int) -> bool:
        """Whether `biased` needs the permutation test's confirmation (`welch_core.permutation`)."""
        return False

    def welch_tiles(self, tested: TileTest) -> np.ndarray | bool:
        """Where `tested`'s result is Welch's test of the two sides (the looks take n - 1 degrees of freedom
        there, `welch_core.looks.conservative`)."""
        return False


@dataclass(frozen=True)
class TileTest:
    """The per-tile test of one scale before any decision: the t-test, which tiles are trusted, the means."""

    method: TileTestMethod
    result: TTestResult
    suspect: np.ndarray  # tile-channels whose Welch samples are clearly not normal
    checked: bool  # normality checked (enough passes)
    ref_mean: np.ndarray
    #: the variance of the reference mean's estimate, and its covariance with the mean difference's (-ref_var
    #: for independent sides; paired, from the per-pass covariance): what a ratio's interval needs
    ref_var: np.ndarray
    cross: np.ndarray
    #: paired runs: the tile-channels tested by Welch's test on the two sides instead (`welch_core.paired_test`)
    unpaired: np.ndarray | None = None
    #: paired runs: the tile-channels whose per-pass differences are mostly exact zeros (`SPARSE_SHARE`)
    sparse: np.ndarray | None = None
    #: the tile-channels tested by their pixel variances (`welch_core.pixels`); None where the test did not run
    pixel: np.ndarray | None = None
    #: g1² + |g2| of the samples `suspect` judged (`diagnostics.Normality.excess`): a suspect tile-channel is
    #: trusted again at passes where this over the passes is at most `diagnostics.SHAPE_LIMIT` (`sizing`)
    excess: np.ndarray | None = None

    @property
    def kind(self) -> TileTestKind:
        return self.method.kind

    @property
    def welch(self) -> np.ndarray | bool:
        """Where the result is Welch's test (see `TileTestMethod.welch_tiles`)."""
        return self.method.welch_tiles(self)


def side_checks(ref: TileStats, test: TileStats) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What every test needs of the two sides themselves: the variance of the reference mean's estimate, the
    tile-channels where either side's samples are clearly not normal, and the larger of their shape excesses."""
    with np.errstate(invalid="ignore", divide="ignore"):
        ref_var = ref.variance / ref.n
    of_ref, of_test = normality(ref), normality(test)
    return ref_var, of_ref.suspect | of_test.suspect, np.fmax(of_ref.excess, of_test.excess)


def take_pixels(result: TTestResult, by_pixels: TTestResult) -> tuple[TTestResult, np.ndarray, np.ndarray]:
    """`result` with the pixel test's `by_pixels` where that is valid with at least `MIN_PIXEL_DF` degrees of freedom,
    where that is, and where the pixel test is valid with fewer (a few pixels carry the variance)."""
    valid = by_pixels.reason == Reason.VALID
    with np.errstate(invalid="ignore"):
        use = valid & (by_pixels.df >= MIN_PIXEL_DF)
    return where(use, by_pixels, result), use, valid & ~use


def where(condition: np.ndarray, chosen: TTestResult, other: TTestResult) -> TTestResult:
    """`chosen`'s elements where `condition` holds, `other`'s elsewhere."""
    fields = (f.name for f in dataclasses.fields(TTestResult))
    return TTestResult(**{f: np.where(condition, getattr(chosen, f), getattr(other, f)) for f in fields})
