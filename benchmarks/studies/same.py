"""Say "the same": what `check` answers on unbiased pairs of every built-in scene, the tile size its `equivalent`
speaks of, whether that claim is ever wrong under a local bias, what its futility stop costs, and `compare` at a
few passes on a caustic.

    python -m benchmarks.studies.same            # pools in benchmarks/cache/ -> docs/benchmarks/same_*.csv, same.png
    python -m benchmarks.studies.same local futility    # some parts only (the local one reads same_aa.csv)
    python -m benchmarks.studies.same --quick --out /tmp/same    # small pools and few runs: the pipeline

Every run replays `check` with its defaults on passes rendered by the tool's own code (`welch_core.sequential_look`
at each look of `look_schedule`, the claim's size kept from its sizing look as `check` keeps it, the pixel test
`auto` on the pool's record, tolerance 1 %, alpha 0.01), at 1 spp a pass, Tabulated Sobol:

* ``aa``: unpaired A/A, every built-in scene at 128x128, the default budget (512 passes a side): disjoint halves of
  a random order of a pool of twice the budget. The verdict, the size claimed and the size planned, the passes a
  side and the seconds of rendering (both sides' median pass times) to the verdict.
* ``paired_aa``: paired A/A on a few scenes: Tabulated Sobol against blue noise with the same seeds (one expected
  image, other random numbers), each pixel's differences folded as `check` folds them; budget 256, from a random
  half of 512 seeds.
* ``local``: `equivalent` where a tile is off: the test side's passes of an A/A split scaled by 1 + `LOCAL_BIAS`
  (1.2 tolerances) in one tile of the size the scene's A/A runs claim (its darkest lit tile, whose noise hides a
  bias the longest), so that a claim at that size or finer is wrong and a coarser one may be right; whether a
  claim is wrong is read off the pool's mean image and the known factor, at the size claimed.
* ``futility``: real biases that `check` finds late in its budget (`POWER`), with and without the futility stop on
  the same pass orders, paired and unpaired: the power the stop gives up.
* ``fixed``: `compare` at 2 v 2, 3 v 3 and 4 v 4 passes of the glass caustic (64x64), unbiased splits: `biased`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import welch_core as wc
from batch.blender.scenes import WALL_COLOR_PATH
from batch.decide.check_job import DEFAULT_MAX_PASSES
from batch.jobs.job import BUILTIN_SCENES

from ..common.cache import study_arguments
from ..common.plotting import plt, save, write_csv
from ..common.pools import PoolSpec, load_or_render, say
from ..common.trials import wilson

ALPHA, TOLERANCE, TILE, RESOLUTION = 0.01, 0.01, 16, 128
#: The bias of the local study, in tolerances: a tile off by this much must never be called equivalent at its size.
LOCAL_BIAS = 1.2
#: Scenes of the local study and of the paired A/A runs.
LOCAL_SCENES = ("corner", "environment", "textured", "volume_noise")
PAIRED_SCENES = ("corner", "glossy", "textured", "sss")
#: (scene, resolution, change, label): biases `check` finds only late in its budget, and one it finds at once.
POWER = (
    ("corner_glass", 64, "cycles.sample_clamp_indirect=20", "caustic, indirect clamp 20"),
    ("glossy", 128, "cycles.blur_glossy=1.0", "glossy, Filter Glossy 1.0"),
    ("corner", 128, f"{WALL_COLOR_PATH}=0.21,0.21,0.21,1", "corner, walls 0.20 -> 0.21"),
)  # fmt: skip
FULL = {"budget": DEFAULT_MAX_PASSES, "aa_runs": 20, "paired_runs": 10, "local_runs": 20, "power_pool": 400,
        "power_budget": 200, "power_runs": 30, "fixed_trials": 2000, "scenes": BUILTIN_SCENES}  # fmt: skip
QUICK = {"budget": 48, "aa_runs": 1, "paired_runs": 1, "local_runs": 1, "power_pool": 48, "power_budget": 24,
         "power_runs": 1, "fixed_trials": 20, "scenes": ("corner", "glossy")}  # fmt: skip


class Side:
    """One side's passes as a check accumulates them: tile sums of the passes so far and their pixel moments
    (Welford, pass by pass), from a pool's images, each multiplied by `factor` (a local bias) where given."""

    def __init__(self, pool, factor: np.ndarray | None = None):
        self.pool, self.factor = pool, factor
        self.moments = wc.PixelMoments(*pool.images.shape[1:])
        self.taken: list[int] = []

    def image(self, index: int) -> np.ndarray:
        image = np.asarray(self.pool.images[index], dtype=np.float64)
        return image if self.factor is None else image * self.factor

    def grow(self, indices) -> None:
        for index in indices[len(self.taken) :]:
            self.moments.add(self.image(index))
            self.taken.append(int(index))

    def stats(self) -> wc.TileStats:
        if self.factor is None:
            sums = self.pool.sums(TILE)[self.taken]
        else:
            sums = np.stack([wc.tile_sums(self.image(i), TILE) for i in self.taken])
        moments = wc.PixelMoments.of(self.moments.mean.copy(), self.moments.m2.copy(), self.moments.n)
        size = self.pool.spec.resolution
        seeds = [self.pool.seeds[i] for i in self.taken]
        return wc.TileStats.from_sums(sums, seeds, size, size, TILE, self.pool.info, pixels=moments)


