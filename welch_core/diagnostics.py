"""Checks the paper asks the user to do by hand: are the Welch samples normal (§4.1, §5.1), and does a run pass
the test against itself (§6: "first test the reference against itself")?
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tiles import TileStats, tile_row_blocks

__all__ = ["MIN_PASSES_FOR_NORMALITY", "NORMALITY_ALPHA", "SHAPE_LIMIT", "Normality", "normality", "split_halves"]

#: Below this many passes a normality check has no power; such runs are reported as unchecked.
MIN_PASSES_FOR_NORMALITY = 8

#: A tile-channel whose Jarque-Bera p falls below this on either side is not trusted. Strict on purpose: the
#: check must flag gross failures (fireflies, caustics: §5.1) without discarding tiles at random (Jarque-Bera is
#: anti-conservative at small n: at n = 20, 0.46 % of normal samples fall below 1e-3, measured).
NORMALITY_ALPHA = 1e-4

#: ...and only while the shape still matters for the test of a mean of n samples: the two-sided t-test's error
#: terms shrink like g1²/n and g2/n (Edgeworth), so a skewed tile is trusted again once (g1² + |g2|) / n is at
#: most this. Without it, more passes would make a scene with fireflies *less* testable, as the check gains power.
SHAPE_LIMIT = 0.1


@dataclass(frozen=True)
class Normality:
    """Per tile-channel normality of one run's Welch samples."""

    skewness: np.ndarray  # sample skewness g1
    excess_kurtosis: np.ndarray  # sample excess kurtosis g2
    pvalue: np.ndarray  # Jarque-Bera p (NaN where unchecked)
    n: int
    checked: bool  # False when n < MIN_PASSES_FOR_NORMALITY

    @property
    def excess(self) -> np.ndarray:
        """g1² + |g2|: how far one sample is from normal (the mean of n samples: this / n)."""
        return self.skewness**2 + np.abs(self.excess_kurtosis)

    @property
    def shape(self) -> np.ndarray:
        """(g1² + |g2|) / n: how far the mean of n such samples still is from normal."""
        return self.excess / self.n

    @property
    def suspect(self) -> np.ndarray:
        """Tile-channels whose samples are clearly not normal, by too much for the test of their mean."""
        with np.errstate(invalid="ignore"):
            return (self.pvalue < NORMALITY_ALPHA) & (self.shape > SHAPE_LIMIT)


def normality(run: TileStats) -> Normality:
    """Skewness, kurtosis and the Jarque-Bera test of each tile-channel's per-pass sums."""
    sums = run.sums
    shape = run.grid_shape
    if run.n < 3:
        nan = np.full(shape, np.nan)
        return Normality(nan, nan, nan, run.n, checked=False)
    m2, m3, m4 = np.empty(shape), np.empty(shape), np.empty(shape)
    with np.errstate(invalid="ignore", divide="ignore"):  # constant and non-finite tiles have no shape: NaN
        for rows in tile_row_blocks(sums):  # block by block: the temporaries stay small for any grid
            block = sums[:, rows]
            shifted = block - block[0]  # exactly zero for a constant tile, whose mean may be an ulp off
            centred = shifted - shifted.mean(axis=0)
            squared = centred * centred  # products, not **3 and **4, which numpy computes with pow(): 10x slower
            m2[rows], m3[rows], m4[rows] = (
                squared.mean(axis=0),
                (squared * centred).mean(axis=0),
                (squared * squared).mean(axis=0),
            )
        g1 = m3 / m2**1.5  # sample skewness (scipy.stats.skew with bias=True)
        g2 = m4 / m2**2 - 3.0  # sample excess kurtosis (scipy.stats.kurtosis with bias=True)
        jb = run.n / 6.0 * (g1**2 + g2**2 / 4.0)  # Jarque & Bera (1980)
        p = np.exp(-jb / 2.0)  # the chi-square survival function with 2 degrees of freedom
    checked = run.n >= MIN_PASSES_FOR_NORMALITY
    return Normality(g1, g2, p if checked else np.full(shape, np.nan), run.n, checked)


def split_halves(run: TileStats) -> tuple[TileStats, TileStats]:
    """Two disjoint halves of one run (alternate passes, so a drift over the run falls on both), for an A/A test."""
    n = run.n
    return run.subset(np.arange(0, n - n % 2, 2)), run.subset(np.arange(1, n - n % 2, 2))
