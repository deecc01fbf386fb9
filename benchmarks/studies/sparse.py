"""Changes that alter a few light paths, rendered: power of the paired test alone, of Welch's test and of the
default (paired, with Welch's test on the two sides where the differences are mostly exact zeros) against passes.

    python -m benchmarks.studies.sparse            # pools in benchmarks/cache/, writes docs/benchmarks/sparse.{csv,png}
    python -m benchmarks.studies.sparse --quick --out /tmp/sparse    # small pools and few trials: the pipeline

Each case is a built-in scene at 64x64, 1 spp a pass, 16-px tiles, and a setting whose change bites in few passes
of a tile (an indirect clamp that clips only the rare bright caustic or subsurface path): a reference pool and a
changed pool rendered with the same seeds. A trial draws n passes: the same seeds from both pools for the paired
tests, disjoint seeds for Welch's. `compare` decides at alpha 0.01 (a fixed design). "paired alone" is the paired
test as it was before the Welch rule: its non-normal tiles left untrusted. Every change here is a real bias, so
the share of `biased` is the power; the false-positive side is in tests/core/test_sparse_pairs.py (synthetic
pairs, fixed design and `check`'s stopping rule), since two renders of one setting with the same seeds are
identical.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import welch_core as wc

from ..common import plan, whatif
from ..common.cache import study_arguments
from ..common.plotting import write_csv
from ..common.pools import load_or_render, say

CASES = plan.SPARSE_CASES
METHODS = ("paired alone", "default (paired + Welch where sparse)", "Welch (disjoint seeds)")
ALPHA, TILE = 0.01, 16
FULL = {"pool": plan.SPARSE_POOL, "passes": (8, 16, 32, 64, 128, 256), "trials": 40}
QUICK = {"pool": plan.SPARSE_QUICK_POOL, "passes": (8, 16), "trials": 3}


def trial(reference, changed, n: int, method: str, rng) -> str:
    if method.startswith("Welch"):
        picked = rng.choice(reference.n, 2 * n, replace=False)
        ref, test = reference.stats(picked[:n], TILE), changed.stats(picked[n:], TILE)
        return wc.compare(ref, test, ALPHA).verdict.label
    picked = rng.choice(reference.n, n, replace=False)
    ref, test = reference.stats(picked, TILE), changed.stats(picked, TILE)
    if method == "paired alone":
        with whatif.paired_alone():
            return wc.compare(ref, test, ALPHA).verdict.label
    return wc.compare(ref, test, ALPHA).verdict.label


def measure(budget: dict, cache: Path) -> list[dict]:
    rows = []
    for scene, change, label in CASES:
        specs = plan.sparse_pools(scene, change, budget["pool"])
        reference, changed = (load_or_render(s, cache, f"{scene} {'changed' if s.overrides else 'reference'}")
                              for s in specs)  # fmt: skip
        diffs = changed.sums(TILE) - reference.sums(TILE)
        zeros = float(np.median((diffs == 0).mean(axis=0)))
        bias = float(diffs.sum() / reference.sums(TILE).sum())
        for n in budget["passes"]:
            if 2 * n > reference.n:
                continue
            for method in METHODS:
                rng = np.random.default_rng([n, METHODS.index(method), CASES.index((scene, change, label))])
                verdicts = [trial(reference, changed, n, method, rng) for _ in range(budget["trials"])]
                row = {"case": label, "scene": scene, "change": change, "zero_share": round(zeros, 3),
                       "bias": round(bias, 5), "passes": n, "method": method, "trials": len(verdicts)}  # fmt: skip
                rows.append(row | {"biased": verdicts.count("biased"), "inconclusive": verdicts.count("inconclusive")})
                say(f"  {label}, {n} passes, {method}: biased {rows[-1]['biased']}/{len(verdicts)}, "
                    f"inconclusive {rows[-1]['inconclusive']}")  # fmt: skip
    return rows


def chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(r["case"] for r in rows))
    fig, axes = plt.subplots(2, len(cases), figsize=(5 * len(cases), 7), squeeze=False, sharex=True)
    for column, case in enumerate(cases):
        mine = [r for r in rows if r["case"] == case]
        for method in METHODS:
            line = [r for r in mine if r["method"] == method]
            for row, key in enumerate(("biased", "inconclusive")):
                axes[row][column].plot([r["passes"] for r in line], [r[key] / r["trials"] for r in line], marker="o",
                                       label=method)  # fmt: skip
        share, bias = mine[0]["zero_share"], 100 * mine[0]["bias"]
        axes[0][column].set_title(f"{case}\n(exact zeros in {share:.0%} of a tile's passes, bias {bias:+.2f} %)")
        for row, label in enumerate(("share biased (power)", "share inconclusive (untestable)")):
            axes[row][column].set(ylabel=label, ylim=(-0.03, 1.03))
            axes[row][column].set_xscale("log", base=2)
            axes[row][column].grid(alpha=0.3)
        axes[1][column].set_xlabel("passes a side")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = study_arguments("sparse", __doc__, "small pools and few trials (checks the pipeline)", argv)
    rows = measure(QUICK if args.quick else FULL, args.cache)
    write_csv(args.out / "sparse.csv", rows)
    chart(rows, args.out / "sparse.png")
    say(f"wrote {args.out / 'sparse.csv'} and {args.out / 'sparse.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
