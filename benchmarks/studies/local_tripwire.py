"""The tripwire (`welch_core.pixels.tripwire`: its median with `global_limit`, each tile-channel with `local_limit`)
on rendered pools: how close unbiased Cycles passes with independent pixels come to its limits, and how often it
refuses pixels that share a shift per pass in one 16x16 region.

    python -m benchmarks.studies.local_tripwire     # -> docs/benchmarks/local_tripwire.csv
    python -m benchmarks.studies.local_tripwire --quick --out /tmp/lt    # few pools and trials: the pipeline

Every pool in the cache (`--cache`; rendered by the tool's own code, `benchmarks.common.pools`), the largest of each
configuration (scene, overrides, sampling pattern, resolution): A/A trials of disjoint random passes, n a side
(`COUNTS`: `check`'s looks up to 16 passes a side, then up to 512), 16-px tiles as `check` and `compare` store
them, the tripwire of both sides as `welch_core.pixel_use` runs it (every tile size, the pixel moments of the
drawn passes). Per pool and count: the largest `local` (a tile-channel's s²(tile sums) / V over its limit; the
tripwire refuses above 1) and where, the trials past the limit without its margin (`beyond_level`: at most about
`TRIPWIRE_ALPHA` of them for normal pixels), the largest median ratio over its limit (`global_max`), and the
trials refused. The pools whose records prove independent pixels (`pixel_eligibility`: Tabulated Sobol, blue
noise) are the calibration; SOBOL_BURLEY and a scrambling distance of 0.1, which the records refuse, are shown
beside them.

Planted (kind ``planted``): the diffuse corner's and the glass caustic's passes with a shift common to the pixels of
one 16x16 tile (x 16, y 16; all three channels) added to each pass, N(0, s²) with s² = (R - 1) V / 256², V the
tile's sum of pixel variances over the whole pool (the channels' mean): the tile sums there vary about R times
what the pixels say (`RATIOS`), the median over the image stays near 1. On the caustic V is carried by rare
bright paths that a few passes mostly miss, so a small draw sees a ratio far above R there.
"""

from __future__ import annotations

import json
import time
import zlib
from pathlib import Path

import numpy as np

import welch_core as wc

from ..common.cache import study_arguments
from ..common.plotting import write_csv
from ..common.pools import Pool, PoolSpec, say

TILE = 16
#: Passes a side: `check`'s looks up to its first 16 passes a side (2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 15, 16), then
#: 32 to 512, `check`'s default budget (where the pool holds twice as many); from `FEW_FROM` a tenth of the trials
#: (a trial of 512 a side reads 1 024 passes).
COUNTS = (2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 15, 16, 32, 64, 128, 256, 512)
FEW_FROM = 256
#: The planted ratio R of the tile's tile-sum variance to its pixels' (1: no shift).
RATIOS = (2.0, 4.0, 16.0, 64.0)
PLANTED_SCENES = ("corner", "corner_glass")
FULL = {"trials": 100, "planted_trials": 100, "quick": False}
QUICK = {"trials": 3, "planted_trials": 3, "quick": True}


def pools(cache: Path) -> list[Pool]:
    """The largest cached pool of each configuration, by scene, pattern and overrides (the diffuse corner's pools
    of consecutive seeds from 1 000 000 are the same configuration)."""
    best: dict[tuple, tuple[int, Path, dict]] = {}
    for meta_path in sorted(Path(cache).glob("pool-*/meta.json")):
        meta = json.loads(meta_path.read_text())
        spec = meta["spec"]
        key = (spec["scene"], tuple(spec["overrides"]), spec["pattern"], spec["resolution"], spec["spp"])
        if key not in best or spec["passes"] > best[key][0]:
            best[key] = (spec["passes"], meta_path.parent, spec)
    out = []
    for _passes, folder, spec in sorted(best.values(), key=lambda e: (e[2]["scene"], e[2]["pattern"], str(e[1]))):
        spec = {**spec, "overrides": tuple(spec["overrides"])}
        out.append(Pool(PoolSpec(**spec), folder))
    return out


def label(pool: Pool) -> str:
    spec = pool.spec
    text = f"{spec.scene} {spec.resolution}², {spec.pattern}"
    return text + "".join(f", {o}" for o in spec.overrides)


def aa_row(pool: Pool, n: int, trials: int) -> dict | None:
    if 2 * n > pool.n:
        return None
    rng = np.random.default_rng(zlib.crc32(f"{label(pool)} {n}".encode()))
    local, median, where, refused, seconds = [], [], [], 0, 0.0
    for _ in range(trials):
        perm = rng.permutation(pool.n)
        ref, test = pool.stats(perm[:n], TILE, pixels=True), pool.stats(perm[n : 2 * n], TILE, pixels=True)
        start = time.perf_counter()
        measured = wc.pixels.tripwire(ref, test)
        seconds += time.perf_counter() - start
        local.append(measured.local)
        median.append(measured.ratio / measured.ratio_limit)
        where.append(measured.where)
        refused += measured.refusal() is not None
    return {
        "kind": "aa",
        "pool": label(pool),
        "record": wc.pixel_eligibility(pool.info) or "independent pixels",
        "passes": n,
        "ratio": 1.0,
        "trials": trials,
        "refused": refused,
        "local_max": max(local),
        "local_median": float(np.median(local)),
        "beyond_level": sum(x * wc.pixels.LOCAL_MARGIN > 1 for x in local),
        "global_max": max(median),
        "tripwire_ms": 1000 * seconds / trials,
        "where": where[int(np.argmax(local))],
    }


