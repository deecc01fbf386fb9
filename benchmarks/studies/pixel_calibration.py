"""The pixel-variance test as the tool runs it: false `biased` under H0, fixed designs and `check`'s stopping rule.

    python -m benchmarks.studies.pixel_calibration     # -> docs/benchmarks/pixel_calibration.{csv,png}
    python -m benchmarks.studies.pixel_calibration --quick --out /tmp/pc    # small pools, few trials: the pipeline

A/A trials on the pools of `benchmarks.studies.pixel_variance` and of every other built-in scene (`SCENES`: 64²,
1 spp, Tabulated Sobol and blue noise (= AUTOMATIC), 400 passes, rendered here where the cache lacks them), all
rendered by the tool's own code
(each pool's record is the run's: its sampling pattern and settings decide `--pixel-variance auto`), unpaired
(disjoint random passes of one pool on the two sides):

* fixed designs: `welch_core.compare` (every scale, Holm and KS, the permutation test where the counts differ) at
  2 v 2, 3 v 3, 4 v 4, 8 v 8, 2 v 8 and 4 v 16 passes, with ``pixel_variance`` auto and off; on the settings whose
  records do not prove independent pixels, also "on" (the user vouches), where the tripwire must refuse them;
* `check`'s stopping rule: `welch_core.sequential_look` at every look of `look_schedule` up to a budget of
  `BUDGET` passes a side (tolerance 1 %, futility on: a run stops at `biased`, `equivalent`, futility or the
  budget, as `benchmarks.common.checks` replays `check`), with ``pixel_variance`` auto;
* a blessed reference against a short run: 256 v 4, 256 v 8 and 4 v 256 passes of the caustic and the glossy room
  (`UNEQUAL`), `compare` with its permutation test, pixel test on and off;
* paired A/A: two unbiased sampling patterns of one scene rendered with the same seeds (`PAIRED`: one expected
  image, each pass's pixels paired by seed, each pixel's difference folded as `check` folds it), fixed at 2, 3, 4
  and 8 passes and under the stopping rule;
* `check`'s own seeds: runs of consecutive seeds as `check --unpaired` renders them (the reference's from 0, the
  test's from 1 000 000; replicate r takes the r-th block of `BUDGET` seeds of each), replayed in that order, pixel
  test on and off (`CONSECUTIVE`; 32² pools of `BUDGET` x `replicates` passes, rendered here): the design a
  random draw from a pool would hide a correlation between consecutive seeds from;
* `equivalent` where it is false: the test side is the pool's other passes scaled by 1 + tolerance (every tile
  off by exactly the tolerance), the tolerance chosen per pool as the smallest of `TOLERANCES` at which half of
  the A/A trials at 48 v 48 end `equivalent` with the pixel test (where the claim is within reach; `equivalent`
  needs 44 passes a side); at 48 v 48 with the pixel test on and off, and under the stopping rule with a budget of
  `EQUIVALENCE_BUDGET` on the first two pools (`equivalence_runs` runs).

Each cell: the verdict it must not give (`biased` under H0, `equivalent` at the tolerance) in `trials` runs with
its 95 % Wilson interval, and how often the pixel test ran (the tripwire or the record refused it otherwise). The
issue's criterion: rate <= 1.5 alpha with the interval's lower end below alpha, alpha = 0.01.
"""

from __future__ import annotations

import time
import zlib

import numpy as np

import welch_core as wc

from ..common import checks
from ..common.cache import study_arguments
from ..common.plotting import save, write_csv
from ..common.pools import PoolSpec, say
from ..common.trials import wilson
from .pixel_variance import POOLS, load, pool_spec

ALPHA, TILE = 0.01, 16
FIXED = ((2, 2), (3, 3), (4, 4), (8, 8), (2, 8), (4, 16))
#: `check`'s budget in the replays: looks at 2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 15, 16 passes a side.
BUDGET = 16
#: Pools whose records do not prove independent pixels: also run with "on", the user vouching for them.
UNPROVEN = ("corner_burley", "corner_glass_burley", "corner_scrambling")
#: The other built-in scenes (batch.jobs.job.BUILTIN_SCENES): (name, label, scene, overrides, pattern, passes in
#: the full run, passes in the quick run, rendered by this study), as `pixel_variance.POOLS`.
SCENES = tuple(
    (f"{scene}{suffix}", scene.replace("_", " ") + label, scene, (), pattern, 400, 40, True)
    for suffix, label, pattern in (("", "", "TABULATED_SOBOL"), ("_blue", ", blue noise", "BLUE_NOISE"))
    for scene in ("corner_mesh_light", "glossy_rough", "glossy_sharp", "many_lights", "environment", "volume",
                  "volume_noise", "sss", "depth_of_field", "motion_blur", "hair", *(("glossy", "textured")
                  if pattern == "BLUE_NOISE" else ()))
)  # fmt: skip
#: Paired A/A pools: (reference, test, label), both rendered with seeds from 0.
PAIRED = (("corner", "corner_blue", "diffuse corner, Sobol v blue noise"),
          ("corner_glass", "corner_glass_blue", "glass caustic, Sobol v blue noise"))  # fmt: skip