def replay(ref_pool, test_pool, ref_order, test_order, budget: int, futility: bool = True, factor=None) -> dict:
    """One `check` with its defaults on the passes `ref_order` of `ref_pool` and `test_order` of `test_pool` (the
    same seeds: paired, each pixel's differences folded per look), until it decides or its budget ends."""
    plan = wc.SequentialPlan(max_passes=budget, alpha=ALPHA, tolerance=TOLERANCE, futility=futility,
                             pixel_variance="auto")  # fmt: skip
    ref, test = Side(ref_pool), Side(test_pool, factor)
    paired = [ref_pool.seeds[i] for i in ref_order] == [test_pool.seeds[i] for i in test_order]
    differences = wc.PixelMoments(*ref_pool.images.shape[1:]) if paired else None
    fractions, look, claim = [], None, None
    schedule = wc.look_schedule(budget)
    for k, n in enumerate(schedule):
        fractions.append(n / budget)
        before = len(ref.taken)
        ref.grow(ref_order[:n])
        test.grow(test_order[:n])
        pairs = None
        if paired:
            for i in range(before, n):
                differences.add(test.image(test_order[i]) - ref.image(ref_order[i]))
            pairs = wc.PixelMoments.of(differences.mean.copy(), differences.m2.copy(), differences.n)
        a, b = ref.stats(), test.stats()
        look = wc.sequential_look(a, b, plan, fractions, final=k == len(schedule) - 1, claim_tile=claim,
                                  pairs=pairs)  # fmt: skip
        claim = look.outcome.target_tile
        if look.verdict is not None:
            break
    o = look.outcome
    passes = min(o.n_ref, o.n_test)
    return {
        "verdict": o.verdict.label,
        "reason": o.reason,
        "claim_tile": o.claim_tile if o.verdict == wc.Verdict.EQUIVALENT else None,
        "target_tile": o.target_tile,
        "passes": passes,
        "seconds": round(passes * (ref_pool.seconds_per_pass + test_pool.seconds_per_pass), 2),
        "pixels": bool(look.pixel_use.used),
        "projected": " ".join(f"{s.tile}:{s.projected}" for s in o.scales),
    }


def pool(scene: str, passes: int, cache: Path, *overrides: str, resolution: int = RESOLUTION, pattern=None):
    spec = PoolSpec(scene, tuple(overrides), resolution, passes=passes, **({"pattern": pattern} if pattern else {}))
    return load_or_render(spec, cache, f"{scene} {' '.join(overrides)} {pattern or ''}".strip())


