"""Sharper check than the 10-permutation table: 200 permutations of each non-blue-noise pool; the observed
median, min and max of D over the 48 tile-channels against their permutation distributions (one-sided p for
max and min, two-sided for the median; p = (1 + #perm at least as extreme) / (1 + P)).
PYTHONPATH=$PWD .venv/bin/python benchmarks/studies/pixel_releases/extended.py"""

import glob
import os
import zlib

import numpy as np

from benchmarks.studies.pixel_variance import dependence

P = 200
for path in sorted(glob.glob("benchmarks/cache/pixel_releases/*.npy")):
    name = os.path.basename(path)[:-4]
    if name.startswith("repeat_") or "BLUE_NOISE" in name or "AUTOMATIC" in name:
        continue
    x = np.load(path)
    d = dependence(x)
    d = d[np.isfinite(d)]
    rng = np.random.default_rng(zlib.crc32(name.encode()) + 1)
    med, mn, mx = [], [], []
    for _ in range(P):
        n = dependence(rng.permuted(x, axis=0))
        n = n[np.isfinite(n)]
        med.append(np.median(n))
        mn.append(n.min())
        mx.append(n.max())
    med, mn, mx = map(np.array, (med, mn, mx))
    p_max = (1 + np.sum(mx >= d.max())) / (1 + P)
    p_min = (1 + np.sum(mn <= d.min())) / (1 + P)
    c = np.median(med)
    p_med = (1 + np.sum(np.abs(med - c) >= abs(np.median(d) - c))) / (1 + P)
    print(
        f"{name:40} D med {np.median(d):.3f} (null {med.min():.3f}-{med.max():.3f}, p {p_med:.3f})  "
        f"min {d.min():.2f} (p {p_min:.3f})  max {d.max():.2f} "
        f"(null max 95% {np.quantile(mx, 0.95):.2f}, p {p_max:.3f})",
        flush=True,
    )