PAIRED_FIXED = (2, 3, 4, 8)
#: Very unequal counts (reference, test) and the pools they are drawn from.
UNEQUAL, UNEQUAL_POOLS = ((256, 4), (256, 8), (4, 256)), ("corner_glass", "glossy")
#: Scenes rendered in runs of consecutive seeds (`consecutive_rows`), at this resolution, and the test side's first
#: seed (`batch.decide.check_job.UNPAIRED_SEEDS`).
CONSECUTIVE, CONSECUTIVE_RESOLUTION, TEST_SEEDS = ("corner", "corner_glass"), 32, 1_000_000
#: The pools, tolerances, passes and budget of the `equivalent` rows.
EQUIVALENCE_POOLS = ("corner", "corner_glass", "glossy", "textured")
TOLERANCES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5)
EQUIVALENCE_PASSES, EQUIVALENCE_BUDGET = 48, 64
FULL = {"trials": 400, "runs": 400, "equivalence_runs": 200, "replicates": 400, "quick": False}
QUICK = {"trials": 8, "runs": 4, "equivalence_runs": 2, "replicates": 3, "quick": True}


def fixed_rows(name: str, label: str, pool, trials: int, designs=FIXED, kind: str = "fixed") -> list[dict]:
    modes = ("auto", "off", "on") if name in UNPROVEN else ("auto", "off")
    rows = []
    for n_ref, n_test in designs:
        if max(n_ref, n_test) > pool.n // 2:
            continue  # the quick pools are too small
        rng = np.random.default_rng(zlib.crc32(f"{name} {n_ref} {n_test}".encode()))
        biased, used = dict.fromkeys(modes, 0), dict.fromkeys(modes, 0)
        for _ in range(trials):
            perm = rng.permutation(pool.n)
            ref = pool.stats(perm[:n_ref], TILE, pixels=True)
            test = pool.stats(perm[pool.n // 2 : pool.n // 2 + n_test], TILE, pixels=True)
            for mode in modes:
                c = wc.compare(ref, test, ALPHA, "welch", pixel_variance=mode)
                biased[mode] += c.verdict.label == "biased"
                used[mode] += c.pixel_use.used
        for mode in modes:
            rows.append(row(kind, name, label, f"{n_ref} v {n_test}", mode, biased[mode], used[mode], trials))
    return rows


def sequential_row(name: str, label: str, pool, runs: int) -> dict:
    plan = wc.SequentialPlan(max_passes=BUDGET, alpha=ALPHA, test_kind="welch", pixel_variance="auto")
    rng = np.random.default_rng(zlib.crc32(f"{name} sequential".encode()))
    done = []
    for _ in range(runs):
        perm = rng.permutation(pool.n)
        done.append(checks.one_run(pool, pool, perm[: pool.n // 2], perm[pool.n // 2 :], plan))
    return sequential(name, label, f"check, budget {BUDGET}", "auto", done)


def sequential(name, label, design, mode, done: list[dict], verdict: str = "biased") -> dict:
    """The row of simulated checks `done`: how many ended `verdict`, how many took the pixel test at their end."""
    found = sum(run["verdict"] == verdict for run in done)
    return row("sequential", name, label, design, mode, found, sum(run["pixels"] for run in done), len(done))


def paired_rows(pools: dict, trials: int, runs: int) -> list[dict]:
    rows = []
    for ref_name, test_name, label in PAIRED:
        ref, test = pools[ref_name], pools[test_name]
        common = min(ref.n, test.n)
        name = f"{ref_name}+{test_name}"
        for n in PAIRED_FIXED:
            rng = np.random.default_rng(zlib.crc32(f"{name} {n}".encode()))
            biased, used = {"auto": 0, "off": 0}, {"auto": 0, "off": 0}
            for _ in range(trials):
                seeds = np.sort(rng.choice(common, n, replace=False))
                a, b = ref.stats(seeds, TILE, pixels=True), test.stats(seeds, TILE, pixels=True)
                pairs = wc.PixelMoments.of_passes(np.asarray(test.images[seeds], float) - ref.images[seeds])
                for mode in biased:
                    c = wc.compare(a, b, ALPHA, "paired", pixel_variance=mode, pairs=pairs)
                    biased[mode] += c.verdict.label == "biased"
                    used[mode] += c.pixel_use.used
            rows += [row("paired", name, label, f"{n} paired", m, biased[m], used[m], trials) for m in biased]
        plan = wc.SequentialPlan(max_passes=BUDGET, alpha=ALPHA, test_kind="paired", pixel_variance="auto")
        rng = np.random.default_rng(zlib.crc32(f"{name} sequential".encode()))
        done = [checks.one_run(ref, test, perm, perm, plan) for perm in (rng.permutation(common) for _ in range(runs))]
        rows.append(
            sequential(name, label, f"check paired, budget {BUDGET}", "auto", done) | {"kind": "paired sequential"}
        )
        say(f"  {label}: paired, worst {max(r['biased'] for r in rows[-9:])} of {trials}")
    return rows


def consecutive_rows(cache, replicates: int) -> list[dict]:
    rows = []
    for scene in CONSECUTIVE:
        passes = BUDGET * replicates
        ref, test = (load(PoolSpec(scene, (), CONSECUTIVE_RESOLUTION, passes=passes, first_seed=first), cache, scene)
                     for first in (0, TEST_SEEDS))  # fmt: skip
        for mode in ("auto", "off"):
            plan = wc.SequentialPlan(max_passes=BUDGET, alpha=ALPHA, test_kind="welch", pixel_variance=mode)
            blocks = [np.arange(r * BUDGET, (r + 1) * BUDGET) for r in range(replicates)]
            done = [checks.one_run(ref, test, block, block, plan) for block in blocks]
            label = f"{scene.replace('_', ' ')}, {CONSECUTIVE_RESOLUTION}², consecutive seeds"
            rows.append(sequential(f"{scene}_seeds", label, f"check, budget {BUDGET}", mode, done)
                        | {"kind": "consecutive"})  # fmt: skip
        say(
            f"  {scene}, consecutive seeds: " + ", ".join(f"{r['mode']} {r['biased']}/{r['trials']}" for r in rows[-2:])
        )
    return rows


class Scaled:
    """A pool whose passes are scaled by `factor`: a bias of exactly factor - 1 in every tile."""

    def __init__(self, pool, factor: float):
        self.pool, self.factor, self.n = pool, factor, pool.n

    def stats(self, indices, tile: int, pixels: bool = False) -> wc.TileStats:
        run, f = self.pool.stats(indices, tile, pixels), self.factor
        moments = None if run.pixels is None else wc.PixelMoments.of(run.pixels.mean * f, run.pixels.m2 * f * f, run.n)
        return wc.TileStats.from_sums(run.sums * f, run.seeds, run.height, run.width, tile, run.info, pixels=moments)


def equivalence_rows(name: str, label: str, pool, trials: int, runs: int) -> list[dict]:
    half, n = pool.n // 2, min(EQUIVALENCE_PASSES, pool.n // 2)
    rng = np.random.default_rng(zlib.crc32(f"{name} equivalence".encode()))
    draws = [rng.permutation(pool.n) for _ in range(trials)]

    def equivalent(tolerance, ref_pool, test_pool, mode, draws):
        """(`equivalent` verdicts, pixel test used) over `draws`."""
        found = used = 0
        for perm in draws:
            ref, test = ref_pool.stats(perm[:n], TILE, True), test_pool.stats(perm[half : half + n], TILE, True)
            c = wc.compare(ref, test, ALPHA, "welch", tolerance=tolerance, pixel_variance=mode)
            found, used = found + (c.verdict.label == "equivalent"), used + c.pixel_use.used
        return found, used

    reach = [t for t in TOLERANCES if equivalent(t, pool, pool, "auto", draws[:40])[0] >= 20]
    if not reach:
        return []
    tolerance = reach[0]
    scaled = Scaled(pool, 1.0 + tolerance)
    rows = []
    for mode in ("auto", "off"):
        found, used = equivalent(tolerance, pool, scaled, mode, draws)
        rows.append(row("equivalence", name, label, f"{n} v {n} at +{tolerance:.0%}", mode, found, used, trials))
    if runs and name in EQUIVALENCE_POOLS[:2]:
        budget = min(EQUIVALENCE_BUDGET, half)
        plan = wc.SequentialPlan(max_passes=budget, alpha=ALPHA, tolerance=tolerance, test_kind="welch",
                                 pixel_variance="auto")  # fmt: skip
        done = [checks.one_run(pool, scaled, p[:half], p[half:], plan) for p in draws[:runs]]
        design = f"check at +{tolerance:.0%}, budget {budget}"
        rows.append(sequential(name, label, design, "auto", done, "equivalent") | {"kind": "equivalence sequential"})
    say(f"  {label}: `equivalent` at a bias of exactly {tolerance:.0%}: "
        + ", ".join(f"{r['design']} {r['mode']} {r['biased']}/{r['trials']}" for r in rows))  # fmt: skip
    return rows


def row(kind, name, label, design, mode, biased, used, trials) -> dict:
    """A cell: `biased` counts the verdict the design must not give (`equivalent` for the equivalence rows)."""
    low, high = wilson(biased, trials)
    ok = biased / trials <= 1.5 * ALPHA and low < ALPHA
    return {"kind": kind, "pool": name, "label": label, "design": design, "mode": mode, "biased": biased,
            "trials": trials, "rate": biased / trials, "low": low, "high": high, "pixel_used": used,
            "meets": ok}  # fmt: skip


def measure(budget: dict, cache, parts=("unpaired", "unequal", "paired", "consecutive", "equivalence")) -> list[dict]:
    rows, pools = [], {}
    for entry in (*POOLS, *SCENES):
        name, label = entry[0], entry[1]
        pool = pools[name] = load(pool_spec(entry, budget["quick"]), cache, label)
        if "unpaired" not in parts:
            continue
        start = time.perf_counter()
        rows += fixed_rows(name, label, pool, budget["trials"])
        rows.append(sequential_row(name, label, pool, budget["runs"]))
        worst = max((r for r in rows if r["pool"] == name and r["mode"] != "off"), key=lambda r: r["rate"])
        say(f"  {label}: worst {worst['biased']}/{worst['trials']} ({worst['design']}, {worst['mode']}) "
            f"in {time.perf_counter() - start:.0f} s")  # fmt: skip
    if "unequal" in parts:
        labels = {entry[0]: entry[1] for entry in POOLS}
        for name in UNEQUAL_POOLS:
            rows += fixed_rows(name, labels[name], pools[name], budget["trials"], UNEQUAL, "unequal")
            say(f"  {labels[name]}: unequal counts, " + ", ".join(f"{r['design']} {r['mode']} {r['biased']}"
                                                                  for r in rows[-6:]))  # fmt: skip
    if "paired" in parts:
        rows += paired_rows(pools, budget["trials"], budget["runs"])
    if "consecutive" in parts:
        rows += consecutive_rows(cache, budget["replicates"])
    if "equivalence" in parts:
        labels = {entry[0]: entry[1] for entry in POOLS}
        for name in EQUIVALENCE_POOLS:
            rows += equivalence_rows(name, labels[name], pools[name], budget["trials"], budget["equivalence_runs"])
    return rows


def chart(rows: list[dict], path) -> None:
    """Each design a column of dots, one per pool (jittered), its false rate in %: pixel test on its record (auto)
    and off; red where the criterion fails. Works on rows read back from the CSV too."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    designs = list(dict.fromkeys(f"{r['kind']}: {r['design']}" for r in rows))
    fig, axes = plt.subplots(2, 1, figsize=(14, 8), sharex=True, sharey=True)
    jitter = np.random.default_rng(0)
    for ax, mode in zip(axes, ("auto", "off"), strict=True):
        for r in rows:
            if r["mode"] != mode:
                continue
            x = designs.index(f"{r['kind']}: {r['design']}") + jitter.uniform(-0.25, 0.25)
            meets = str(r["meets"]) == "True"
            used = int(r["pixel_used"]) > 0
            ax.plot(x, 100 * float(r["rate"]), "o" if used else "s", ms=4, alpha=0.7,
                    color="#1f77b4" if meets else "#d62728", mfc="none" if not used else None)  # fmt: skip
        ax.axhline(100 * ALPHA, color="k", lw=0.8)
        ax.axhline(150 * ALPHA, color="#d62728", lw=0.8, ls="--")
        title = "pixel test on the run's record (auto)" if mode == "auto" else "tile sums only (off)"
        ax.set_title(f"{title}: dots where the pixel test ran, squares where it did not; red: above 1.5 alpha")
        ax.set_ylabel("verdict it must not give, %")
        ax.grid(alpha=0.3, lw=0.4)
    axes[1].set_xticks(range(len(designs)), designs, rotation=40, ha="right", fontsize=7)
    fig.suptitle(f"A/A false `biased` (and `equivalent` at a bias of the tolerance), alpha {ALPHA:g}, one dot a pool")
    fig.tight_layout()
    save(fig, path)


def main(argv: list[str] | None = None) -> int:
    args = study_arguments("pixel_calibration", __doc__, "small pools and few trials (checks the pipeline)", argv)
    start = time.perf_counter()
    rows = measure(QUICK if args.quick else FULL, args.cache)
    write_csv(args.out / "pixel_calibration.csv", rows)
    chart(rows, args.out / "pixel_calibration.png")
    say(f"wrote {args.out / 'pixel_calibration.csv'} and {args.out / 'pixel_calibration.png'} "
        f"in {time.perf_counter() - start:.0f} s")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