def aa(b: dict, cache: Path) -> tuple[list[dict], dict[str, int]]:
    """Unpaired A/A runs of every scene; also each scene's most often claimed size (for the local study)."""
    rows, sizes = [], {}
    for number, scene in enumerate(b["scenes"]):
        p = pool(scene, 2 * b["budget"], cache)
        rng = np.random.default_rng([50, number])
        start = time.perf_counter()
        for run in range(b["aa_runs"]):
            order = rng.permutation(p.n)
            row = replay(p, p, order[: b["budget"]], order[b["budget"] :], b["budget"])
            rows.append({"part": "aa", "scene": scene, "run": run, "budget": b["budget"], **row})
        mine = [r for r in rows if r["scene"] == scene]
        claimed = [r["claim_tile"] for r in mine if r["claim_tile"]]
        sizes[scene] = max(set(claimed), key=claimed.count) if claimed else None
        say(f"  aa {scene}: " + ", ".join(f"{v} {sum(r['verdict'] == v for r in mine)}" for v in
            ("equivalent", "inconclusive", "biased")) + f"; sizes {sorted(set(claimed))}; median passes "
            f"{np.median([r['passes'] for r in mine]):.0f}; {time.perf_counter() - start:.0f} s")  # fmt: skip
    return rows, sizes


def paired_aa(b: dict, cache: Path) -> list[dict]:
    rows = []
    passes = 2 * b["power_budget"] if b is QUICK else 512
    budget = passes // 2
    for number, scene in enumerate(s for s in PAIRED_SCENES if s in b["scenes"] or b is FULL):
        sobol, blue = pool(scene, passes, cache), pool(scene, passes, cache, pattern="BLUE_NOISE")
        rng = np.random.default_rng([51, number])
        for run in range(b["paired_runs"]):
            order = rng.permutation(passes)[:budget]
            rows.append({"part": "paired_aa", "scene": scene, "run": run, "budget": budget,
                         **replay(sobol, blue, order, order, budget)})  # fmt: skip
        mine = [r for r in rows if r["scene"] == scene]
        say(f"  paired {scene}: " + ", ".join(f"{r['verdict']} {r['claim_tile']} {r['passes']}" for r in mine))
    return rows


def local(b: dict, cache: Path, sizes: dict[str, int]) -> list[dict]:
    """A/A splits whose test side is `LOCAL_BIAS` tolerances brighter in one tile of the size the scene's A/A runs
    claimed (its brightest tile), and whether each `equivalent` is wrong at the size it claims."""
    rows = []
    for number, scene in enumerate(s for s in LOCAL_SCENES if sizes.get(s)):
        p = pool(scene, 2 * b["budget"], cache)
        size = sizes[scene]
        mean = p.mean_image
        factor, (y, x) = _local_factor(mean, size)
        truth = _true_bias(mean, factor)
        rng = np.random.default_rng([52, number])
        for run in range(b["local_runs"]):
            order = rng.permutation(p.n)
            row = replay(p, p, order[: b["budget"]], order[b["budget"] :], b["budget"], factor=factor)
            wrong = row["verdict"] == "equivalent" and truth[row["claim_tile"]] >= TOLERANCE
            rows.append({"part": "local", "scene": scene, "run": run, "budget": b["budget"], **row,
                         "biased_tile": f"{size}x{size} at x {x}, y {y}", "wrong": wrong})  # fmt: skip
        mine = [r for r in rows if r["scene"] == scene]
        say(f"  local {scene} ({size}x{size} +{100 * LOCAL_BIAS * TOLERANCE:.1f} %): "
            + ", ".join(f"{r['verdict']} {r['claim_tile']}" for r in mine)
            + f"; wrong {sum(r['wrong'] for r in mine)}")  # fmt: skip
    return rows


