"""`biased` on unbiased pairs whose sides differ in passes, rendered: before and after the permutation test.

    python -m benchmarks.studies.unequal         # pools in benchmarks/cache/, writes docs/benchmarks/unequal.{csv,png}
    python -m benchmarks.studies.unequal --quick --out /tmp/unequal    # small pools and few splits: the pipeline

A/A pools of one built-in scene at 64x64, 1 spp a pass (a glass caustic, the glossy room, the diffuse corner), split
at random (1000 splits) into disjoint reference and test passes of the given counts; `compare` at alpha 0.01 with
16-px tiles decides each split (a fixed design), and `check`'s looks decide a suite's replays: a reference blessed
with 256 or 512 passes against a test side rendered until decided (at most 128 passes, the built-in suite's budget;
400 replays). An exact test at level alpha shows above 1.5 alpha in about a quarter of 400-run measurements by
chance alone, hence 1000 splits where they are cheap.
"before" is the tool without the permutation test (Welch's t-tests alone), "after" the tool as it is. Detection:
at 64 v 64 (equal counts: the permutation test is not used, so before = after) and at 16 v 256 (a blessed reference
against a short test run), an indirect clamp on the caustic and Filter Glossy on a textured scene (400 splits).
Paired A/A (400 runs):
the caustic with Tabulated Sobol against blue noise and the same seeds (a noise-only change). Every share comes
with its Clopper-Pearson 95 % interval.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy import stats

import welch_core as wc

from ..common import whatif
from ..common.cache import study_arguments
from ..common.plotting import write_csv
from ..common.pools import PoolSpec, load_or_render, say

ALPHA, TILE, RESOLUTION = 0.01, 16, 64
SCENES = (("corner_glass", "glass caustic"), ("glossy", "glossy room"), ("corner", "diffuse corner"))
SPLITS = ((4, 256), (8, 256), (16, 256), (256, 8), (32, 32), (2, 8), (4, 4))
DETECTION = (
    ("corner_glass", "cycles.sample_clamp_indirect=20", "caustic, indirect clamp 20"),
    ("textured", "cycles.blur_glossy=1.0", "textured, Filter Glossy 1.0"),
)
FULL = {"pool": 1000, "changed": 400, "splits": 1000, "detection_splits": 400, "suite": 400, "suite_budget": 128,
        "blessed": (256, 512), "detection": ((64, 64), (256, 16)), "paired": (4, 8, 32)}  # fmt: skip
QUICK = {"pool": 80, "changed": 40, "splits": 4, "detection_splits": 4, "suite": 2, "suite_budget": 8,
         "blessed": (24,), "detection": ((8, 8), (24, 4)), "paired": (4,)}  # fmt: skip


def interval(k: int, n: int) -> tuple[float, float]:
    """Clopper-Pearson 95 % interval of a share k / n."""
    low = stats.beta.ppf(0.025, k, n - k + 1) if k else 0.0
    high = stats.beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
    return float(low), float(high)


def _row(kind: str, case: str, config: str, method: str, verdicts: list[str], **extra) -> dict:
    k, n = verdicts.count("biased"), len(verdicts)
    low, high = interval(k, n)
    say(f"  {case}, {config}, {method}: biased {k}/{n} ({100 * k / n:.1f} %, [{100 * low:.1f}, {100 * high:.1f}])")
    return {"kind": kind, "case": case, "config": config, "method": method, "runs": n, "biased": k,
            "share": k / n, "low": low, "high": high, **extra}  # fmt: skip


def _split(rng, pools, n_ref: int, n_test: int):
    """Disjoint passes: the reference's from `pools[0]`, the test's from `pools[1]` (one pool for an A/A pair)."""
    ref_pool, test_pool = pools
    picked = rng.choice(min(ref_pool.n, test_pool.n), n_ref + n_test, replace=False)
    return ref_pool.stats(np.sort(picked[:n_ref]), TILE), test_pool.stats(np.sort(picked[n_ref:]), TILE)


def fixed(pools, n_ref: int, n_test: int, runs: int, seed) -> dict[str, list[str]]:
    """`compare`'s verdicts on `runs` random splits, before and after, on the same splits."""
    out = {"before": [], "after": []}
    rng = np.random.default_rng(seed)
    for _ in range(runs):
        ref, test = _split(rng, pools, n_ref, n_test)
        with whatif.without_permutation():
            out["before"].append(wc.compare(ref, test, ALPHA).verdict.label)
        out["after"].append(wc.compare(ref, test, ALPHA).verdict.label)
    return out


