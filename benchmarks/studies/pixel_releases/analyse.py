"""D per 16x16 tile and RGB channel with the project's own `dependence` and the permutation null of
`dependence_row` (each pixel shuffled across passes on its own; 10 permutations). Run with the project's venv:
PYTHONPATH=$PWD .venv/bin/python benchmarks/studies/pixel_releases/analyse.py
"""

import glob
import json
import os
import zlib

import numpy as np

from benchmarks.studies.pixel_variance import dependence

PERMS = 10
rows = []
for path in sorted(glob.glob("benchmarks/cache/pixel_releases/*.npy")):
    name = os.path.basename(path)[:-4]
    if name.startswith("repeat_"):
        continue
    release, rest = name.split("_", 1)
    scene = "corner_glass" if rest.startswith("corner_glass") else "corner"
    pattern = rest[len(scene) + 1 :]
    images = np.load(path)
    d = dependence(images)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    null = [dependence(rng.permuted(images, axis=0)) for _ in range(PERMS)]
    pooled = np.concatenate([n[np.isfinite(n)] for n in null])
    lo, hi = np.quantile(pooled, [0.01, 0.99])
    dd = d[np.isfinite(d)]
    below, above = float(np.mean(dd < lo)), float(np.mean(dd > hi))
    if dd.max() > pooled.max() or above > 0.05:
        verdict = "ABOVE (positive: unsafe)"
    elif np.median(dd) < lo or below > 0.10:
        verdict = "below (negative: conservative)"
    else:
        verdict = "within (independent)"
    row = dict(
        release=release,
        pattern=pattern,
        scene=scene,
        passes=len(images),
        n=int(dd.size),
        d_median=float(np.median(dd)),
        d_min=float(dd.min()),
        d_max=float(dd.max()),
        null_lo=float(lo),
        null_hi=float(hi),
        null_min=float(pooled.min()),
        null_max=float(pooled.max()),
        frac_below_null1=below,
        frac_above_null99=above,
        verdict=verdict,
    )
    rows.append(row)
    print(
        f"{release:6} {pattern:25} {scene:12} D med {row['d_median']:.2f} [{row['d_min']:.2f}, {row['d_max']:.2f}]"
        f"  null 1-99% [{lo:.2f}, {hi:.2f}] min {row['null_min']:.2f} max {row['null_max']:.2f}"
        f"  <1%:{below:.2f} >99%:{above:.2f}  {verdict}",
        flush=True,
    )
json.dump(rows, open("benchmarks/cache/pixel_releases/dependence.json", "w"), indent=1)

print("\nBit-identity of passes (same seed), per release and scene:")


def load(n):
    p = f"benchmarks/cache/pixel_releases/{n}.npy"
    return np.load(p) if os.path.exists(p) else None


for release in ("4.5.4", "5.1.2", "5.2.3", "5.3.0"):
    for scene in ("corner", "corner_glass"):
        auto = load(f"{release}_{scene}_AUTOMATIC")
        out = []
        for other in ("BLUE_NOISE", "TABULATED_SOBOL"):
            o = load(f"{release}_{scene}_{other}")
            same = sum(np.array_equal(a, b) for a, b in zip(auto, o, strict=True))
            out.append(f"AUTOMATIC==={other}: {same}/{len(auto)}")
        print(f"  {release} {scene}: " + ", ".join(out))
    for p in ("BLUE_NOISE", "TABULATED_SOBOL"):
        rep, full = load(f"repeat_{release}_corner_{p}"), load(f"{release}_corner_{p}")
        same = sum(np.array_equal(a, b) for a, b in zip(rep, full[: len(rep)], strict=True))
        print(f"  {release} corner {p} re-rendered in a new process, seeds 0-4: {same}/5 bit-identical")