def _local_factor(mean: np.ndarray, size: int):
    """1 everywhere but 1 + LOCAL_BIAS tolerances in the darkest full tile of `size` whose darkest channel has at
    least a tenth of the brightest tile's light (the noisiest a claim still speaks for); and that tile's corner."""
    h, w = mean.shape[:2]
    tiles = {(y, x): float(mean[y : y + size, x : x + size].mean(axis=(0, 1)).min())
             for y in range(0, h - size + 1, size) for x in range(0, w - size + 1, size)}  # fmt: skip
    lit = {corner: level for corner, level in tiles.items() if level >= 0.1 * max(tiles.values())}
    corner = min(lit, key=lit.get)
    factor = np.ones(mean.shape)
    y, x = corner
    factor[y : y + size, x : x + size] = 1.0 + LOCAL_BIAS * TOLERANCE
    return factor, corner


def _true_bias(mean: np.ndarray, factor: np.ndarray) -> dict[int, float]:
    """Per tile size, the largest |relative bias| over its tiles and channels: expected test over reference."""
    out, tile = {}, TILE
    while True:
        ref, test = wc.tile_sums(mean, tile), wc.tile_sums(mean * factor, tile)
        with np.errstate(invalid="ignore", divide="ignore"):
            out[tile] = float(np.nanmax(np.abs(test / ref - 1.0)))
        if tile >= max(mean.shape[:2]):
            return out
        tile *= 2


def futility(b: dict, cache: Path) -> list[dict]:
    """`check` with and without the futility stop on the same pass orders: `biased` found, passes."""
    rows = []
    for number, (scene, resolution, change, label) in enumerate(POWER):
        size = b["power_pool"]
        reference = pool(scene, size, cache, resolution=resolution)
        changed = pool(scene, size, cache, change, resolution=resolution)
        for paired in (False, True):
            rng = np.random.default_rng([53, number, paired])
            budget = b["power_budget"]
            for run in range(b["power_runs"]):
                order = rng.permutation(size)
                ref_order, test_order = (order[:budget], order[:budget]) if paired else (order[:budget],
                                                                                           order[budget:])  # fmt: skip
                for stop in (True, False):
                    row = replay(reference, changed, ref_order, test_order, budget, futility=stop)
                    rows.append({"part": "futility", "scene": label, "run": run, "budget": budget,
                                 "design": ("paired" if paired else "unpaired") + (" stop" if stop else " no stop"),
                                 **row})  # fmt: skip
            for stop in (True, False):
                design = ("paired" if paired else "unpaired") + (" stop" if stop else " no stop")
                mine = [r for r in rows if r["scene"] == label and r["design"] == design]
                found = [r["passes"] for r in mine if r["verdict"] == "biased"]
                say(f"  {label}, {design}: biased {len(found)}/{len(mine)}, passes {sorted(found)}")
    return rows


def fixed(b: dict, cache: Path) -> list[dict]:
    """`compare` at a few passes a side of the glass caustic: unbiased splits called `biased`."""
    p = pool("corner_glass", 400 if b is FULL else 48, cache, resolution=64)
    rows = []
    for k in (2, 3, 4):
        rng = np.random.default_rng([54, k])
        found = 0
        for _ in range(b["fixed_trials"]):
            picked = rng.choice(p.n, 2 * k, replace=False)
            a, c = p.stats(np.sort(picked[:k]), TILE, True), p.stats(np.sort(picked[k:]), TILE, True)
            found += wc.compare(a, c, ALPHA, pixel_variance="auto").verdict == wc.Verdict.BIASED
        low, high = wilson(found, b["fixed_trials"])
        rows.append({"part": "fixed", "scene": "corner_glass 64x64", "run": f"{k} v {k}", "verdict": "biased",
                     "passes": k, "count": found, "trials": b["fixed_trials"], "low": low, "high": high})  # fmt: skip
        say(f"  fixed caustic {k} v {k}: biased {found}/{b['fixed_trials']} [{100 * low:.2f} %, {100 * high:.2f} %]")
    return rows