def planted_row(pool: Pool, n: int, ratio: float, trials: int) -> dict | None:
    if 2 * n > pool.n:
        return None
    rng = np.random.default_rng(zlib.crc32(f"{label(pool)} planted {n} {ratio}".encode()))
    region = (slice(16, 32), slice(16, 32))
    variance = float(
        np.asarray(pool.images[:, region[0], region[1]], np.float64).var(axis=0, ddof=1).sum(axis=(0, 1)).mean()
    )
    sd = np.sqrt((ratio - 1) * variance) / 256
    refused, local = 0, []
    for _ in range(trials):
        perm = rng.permutation(pool.n)[: 2 * n]
        runs = []
        for side in (np.sort(perm[:n]), np.sort(perm[n:])):
            images = np.asarray(pool.images[side], np.float64)
            images[:, region[0], region[1]] += sd * rng.standard_normal(len(side))[:, None, None, None]
            run = wc.TileStats(*images.shape[1:3], TILE, 3, pool.info, keep_pixel_moments=True)
            for image, seed in zip(images, side, strict=True):
                run.add_pass(image, int(seed))
            runs.append(run)
        measured = wc.pixels.tripwire(*runs)
        refused += measured.refusal() is not None
        local.append(measured.local)
    return {
        "kind": "planted",
        "pool": label(pool),
        "record": "independent pixels but one 16x16 tile",
        "passes": n,
        "ratio": ratio,
        "trials": trials,
        "refused": refused,
        "local_max": max(local),
        "local_median": float(np.median(local)),
        "beyond_level": sum(x * wc.pixels.LOCAL_MARGIN > 1 for x in local),
        "global_max": float("nan"),
        "tripwire_ms": float("nan"),
        "where": "",
    }


def main(argv: list[str] | None = None) -> int:
    args = study_arguments("local_tripwire", __doc__, "three trials of a few pools: the pipeline", argv)
    budget = QUICK if args.quick else FULL
    found = pools(args.cache)
    if args.quick:
        found = [p for p in found if p.spec.resolution == 64 and p.spec.scene == "corner"]
    if not found:
        say(f"no pools in {args.cache}: render them with the other studies (pixel_calibration, power) first")
        return 1
    say(f"{len(found)} pools; limits at 2 / 8 / 16 passes a side and 100 tile-channels: "
        + " / ".join(f"{wc.pixels.local_limit(n, 100):.3g}" for n in (2, 8, 16)))  # fmt: skip
    rows = []
    for pool in found:
        start = time.perf_counter()
        for n in COUNTS:
            row = aa_row(pool, n, budget["trials"] if n < FEW_FROM else max(2, budget["trials"] // 10))
            if row is not None:
                rows.append(row)
        mine = [r for r in rows if r["pool"] == label(pool)]
        say(f"  {label(pool)} ({pool.n} passes): largest local {max(r['local_max'] for r in mine):.3f}, median "
            f"{max(r['global_max'] for r in mine):.3f}; refused {sum(r['refused'] for r in mine)} of "
            f"{sum(r['trials'] for r in mine)} ({time.perf_counter() - start:.0f} s)")  # fmt: skip
    planted = [p for p in found if p.spec.scene in PLANTED_SCENES and p.spec.resolution == 64]
    planted = [p for p in planted if p.spec.pattern == "TABULATED_SOBOL" and not p.spec.overrides]
    for pool in planted:
        for ratio in RATIOS:
            for n in (2, 3, 4, 8, 16):
                row = planted_row(pool, n, ratio, budget["planted_trials"])
                if row is not None:
                    rows.append(row)
                    say(f"  planted {label(pool)}, R {ratio:g}, {n} a side: refused {row['refused']} of "
                        f"{row['trials']}")  # fmt: skip
    name = write_csv(args.out / "local_tripwire.csv", rows)
    calibration = [r for r in rows if r["kind"] == "aa" and r["record"] == "independent pixels"]
    if calibration:
        top = max(calibration, key=lambda r: r["local_max"])
        say(f"independent pixels: {sum(r['refused'] for r in calibration)} refused in "
            f"{sum(r['trials'] for r in calibration)} trials, {sum(r['beyond_level'] for r in calibration)} past the "
            f"local limit without its margin; the largest local {top['local_max']:.3f} ({top['pool']}, "
            f"{top['passes']} a side, {top['where']}), the largest median "
            f"{max(r['global_max'] for r in calibration):.3f} of its limit; wrote {name}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
