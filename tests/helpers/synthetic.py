"""Synthetic data: Welch samples (tile sums) for the tests of the comparison and its summaries, and grey passes
with a planted bias for the add-on's tests."""

import numpy as np

from welch_core import RunInfo, TileStats, save_stats

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


def one_bright_tile():
    """Runs of 20 passes a side, the test side's tile (5, 2) 20 % too bright and nothing else biased."""
    rng = np.random.default_rng(38)
    m = scene_means()
    shift = np.ones_like(m)
    shift[5, 2] = 1.2
    return make_run(tile_sum_samples(rng, 20, m), range(20)), make_run(
        tile_sum_samples(rng, 20, m, shift), range(20, 40)
    )


def grey_stats(seeds, bias=0.0, width=64, height=64, tile=16, seed=0):
    """Passes of grey 0.2 with noise, one a seed; ``bias`` scales the top-left quarter."""
    rng = np.random.default_rng(seed)
    stats = TileStats(height, width, tile, 3, RunInfo(spp=1, renderer="synthetic"))
    for s in seeds:
        image = 0.2 + rng.normal(0.0, 0.05, (height, width, 3))
        image[: height // 2, : width // 2] *= 1.0 + bias
        stats.add_pass(image.astype(np.float32), s)
    return stats


def write_grey_stats(path, seeds, bias=0.0, size=64, tile=16, seed=0) -> str:
    """grey_stats of a square image, saved to `path`; returns the path as a string."""
    save_stats(path, grey_stats(seeds, bias, size, size, tile, seed))
    return str(path)
