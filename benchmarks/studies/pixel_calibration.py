"""The pixel-variance test as the tool runs it: false `biased` under H0, fixed designs and `check`'s stopping rule.

    python -m benchmarks.studies.pixel_calibration     # -> docs/benchmarks/pixel_calibration.{csv,png}
    python -m benchmarks.studies.pixel_calibration --quick --out /tmp/pc    # small pools, few trials: the pipeline

A/A trials on the pools of `benchmarks.studies.pixel_variance` (64², 1 spp, rendered by the tool's own code; each
pool's record is the run's: its sampling pattern and settings decide `--pixel-variance auto`), unpaired (disjoint
random passes of one pool on the two sides):

* fixed designs: `welch_core.compare` (every scale, Holm and KS, the permutation test where the counts differ) at
  2 v 2, 3 v 3, 4 v 4, 8 v 8, 2 v 8 and 4 v 16 passes, with ``pixel_variance`` auto and off; on the settings whose
  records do not prove independent pixels, also "on" (the user vouches), where the tripwire must refuse them;
* `check`'s stopping rule: `welch_core.sequential_look` at every look of `look_schedule` up to a budget of
  `BUDGET` passes a side (tolerance 1 %, futility on: a run stops at `biased`, `equivalent`, futility or the
  budget, as `benchmarks.common.checks` replays `check`), with ``pixel_variance`` auto.

Each cell: `biased` in `trials` runs with its 95 % Wilson interval, and how often the pixel test ran (the tripwire
or the record refused it otherwise). The issue's criterion: rate <= 1.5 alpha with the interval's lower end below
alpha, alpha = 0.01.
"""

from __future__ import annotations

import time
import zlib

import numpy as np

import welch_core as wc

from ..common import checks
from ..common.cache import study_arguments
from ..common.plotting import save, write_csv
from ..common.pools import say
from ..common.trials import wilson
from .pixel_variance import POOLS, load, pool_spec

ALPHA, TILE = 0.01, 16
FIXED = ((2, 2), (3, 3), (4, 4), (8, 8), (2, 8), (4, 16))
#: `check`'s budget in the replays: looks at 2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 15, 16 passes a side.
BUDGET = 16
#: Pools whose records do not prove independent pixels: also run with "on", the user vouching for them.
UNPROVEN = ("corner_burley", "corner_glass_burley", "corner_scrambling")
FULL = {"trials": 400, "runs": 400, "quick": False}
QUICK = {"trials": 8, "runs": 4, "quick": True}


def fixed_rows(name: str, label: str, pool, trials: int) -> list[dict]:
    modes = ("auto", "off", "on") if name in UNPROVEN else ("auto", "off")
    rows = []
    for n_ref, n_test in FIXED:
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
            rows.append(row("fixed", name, label, f"{n_ref} v {n_test}", mode, biased[mode], used[mode], trials))
    return rows


def sequential_row(name: str, label: str, pool, runs: int) -> dict:
    plan = wc.SequentialPlan(max_passes=BUDGET, alpha=ALPHA, test_kind="welch", pixel_variance="auto")
    rng = np.random.default_rng(zlib.crc32(f"{name} sequential".encode()))
    verdicts = []
    for _ in range(runs):
        perm = rng.permutation(pool.n)
        verdicts.append(checks.one_run(pool, pool, perm[: pool.n // 2], perm[pool.n // 2 :], plan)["verdict"])
    # How often the looks' last comparison used the pixel test: its record and data decide it at every look alike.
    sample = pool.stats(np.arange(BUDGET), TILE, pixels=True), pool.stats(np.arange(BUDGET, 2 * BUDGET), TILE, True)
    used = wc.pixel_use(*sample, "welch", "auto").used
    return row("sequential", name, label, f"check, budget {BUDGET}", "auto", verdicts.count("biased"),
               runs if used else 0, runs)  # fmt: skip


def row(kind, name, label, design, mode, biased, used, trials) -> dict:
    low, high = wilson(biased, trials)
    ok = biased / trials <= 1.5 * ALPHA and low < ALPHA
    return {"kind": kind, "pool": name, "label": label, "design": design, "mode": mode, "biased": biased,
            "trials": trials, "rate": biased / trials, "low": low, "high": high, "pixel_used": used,
            "meets": ok}  # fmt: skip


def measure(budget: dict, cache) -> list[dict]:
    rows = []
    for entry in POOLS:
        name, label = entry[0], entry[1]
        pool = load(pool_spec(entry, budget["quick"]), cache, label)
        start = time.perf_counter()
        rows += fixed_rows(name, label, pool, budget["trials"])
        rows.append(sequential_row(name, label, pool, budget["runs"]))
        worst = max((r for r in rows if r["pool"] == name and r["mode"] != "off"), key=lambda r: r["rate"])
        say(f"  {label}: worst {worst['biased']}/{worst['trials']} ({worst['design']}, {worst['mode']}) "
            f"in {time.perf_counter() - start:.0f} s")  # fmt: skip
    return rows


def chart(rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    designs = [f"{a} v {b}" for a, b in FIXED] + [f"check, budget {BUDGET}"]
    labels = list(dict.fromkeys(r["label"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5), sharey=True)
    for ax, mode in zip(axes, ("auto", "off"), strict=True):
        for i, label in enumerate(labels):
            cells = {r["design"]: r for r in rows if r["label"] == label and r["mode"] == mode}
            x = [j for j, d in enumerate(designs) if d in cells]
            y = [100 * cells[designs[j]]["rate"] for j in x]
            ax.plot(np.asarray(x) + (i - len(labels) / 2) * 0.03, y, "o-", ms=4, lw=0.8, label=label)
        ax.axhline(100 * ALPHA, color="k", lw=0.8)
        ax.axhline(150 * ALPHA, color="r", lw=0.8, ls="--")
        ax.set_xticks(range(len(designs)), designs, rotation=30, ha="right")
        ax.set_title(f"--pixel-variance {mode}" + (" (fixed designs only)" if mode == "off" else ""))
        ax.set_yscale("symlog", linthresh=1)
    axes[0].set_ylabel("false `biased`, % of A/A runs (alpha 1 %, red: 1.5 alpha)")
    axes[1].legend(fontsize=7, loc="upper right")
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