def chart(rows: list[dict], out: Path) -> str:
    """Per scene: the share of A/A runs per verdict and size claimed, and the median passes to the verdict."""
    runs = [r for r in rows if r["part"] == "aa"]
    scenes = list(dict.fromkeys(r["scene"] for r in runs))
    kinds = [("equivalent", 16), ("equivalent", 32), ("equivalent", 64), ("equivalent", 128), ("inconclusive", None),
             ("biased", None)]  # fmt: skip
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
    y = np.arange(len(scenes))
    start = np.zeros(len(scenes))
    for verdict, tile in kinds:
        share = np.array([np.mean([r["verdict"] == verdict and (tile is None or r["claim_tile"] == tile)
                                   for r in runs if r["scene"] == s]) for s in scenes])  # fmt: skip
        label = f"equivalent at {tile}x{tile}" if tile else verdict
        left.barh(y, share, left=start, label=label)
        start += share
    left.set_yticks(y, scenes)
    left.set_xlabel("share of unbiased runs")
    left.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3)
    left.set_title("check's verdict on A/A pairs, 128x128, default budget")
    right.barh(y, [np.median([r["passes"] for r in runs if r["scene"] == s]) for s in scenes], color="grey")
    right.set_xlabel("median passes a side to the verdict")
    return save(fig, out / "same.png")


PARTS = ("aa", "paired_aa", "local", "futility", "fixed")


def main(argv: list[str] | None = None) -> int:
    import sys

    argv = sys.argv[1:] if argv is None else argv
    parts = [a for a in argv if a in PARTS] or list(PARTS)
    args = study_arguments("same", __doc__, "small pools and few runs (checks the pipeline)",
                           [a for a in argv if a not in PARTS])  # fmt: skip
    b = QUICK if args.quick else FULL
    start = time.perf_counter()
    done = {}
    if "aa" in parts:
        done["aa"], sizes = aa(b, args.cache)
    else:
        sizes = _sizes(args.out / "same_aa.csv")
    for part in parts:
        if part == "paired_aa":
            done[part] = paired_aa(b, args.cache)
        elif part == "local":
            done[part] = local(b, args.cache, sizes)
        elif part == "futility":
            done[part] = futility(b, args.cache)
        elif part == "fixed":
            done[part] = fixed(b, args.cache)
    for part, rows in done.items():
        if rows:
            keys = list(dict.fromkeys(k for r in rows for k in r))
            write_csv(args.out / f"same_{part}.csv", [{k: r.get(k) for k in keys} for r in rows])
    if "aa" in done:
        chart(done["aa"], args.out)
    summary([r for rows in done.values() for r in rows])
    say(f"wrote same_{{{','.join(done)}}}.csv in {args.out} in {time.perf_counter() - start:.0f} s")
    return 0


def _sizes(path: Path) -> dict[str, int]:
    """Each scene's most often claimed size, from an earlier A/A part's CSV."""
    import csv

    claimed: dict[str, list[int]] = {}
    with open(path) as f:
        for row in csv.DictReader(f):
            if row["claim_tile"]:
                claimed.setdefault(row["scene"], []).append(int(row["claim_tile"]))
    return {scene: max(set(tiles), key=tiles.count) for scene, tiles in claimed.items()}


def summary(rows: list[dict]) -> None:
    """The issue's figures, in lines."""
    runs = [r for r in rows if r["part"] == "aa"]
    if runs:
        equivalent = sum(r["verdict"] == "equivalent" for r in runs)
        biased = sum(r["verdict"] == "biased" for r in runs)
        fine = sum(
            1
            for s in dict.fromkeys(r["scene"] for r in runs)
            if np.median([r["claim_tile"] or 10**6 for r in runs if r["scene"] == s]) <= 64
        )
        say(f"A/A: equivalent {equivalent}/{len(runs)}, biased {biased} (alpha {ALPHA}); median claimed size 64x64 or "
            f"finer on {fine} of {len(set(r['scene'] for r in runs))} scenes")  # fmt: skip
    wrong = [r for r in rows if r["part"] == "local" and r["wrong"]]
    say(f"local bias: wrong `equivalent` {len(wrong)} of {sum(r['part'] == 'local' for r in rows)}")


if __name__ == "__main__":
    raise SystemExit(main())
