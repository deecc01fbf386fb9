"""Passes a side to `biased`: `check` against the best fixed design chosen in hindsight and a matched-filter oracle.

    python -m benchmarks.studies.power              # pools in benchmarks/cache/, writes docs/benchmarks/power.{csv,png}
    python -m benchmarks.studies.power --quick --out /tmp/power    # the quick pools of the sparse study: the pipeline

Cases: chart 5's (chart 1's bias cases and the local metal sphere, 128² px, 400-pass pools) and the rendered
sparse cases of `benchmarks.studies.sparse` that `check` finds within its budget (a glass caustic and a fog volume under
an indirect clamp, 64² px, 640-pass pools); each paired (the same seeds on both sides) and unpaired (disjoint
seeds). Per case and test, in the same run:

* `check` simulated as in chart 5 (`benchmarks.common.checks`: the passes of a run in a random order of the pool's
  seeds, a look at each step of `look_schedule`, the pool as the budget), at its defaults, and the same with the
  early design switched off (``SequentialPlan(early_share=0)``, the design before it); median and 80th
  percentile of the passes a side to `biased` (a run that never gets there counts as never);
* the best fixed design in hindsight: of `compare` at one tile size each (16², 32², 64², the whole image), the
  fewest passes a side at which 80 % of trials say `biased`;
* the oracle: it is told the true bias pattern, the difference of the two pools' mean tile sums (16² tiles) and
  their variances, and tests the matched-filter statistic ``sum_j w_j x_j`` with ``w_j = delta_j / var_j`` of each
  pass, one-sided at alpha 0.01 (the paired t-test on its per-pass differences, or Welch's t); the fewest passes
  a side at which 80 % of trials reject.

Also the unbiased pairs of chart 6 (A/A): how often `check` ends `equivalent`, its median passes, and `biased`
(a false positive), with and without the early design. Pass counts are searched on every integer up to 16, then in
steps of 10 %.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import stats

import welch_core as wc

from ..common import checks, plan
from ..common.cache import study_arguments
from ..common.plotting import write_csv
from ..common.pools import load_or_render, say
from ..common.trials import ALPHA, compare_verdicts, draw_paired, draw_unpaired

#: The goals of issue 20: median passes to `biased` within these multiples of the best fixed design and the oracle.
GOAL_FIXED, GOAL_ORACLE = 1.25, 1.5
#: The designs simulated: (key in the CSV, early share, pixel-variance test): the defaults with the tile sums alone
#: (`SequentialPlan`'s default share), the design before the early one, and the defaults with the pixel-variance
#: test on each pool's own record (`--pixel-variance auto`, the tool's default).
DESIGNS = (("check", wc.SequentialPlan.early_share, "off"), ("previous", 0.0, "off"),
           ("pixels", wc.SequentialPlan.early_share, "auto"))  # fmt: skip
FULL = {"runs": 200, "trials": 200, "aa_runs": 200, "plan": plan.FULL, "sparse_pool": plan.SPARSE_POOL}
QUICK = {"runs": 4, "trials": 6, "aa_runs": 3, "plan": None, "sparse_pool": plan.SPARSE_QUICK_POOL}
#: The sparse cases `check` finds within a 640-pass pool (the subsurface clamp is not found by any method there).
SPARSE_CASES = plan.SPARSE_CASES[:2]


def pass_grid(most: int) -> list[int]:
    """2, 3, ..., 16, then 10 % more each step, up to `most`."""
    grid, n = [], 2
    while n <= most:
        grid.append(n)
        n = n + 1 if n < 16 else int(n * 1.1) + 1
    return grid


def cases(budget: dict, cache: Path) -> list[dict]:
    """Every case: name, label, the two pools."""
    out = []
    if budget["plan"] is not None:
        for case in [*plan.cases(budget["plan"]), plan.local_case(budget["plan"])]:
            out.append({"name": case.name, "label": case.label, "ref": load_or_render(case.ref, cache),
                        "test": load_or_render(case.test, cache)})  # fmt: skip
    for scene, change, label in SPARSE_CASES:
        ref, test = (load_or_render(s, cache) for s in plan.sparse_pools(scene, change, budget["sparse_pool"]))
        out.append({"name": scene, "label": label, "ref": ref, "test": test})
    return out


def first_passing(grid: list[int], rate) -> int | None:
    """The first n of `grid` whose `rate(n)` is at least 80 % (None: none)."""
    for n in grid:
        if rate(n) >= 0.8:
            return n
    return None


def fixed_passes(ref, test, paired: bool, trials: int, seed: int) -> tuple[int | None, str | None]:
    """The best fixed design in hindsight: (passes a side to 80 % `biased`, its method) over the tile sizes."""
    size = ref.spec.resolution
    methods = [f"{'paired' if paired else 'welch'}{t}" for t in (16, 32, 64, 128) if t <= size]
    most = checks.budget(ref, paired)
    best = (None, None)
    for method in methods:
        rng = np.random.default_rng([seed, methods.index(method)])
        draw = draw_paired if paired else draw_unpaired

        def rate(n, method=method, rng=rng, draw=draw):
            verdicts = [compare_verdicts(ref, test, draw(rng, ref.n, n), (method,)) for _ in range(trials)]
            return sum(v.get(method) == wc.Verdict.BIASED for v in verdicts) / trials

        limit = [n for n in pass_grid(most) if best[0] is None or n < best[0]]
        found = first_passing(limit, rate)
        if found is not None:
            best = (found, method)
    return best


def oracle_passes(ref, test, paired: bool, trials: int, seed: int, tile: int = 16) -> int | None:
    """Passes a side to 80 % rejection of the matched-filter test that is told the bias pattern."""
    r = ref.sums(tile).reshape(ref.n, -1).astype(float)
    t = test.sums(tile).reshape(test.n, -1).astype(float)
    delta = t.mean(axis=0) - r.mean(axis=0)
    var = (t - r).var(axis=0, ddof=1) if paired else t.var(axis=0, ddof=1) + r.var(axis=0, ddof=1)
    weights = np.divide(delta, var, out=np.zeros_like(delta), where=var > 0)
    on_ref, on_test = r @ weights, t @ weights
    rng = np.random.default_rng(seed)

    def rate(n):
        hits = 0
        for _ in range(trials):
            draw = (draw_paired if paired else draw_unpaired)(rng, ref.n, n)
            if paired:
                d = on_test[draw.test] - on_ref[draw.ref]
                sd = d.std(ddof=1)
                p = stats.t.sf(d.mean() / (sd / np.sqrt(n)), n - 1) if sd > 0 else float(d.mean() <= 0)
            else:
                p = stats.ttest_ind(on_test[draw.test], on_ref[draw.ref], equal_var=False, alternative="greater").pvalue
            hits += p <= ALPHA
        return hits / trials

    return first_passing(pass_grid(checks.budget(ref, paired)), rate)


def check_runs(ref, test, paired: bool, runs: int, early_share: float, seed: int, pixels: str = "off") -> list[dict]:
    """`runs` simulated checks at the defaults, with the early design's share `early_share` and the pixel-variance
    test `pixels`."""
    max_passes = checks.budget(ref, paired)
    design = wc.SequentialPlan(max_passes=max_passes, alpha=ALPHA, tolerance=checks.TOLERANCE, early_share=early_share,
                               pixel_variance=pixels)  # fmt: skip
    return checks.run_many(ref, test, paired, runs, design, np.random.default_rng(seed))


def _ratio(a, b) -> float | None:
    return None if a is None or b is None else a / b


def case_rows(case: dict, budget: dict) -> list[dict]:
    rows = []
    for paired in (True, False):
        ref, test = case["ref"], case["test"]
        mode = "paired" if paired else "unpaired"
        seed = sum(map(ord, case["name"])) + paired
        fixed, method = fixed_passes(ref, test, paired, budget["trials"], seed)
        oracle = oracle_passes(ref, test, paired, budget["trials"], seed)
        row = {"case": case["name"], "label": case["label"], "test": mode, "budget": checks.budget(ref, paired),
               "oracle_passes": oracle, "fixed_passes": fixed, "fixed_method": method}  # fmt: skip
        for key, share, pixels in DESIGNS:
            runs = check_runs(ref, test, paired, budget["runs"], share, seed, pixels)
            to_biased = [r["passes"] if r["verdict"] == "biased" else np.inf for r in runs]
            median, p80 = checks.percentile(to_biased, 0.5), checks.percentile(to_biased, 0.8)
            row |= {f"{key}_runs": len(runs), f"{key}_biased": sum(r["verdict"] == "biased" for r in runs),
                    f"{key}_median": median, f"{key}_p80": p80}  # fmt: skip
            for q, value in (("median", median), ("p80", p80)):
                row |= {f"{key}_{q}_vs_fixed": _ratio(value, fixed), f"{key}_{q}_vs_oracle": _ratio(value, oracle)}
        rows.append(row)
        say(f"  {case['name']} {mode}: oracle {oracle}, best fixed {fixed} ({method}); check median/p80 "
            f"{row['check_median']}/{row['check_p80']}, without the early design "
            f"{row['previous_median']}/{row['previous_p80']}, with the pixel test "
            f"{row['pixels_median']}/{row['pixels_p80']}")  # fmt: skip
    return rows


def aa_rows(budget: dict, cache: Path) -> list[dict]:
    """The unbiased pairs of chart 6, with and without the early design."""
    if budget["plan"] is None:
        return []
    rows = []
    for pair in plan.aa_pairs(budget["plan"]):
        ref, test = load_or_render(pair["ref"], cache), load_or_render(pair["test"], cache)
        row = {"case": pair["name"], "label": pair["label"], "test": "paired" if pair["paired"] else "unpaired",
               "budget": checks.budget(ref, pair["paired"])}  # fmt: skip
        for key, share, pixels in DESIGNS:
            runs = check_runs(ref, test, pair["paired"], budget["aa_runs"], share, 7, pixels)
            eq = [r["passes"] for r in runs if r["verdict"] == "equivalent"]
            row |= {f"{key}_runs": len(runs), f"{key}_equivalent": len(eq),
                    f"{key}_equivalent_median": checks.percentile(eq, 0.5),
                    f"{key}_biased": sum(r["verdict"] == "biased" for r in runs)}  # fmt: skip
        rows.append(row)
        say(f"  A/A {pair['name']}: equivalent {row['check_equivalent']}/{row['check_runs']} (median "
            f"{row['check_equivalent_median']} passes), biased {row['check_biased']}; without the early design "
            f"{row['previous_equivalent']} (median {row['previous_equivalent_median']}), "
            f"biased {row['previous_biased']}; with the pixel test {row['pixels_equivalent']} (median "
            f"{row['pixels_equivalent_median']}), biased {row['pixels_biased']}")  # fmt: skip
    return rows


def chart(rows: list[dict], path: Path) -> None:
    from ..common.plotting import plt, save

    fig, axes = plt.subplots(2, 1, figsize=(14, 8), sharex=True)
    names = [f"{r['case']}\n{r['test']}" for r in rows]
    x = np.arange(len(rows))
    series = (("oracle_passes", "oracle (told the bias pattern)", "#2ca02c", "D"),
              ("fixed_passes", "best fixed design in hindsight (80 %)", "#7f7f7f", "s"),
              ("previous_median", "check without the early design (median)", "#1f77b4", "x"),
              ("check_median", "check, tile sums (median)", "#d62728", "o"),
              ("pixels_median", "check with the pixel-variance test (median)", "#9467bd", "^"))  # fmt: skip
    for key, label, color, marker in series:
        y = [np.nan if r[key] is None else r[key] for r in rows]
        axes[0].plot(x, y, marker, color=color, label=label, ms=7, mfc="none" if marker == "D" else color)
    axes[0].set_yscale("log")
    axes[0].set_ylabel("passes a side to `biased` (log)")
    axes[0].legend(fontsize=8)
    axes[0].grid(alpha=0.3, which="both", axis="y", lw=0.4)
    for key, label, color, marker in (("check_median_vs_fixed", "check / best fixed", "#d62728", "o"),
                                      ("pixels_median_vs_fixed", "with the pixel test / best fixed", "#9467bd", "^"),
                                      ("check_median_vs_oracle", "check / oracle", "#2ca02c", "D"),
                                      ("previous_median_vs_fixed", "without the early design / best fixed",
                                       "#1f77b4", "x")):  # fmt: skip
        y = [np.nan if r[key] is None else r[key] for r in rows]
        axes[1].plot(x, y, marker, color=color, label=label, ms=7)
    axes[1].axhline(GOAL_FIXED, color="k", ls="--", lw=0.8, label=f"goal vs fixed {GOAL_FIXED}×")
    axes[1].axhline(GOAL_ORACLE, color="#2ca02c", ls=":", lw=0.8, label=f"goal vs oracle {GOAL_ORACLE}×")
    axes[1].set_ylabel("median passes / baseline")
    axes[1].set_xticks(x, names, fontsize=7)
    axes[1].legend(fontsize=8, ncol=3)
    axes[1].grid(alpha=0.3, lw=0.4)
    fig.suptitle(
        "Passes a side to `biased` (α 0.01): check against the best fixed design and the matched-filter oracle"
    )
    fig.tight_layout()
    save(fig, path)


def main(argv: list[str] | None = None) -> int:
    args = study_arguments("power", __doc__, "the quick pools of benchmarks.studies.sparse, few runs", argv)
    budget = QUICK if args.quick else FULL
    rows = []
    for case in cases(budget, args.cache):
        say(f"power: {case['label']}")
        rows += case_rows(case, budget)
    write_csv(args.out / "power.csv", rows)
    chart(rows, args.out / "power.png")
    aa_found = aa_rows(budget, args.cache)
    if aa_found:
        write_csv(args.out / "power_aa.csv", aa_found)
    say(f"wrote {args.out / 'power.csv'} and {args.out / 'power.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
