"""Synthetic Welch samples for the tests of the comparison and its summaries."""

import numpy as np

from welch_core import TileStats

TILE = 32


def tile_sum_samples(rng, n, mean_tiles, shift=None, tile=TILE):
    """Welch samples of `n` passes: tile sums of per-pixel values with coefficient of variation 1.

    Pixel value = mean * (G_shared + G_channel) / 2 with G ~ Gamma(1/2, 2) (mean 1, variance 2): the shared
    term correlates R, G and B; the per-pixel CV is exactly 1. The sum of tile² such pixels is drawn exactly as
    mean * (Gamma(tile²/2, 2)_shared + Gamma(tile²/2, 2)_channel) / 2, so the Welch samples have CV 1 / tile.
    """
    mean_tiles = np.asarray(mean_tiles, dtype=float)
    if shift is not None:
        mean_tiles = mean_tiles * shift
    k = tile * tile / 2.0
    ty, tx, _ = mean_tiles.shape
    shared = rng.gamma(k, 2.0, size=(n, ty, tx, 1))
    own = rng.gamma(k, 2.0, size=(n, ty, tx, 3))
    return mean_tiles * (shared + own) / 2.0


def scene_means(ty=8, tx=8):
    """A smoothly varying per-pixel mean per tile and channel."""
    y, x = np.mgrid[0:ty, 0:tx]
    return np.stack([0.2 + x / tx, 0.5 + 0.4 * np.sin(y) ** 2, 1.0 + 0.5 * (x * y) / (tx * ty)], axis=-1)


def make_run(sums, seeds, tile=TILE, info=None):
    ty, tx = sums.shape[1:3]
    return TileStats.from_sums(sums, list(seeds), ty * tile, tx * tile, tile, info)
