"""Repeated trials drawn from pools, the detection methods they run, and rates with binomial intervals.

Each trial draws passes from the pools (never renders): an unpaired trial splits the seeds into two random halves
and takes the reference's n passes from one and the test's n passes from the other (disjoint seeds); a paired
trial takes the same n seeds from both pools. Trials resample one pool, so they are not fully independent: two
trials at n = P/2 share most of their passes.

Methods, all at alpha = 0.01: the tool's own `welch_core.compare` (Welch at one tile size each, 16, 32, 64 and
128 = the whole image at 128² px, passed explicitly as `tile=`; Welch at every scale from 16², compare's default;
the paired test likewise; the paper's Gaussian variant at 32²) and two conventional baselines whose thresholds are
calibrated on unbiased pairs to the same false-positive rate: the RMSE of the test's mean image against a
converged reference, and the largest absolute tile-mean difference (a thresholded tile-wise difference image).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

import welch_core as wc

ALPHA = 0.01
BASE_TILE = 16
#: Part of every cached trial result's key, with welch_core's source: bump it when a change here changes results.
TRIALS_VERSION = 3

#: The tool's tests: (tile, test_kind, pvalue_method); tile None is every scale from BASE_TILE (compare's default).
#: A fixed tile is passed to `compare` as `tile=` (coarser tiles are summed from the tile-16 sums); a tile larger
#: than the image is skipped (the quick run's 64² pools).
COMPARE_METHODS = {
    "welch16": (16, "welch", "exact"),
    "welch32": (32, "welch", "exact"),
    "welch64": (64, "welch", "exact"),
    "welch128": (128, "welch", "exact"),
    "welch_multi": (None, "welch", "exact"),
    "gauss32": (32, "welch", "gauss"),
    "paired16": (16, "paired", "exact"),
    "paired32": (32, "paired", "exact"),
    "paired64": (64, "paired", "exact"),
    "paired128": (128, "paired", "exact"),
    "paired_multi": (None, "paired", "exact"),
}
#: Baselines with a threshold calibrated on unbiased pairs.
CALIBRATED_METHODS = ("rmse", "tilediff16")
METHODS = (*COMPARE_METHODS, *CALIBRATED_METHODS)
UNPAIRED = tuple(m for m, (_t, kind, _p) in COMPARE_METHODS.items() if kind == "welch")
PAIRED = tuple(m for m, (_t, kind, _p) in COMPARE_METHODS.items() if kind == "paired")
#: The fixed designs of one tile size (the multi-scale and Gaussian variants aside), per test.
FIXED_WELCH = ("welch16", "welch32", "welch64", "welch128")
FIXED_PAIRED = ("paired16", "paired32", "paired64", "paired128")

LABELS = {
    "welch16": "Welch, 16² tiles",
    "welch32": "Welch, 32² tiles",
    "welch64": "Welch, 64² tiles",
    "welch128": "Welch, 128² (whole image)",
    "welch_multi": "Welch multi-scale (from 16²)",
    "gauss32": "Welch + paper's Gaussian (ν ≥ 20), 32²",
    "paired16": "paired t-test, 16² tiles",
    "paired32": "paired t-test, 32² tiles",
    "paired64": "paired t-test, 64² tiles",
    "paired128": "paired t-test, 128² (whole image)",
    "paired_multi": "paired multi-scale (from 16²)",
    "rmse": "RMSE vs converged reference",
    "tilediff16": "largest tile-mean difference, 16²",
}


def wilson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial rate k/n (stays inside [0, 1] and is sensible at k = 0 or n)."""
    if n == 0:
        return float("nan"), float("nan")
    z = stats.norm.ppf(0.5 + confidence / 2)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    lo = 0.0 if k == 0 else max(0.0, centre - half)  # exact ends: rounding would leave 1e-18 at k = 0
    hi = 1.0 if k == n else min(1.0, centre + half)
    return float(lo), float(hi)


@dataclass(frozen=True)
class Draw:
    """Positions of the passes one trial takes from the reference and the test pool."""

    ref: np.ndarray
    test: np.ndarray


def draw_unpaired(rng: np.random.Generator, passes: int, n: int) -> Draw:
    """n passes from one random half of the seeds for the reference, n from the other half for the test."""
    if 2 * n > passes:
        raise ValueError(f"an unpaired trial of n = {n} a side needs {2 * n} passes, the pool has {passes}")
    perm = rng.permutation(passes)
    return Draw(perm[:n], perm[passes // 2 : passes // 2 + n])


def draw_paired(rng: np.random.Generator, passes: int, n: int) -> Draw:
    """The same n seeds on both sides."""
    idx = rng.choice(passes, n, replace=False)
    return Draw(idx, idx)


def compare_verdicts(ref_pool, test_pool, draw: Draw, methods) -> dict[str, str]:
    """Verdict of each requested `COMPARE_METHODS` entry on one draw (all share its passes); a method whose tile
    does not fit the image is left out."""
    ref16, test16 = ref_pool.stats(draw.ref, BASE_TILE), test_pool.stats(draw.test, BASE_TILE)
    out = {}
    for name in methods:
        tile, kind, pmethod = COMPARE_METHODS[name]
        if tile is not None and tile > min(ref16.height, ref16.width):
            continue
        out[name] = wc.compare(ref16, test16, ALPHA, test_kind=kind, pvalue_method=pmethod, tile=tile).verdict
    return out


def rmse_curve(pool, order: np.ndarray, ns, converged: np.ndarray) -> np.ndarray:
    """RMSE (paper §2) of the mean of the first n passes of `order` against `converged`, for every n in `ns`.

    Nested prefixes of one random order: each n is still a uniformly random subset, at the cost of one pass over
    the largest n instead of one per n.
    """
    total = np.zeros(converged.shape)
    done, out = 0, []
    for n in ns:
        total += np.asarray(pool.images[order[done:n]], dtype=np.float64).sum(axis=0)
        done = n
        out.append(np.sqrt(np.mean((total / n - converged) ** 2)))
    return np.array(out)


def tilediff_curve(ref_pool, test_pool, ref_order: np.ndarray, test_order: np.ndarray, ns) -> np.ndarray:
    """Largest |tile-mean difference| over tile-channels (the tile-wise difference image of paper Fig. 15d)."""
    ref_sums, test_sums = ref_pool.sums(BASE_TILE), test_pool.sums(BASE_TILE)
    ref_csum = np.cumsum(ref_sums[ref_order[: max(ns)]], axis=0)
    test_csum = np.cumsum(test_sums[test_order[: max(ns)]], axis=0)
    return np.array([np.abs(test_csum[n - 1] / n - ref_csum[n - 1] / n).max() for n in ns])


def calibrate(null_values: np.ndarray, alpha: float = ALPHA) -> float:
    """The threshold that unbiased pairs exceed with probability alpha (the empirical 1 - alpha quantile)."""
    return float(np.quantile(null_values, 1.0 - alpha, method="higher"))