def suite_replay(pool, blessed: int, budget: int, runs: int, seed) -> dict[str, list[str]]:
    """A suite case replayed: a reference of `blessed` passes, the test side looked at as `check` looks at it
    (fixed reference) until decided or `budget` passes. Before and after on the same passes, from one sequence of
    looks: a look that needed the permutation test is one where the t-tests alone crossed (`biased` before)."""
    out = {"before": [], "after": []}
    rng = np.random.default_rng(seed)
    plan = wc.SequentialPlan(max_passes=budget, alpha=ALPHA, tolerance=None)
    for _ in range(runs):
        picked = rng.choice(pool.n, blessed + budget, replace=False)
        ref = pool.stats(np.sort(picked[:blessed]), TILE)
        order = picked[blessed:]
        fractions, before, after = [], None, "inconclusive"
        for n in wc.look_schedule(budget):
            fractions.append(wc.information_fraction(n, budget, blessed))
            look = wc.sequential_look(ref, pool.stats(order[:n], TILE), plan, fractions)
            if before is None and look.outcome.resampling is not None:
                before = "biased"
            if look.verdict is not None:
                after = look.verdict.label
                break
        out["before"].append(before or after)
        out["after"].append(after)
    return out


def measure(budget: dict, cache: Path) -> list[dict]:
    rows = []
    pools = {scene: load_or_render(PoolSpec(scene, (), RESOLUTION, passes=budget["pool"]), cache, f"{scene} A/A")
             for scene, _ in SCENES}  # fmt: skip
    for s, (scene, label) in enumerate(SCENES):
        for n_ref, n_test in SPLITS:
            if n_ref + n_test > pools[scene].n:
                continue
            start = time.perf_counter()
            verdicts = fixed((pools[scene], pools[scene]), n_ref, n_test, budget["splits"], [s, n_ref, n_test])
            seconds = (time.perf_counter() - start) / len(verdicts["after"])
            for method, found in verdicts.items():
                rows.append(_row("aa", label, f"{n_ref} v {n_test}", method, found, seconds=round(seconds, 4)))
        for blessed in budget["blessed"]:
            if blessed + budget["suite_budget"] > pools[scene].n:
                continue
            verdicts = suite_replay(pools[scene], blessed, budget["suite_budget"], budget["suite"], [s, blessed])
            for method, found in verdicts.items():
                rows.append(_row("suite", label, f"blessed {blessed}", method, found))
    for d, (scene, change, label) in enumerate(DETECTION):
        reference = load_or_render(PoolSpec(scene, (), RESOLUTION, passes=budget["changed"]), cache, f"{scene}")
        changed = load_or_render(PoolSpec(scene, (change,), RESOLUTION, passes=budget["changed"]), cache, label)
        for n_ref, n_test in budget["detection"]:
            verdicts = fixed((reference, changed), n_ref, n_test, budget["detection_splits"], [10 + d, n_ref, n_test])
            for method, found in verdicts.items():
                rows.append(_row("detection", label, f"{n_ref} v {n_test}", method, found))
    glass = pools["corner_glass"]
    blue = load_or_render(PoolSpec("corner_glass", (), RESOLUTION, passes=budget["pool"], pattern="BLUE_NOISE"),
                          cache, "glass blue noise")  # fmt: skip
    for n in budget["paired"]:
        rng = np.random.default_rng([20, n])
        found = []
        for _ in range(budget["detection_splits"]):
            picked = np.sort(rng.choice(glass.n, n, replace=False))
            found.append(wc.compare(glass.stats(picked, TILE), blue.stats(picked, TILE), ALPHA).verdict.label)
        rows.append(_row("paired", "glass caustic, Sobol v blue noise", f"{n} v {n} paired", "after", found))
    return rows


def chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [("aa", "A/A splits, compare"), ("suite", "A/A suite replays, check's looks"),
              ("detection", "detection (a real bias)"), ("paired", "paired A/A, compare")]  # fmt: skip
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 6), squeeze=False)
    for ax, (kind, title) in zip(axes[0], panels, strict=True):
        mine = [r for r in rows if r["kind"] == kind]
        labels = list(dict.fromkeys(f"{r['case']}\n{r['config']}" for r in mine))
        for offset, method, colour in ((-0.2, "before", "tab:blue"), (0.2, "after", "tab:orange")):
            line = [r for r in mine if r["method"] == method]
            if not line:
                continue
            y = [labels.index(f"{r['case']}\n{r['config']}") + offset for r in line]
            share = np.array([100 * r["share"] for r in line])
            err = np.array(
                [[100 * (r["share"] - r["low"]) for r in line], [100 * (r["high"] - r["share"]) for r in line]]
            )
            ax.errorbar(share, y, xerr=err, fmt="o", label=method, capsize=3, color=colour)
        if kind != "detection":
            ax.axvline(100 * ALPHA, color="k", lw=0.8, ls="--", label="alpha")
            ax.axvline(150 * ALPHA, color="r", lw=0.8, ls=":", label="1.5 alpha")
            ax.set_xscale("symlog", linthresh=1)
            ax.set_xlim(0, 100)
        ax.set_yticks(range(len(labels)), labels, fontsize=7)
        ax.invert_yaxis()
        ax.set(title=title, xlabel="% of runs called biased")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = study_arguments("unequal", __doc__, "small pools and few splits (checks the pipeline)", argv)
    rows = measure(QUICK if args.quick else FULL, args.cache)
    write_csv(args.out / "unequal.csv", rows)
    chart(rows, args.out / "unequal.png")
    say(f"wrote {args.out / 'unequal.csv'} and {args.out / 'unequal.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
