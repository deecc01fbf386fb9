"""Chart 5: render seconds to a decision, `check` (render until decided) against the best fixed design.

On each bias case of chart 1 (same pools) and the local bias of chart 7, `decision_runs` simulated runs of `check`
at its defaults (`checks`: alpha 1 %, tolerance 1 %, finest tile 16 px, every scale, the pool as the budget),
paired (same seeds, what `check` does on one build) and unpaired (``--unpaired``, or two builds). Against them the
fixed designs of chart 1 in hindsight: per case the smallest render time to 80 % detection over the tile sizes
(16², 32², 64², 128²) and pass counts, Welch and paired separately. Seconds count as on chart 1: the median
seconds of a pass of each side times the passes a side.

Also measured, to see where the time goes: `check` with the equivalence verdict switched off
(``SequentialPlan(tolerance=None)``: it can only stop at `biased`), and, unpaired, the same with Welch-Satterthwaite
degrees of freedom instead of the sequential design's conservative n - 1 (a what-if: the design is only calibrated
with n - 1).
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

import welch_core as wc

from ..common import checks, fixed_designs, plan, whatif
from ..common.plotting import plt, save, write_csv
from ..common.pools import load_or_render, say
from ..common.trials import ALPHA, FIXED_PAIRED, FIXED_WELCH, LABELS
from ..common.words import MODE_NAMES
from ..common.words import n as _n
from ..common.words import pct as _pct
from ..common.words import s as _s
from ..common.words import tg as _tg
from ..common.words import x as _x

#: The goal of issue 11: `check` reaches `biased` in at most this many times the best fixed design's seconds.
GOAL = 1.25

#: (name, paired, tolerance, degrees of freedom) of each simulated design.
MODES = (
    ("paired", True, checks.TOLERANCE, "n-1"),
    ("unpaired", False, checks.TOLERANCE, "n-1"),
    ("paired_noeq", True, None, "n-1"),
    ("unpaired_noeq", False, None, "n-1"),
    ("unpaired_noeq_ws", False, None, "welch"),
)
MODE_LABELS = {
    "paired": "check, paired (defaults)",
    "unpaired": "check --unpaired (defaults)",
    "paired_noeq": "check, paired, equivalence off",
    "unpaired_noeq": "check --unpaired, equivalence off",
    "unpaired_noeq_ws": "check --unpaired, equivalence off, Welch-Satterthwaite df (what-if)",
}


def case_rows(b: plan.Budget, cache_dir: Path, case: plan.Case, summary: list[dict]) -> list[dict]:
    """One row per design simulated on `case`, with the best fixed design of the same test beside it."""
    ref, test = load_or_render(case.ref, cache_dir), load_or_render(case.test, cache_dir)
    per_pass = ref.seconds_per_pass + test.seconds_per_pass
    rows = []
    for name, paired, tolerance, df in MODES:
        if df == "welch" and not whatif.welch_df_available():
            continue  # welch_core changed: the what-if no longer applies
        say(f"chart 5: {case.name}, {MODE_LABELS[name]}")
        with whatif.welch_df() if df == "welch" else contextlib.nullcontext():
            runs = checks.simulate(ref, test, paired, b.decision_runs, cache_dir, tolerance=tolerance, df=df)
        found = checks.tally(runs, per_pass)
        best = fixed_designs.best_fixed(summary, case.name, FIXED_PAIRED if paired else FIXED_WELCH)
        best_s = best["seconds_to_80"] if best else None
        row = {"case": case.name, "label": case.label, "mode": name, "paired": paired, "tolerance": tolerance,
               "df": df, "max_passes": checks.budget(ref, paired), "seconds_per_pass_both": per_pass, **found,
               "best_fixed_method": best["method"] if best else None, "best_fixed_s": best_s,
               "best_fixed_passes": best["passes_to_80"] if best else None}  # fmt: skip
        for what in ("decision", "biased"):
            for q in ("median", "p80", "p90"):
                s = found[f"{what}_{q}_s"]
                row[f"{what}_{q}_ratio"] = s / best_s if s is not None and best_s else None
        rows.append(row)
        say(
            f"  {case.name} {name}: biased {found['biased']}, equivalent {found['equivalent']}, inconclusive "
            f"{found['inconclusive']} of {found['runs']}; decision median {_fmt(found['decision_median_s'])} "
            f"p90 {_fmt(found['decision_p90_s'])}; best fixed {_fmt(best_s)}"
            + (f" ({best['method']})" if best else "")
            + f"; ratios median {_r(row['decision_median_ratio'])}, p90 {_r(row['decision_p90_ratio'])}"
        )
    return rows


def _fmt(s) -> str:
    return "—" if s is None else f"{s:.3g} s"


def _r(x) -> str:
    return "—" if x is None else f"{x:.2f}×"


def boundary_rows(b: plan.Budget, looks: int = 8) -> list[dict]:
    """Why the first looks rarely decide: at each of the first `looks` looks of a budget (the pool, paired; half
    of it, unpaired), the critical |t| a hypothesis must reach, for the finest (16²) and the coarsest scale (the
    whole image), in the sequential design (its nominal level: Pocock spending of the hypothesis's Bonferroni
    share over 4 scales; t with n - 1 degrees of freedom) against one fixed test of that tile size alone at the
    same n (Holm's first step alpha / tile-channels, halved for the Bonferroni with the KS test; Welch's nu = 2n - 2
    for equal variances, the paired test's n - 1)."""
    from scipy import stats

    out = []
    size = b.resolution
    sizes = [t for t in (16, 2 * 16, 4 * 16, 8 * 16) if t <= size]
    channels = {t: 3 * (size // t) ** 2 for t in sizes}
    finest, coarsest = sizes[0], sizes[-1]
    for paired, max_passes in ((False, b.passes // 2), (True, b.passes)):
        schedule = wc.look_schedule(max_passes)
        fractions = [min(n / max_passes, 1.0) for n in schedule]
        shares = [ALPHA / (len(sizes) * channels[t]) for t in (finest, coarsest)]
        levels = wc.nominal_levels(wc.boundaries(fractions, shares, "pocock"))
        for k, n in enumerate(schedule[:looks]):
            row = {"test": "paired" if paired else "unpaired", "max_passes": max_passes, "look": k + 1, "passes": n,
                   "fraction": fractions[k], "finest": finest, "coarsest": coarsest}  # fmt: skip
            for j, (t, name) in enumerate(((finest, "finest"), (coarsest, "coarsest"))):
                fixed = ALPHA / (2 * channels[t])
                nu = n - 1 if paired else 2 * n - 2
                row[f"level_seq_{name}"] = float(levels[k, j])
                row[f"level_fixed_{name}"] = fixed
                row[f"t_seq_{name}"] = float(stats.t.isf(levels[k, j] / 2, n - 1)) if levels[k, j] > 0 else None
                row[f"t_fixed_{name}"] = float(stats.t.isf(fixed / 2, nu))
            out.append(row)
    return out


def run(b: plan.Budget, cache_dir: Path, out_dir: Path) -> dict:
    found = fixed_designs.compute(b, cache_dir)
    summary = list(found["summary"])
    local = fixed_designs.local_results(b, cache_dir)
    summary += local["summary"]
    cases = [*found["cases"], local["case"]]
    rows = []
    for case in cases:
        rows += case_rows(b, cache_dir, case, summary)
    bounds = boundary_rows(b)
    files = [
        write_csv(out_dir / "chart5_decision.csv", rows),
        write_csv(out_dir / "chart5_boundaries.csv", bounds),
        _plot(out_dir / "chart5_decision.png", cases, rows),
    ]
    goal = goal_rows(rows)
    return {"files": files, "rows": rows, "goal": goal, "runs": b.decision_runs, "boundaries": bounds,
            "changes": {c.name: next((r["mean_change"] for r in summary if r["case"] == c.name), None)
                        for c in cases}}  # fmt: skip


def goal_rows(rows: list[dict]) -> list[dict]:
    """Per case and test: does `check` at its defaults reach `biased` within GOAL times the best fixed design?"""
    out = []
    for r in rows:
        if r["mode"] not in ("paired", "unpaired"):
            continue
        noeq = next(x for x in rows if x["case"] == r["case"] and x["mode"] == f"{r['mode']}_noeq")
        ratio = r["biased_median_ratio"]
        out.append({"case": r["case"], "label": r["label"], "mode": r["mode"], "best_fixed_s": r["best_fixed_s"],
                    "best_fixed_method": r["best_fixed_method"], "median_s": r["biased_median_s"],
                    "p80_s": r["biased_p80_s"], "p90_s": r["biased_p90_s"], "median_ratio": ratio,
                    "p80_ratio": r["biased_p80_ratio"], "p90_ratio": r["biased_p90_ratio"],
                    "biased_share": r["biased"] / r["runs"], "equivalent_share": r["equivalent"] / r["runs"],
                    "noeq_median_ratio": noeq["biased_median_ratio"], "noeq_p90_ratio": noeq["biased_p90_ratio"],
                    "met_median": ratio is not None and ratio <= GOAL})  # fmt: skip
    return out


def _plot(path: Path, cases, rows) -> str:
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(15, 10), height_ratios=[1.3, 1])
    x = np.arange(len(cases))
    styles = {"unpaired": ("#1f77b4", -0.2), "paired": ("#d62728", 0.2)}
    for mode, (color, dx) in styles.items():
        for i, case in enumerate(cases):
            r = next(r for r in rows if r["case"] == case.name and r["mode"] == mode)
            noeq = next(r for r in rows if r["case"] == case.name and r["mode"] == f"{mode}_noeq")
            if r["best_fixed_s"]:
                top.plot(i + dx - 0.07, r["best_fixed_s"], "D", color=color, ms=7, mfc="white", mew=1.5,
                         label=f"best fixed design ({mode}), 80 % detection" if i == 0 else None)  # fmt: skip
            med, p90 = r["decision_median_s"], r["decision_p90_s"]
            top.errorbar(i + dx, med, yerr=[[0], [p90 - med]], fmt="o", color=color, capsize=4, ms=6,
                         label=f"{MODE_LABELS[mode]}: median, bar to p90" if i == 0 else None)  # fmt: skip
            shares = f"{100 * r['biased'] / r['runs']:.0f}/{100 * r['equivalent'] / r['runs']:.0f}"
            top.annotate(shares, (i + dx, p90), textcoords="offset points", xytext=(0, 6), ha="center", fontsize=7,
                         color=color)  # fmt: skip
            if noeq["biased_median_s"] is not None:
                hi = noeq["biased_p90_s"] or noeq["biased_median_s"]
                top.errorbar(i + dx + 0.07, noeq["biased_median_s"], yerr=[[0], [hi - noeq["biased_median_s"]]],
                             fmt="x", color=color, capsize=3, ms=6, alpha=0.7,
                             label=f"{MODE_LABELS[mode]}, equivalence off" if i == 0 else None)  # fmt: skip
            for q, marker in (("median", "o"), ("p90", "^")):
                ratio = r[f"decision_{q}_ratio"]
                if ratio is not None:
                    bottom.plot(i + dx + (0.05 if q == "p90" else -0.05), ratio, marker, color=color, ms=7,
                                label=f"{mode}: {q} / best fixed" if i == 0 else None)  # fmt: skip
                ratio = noeq[f"biased_{q}_ratio"]
                if ratio is not None:
                    bottom.plot(i + dx + (0.12 if q == "p90" else 0.02), ratio, marker, color=color, ms=6, mfc="none",
                                label=f"{mode}, equivalence off: {q} / best fixed" if i == 0 else None)  # fmt: skip
    top.set_yscale("log")
    top.set_xticks(x, [c.label for c in cases], fontsize=8, rotation=12)
    top.set_ylabel("render seconds, both sides (log)")
    top.set_title("Seconds to a decision: `check` (simulated runs on the pools) against the best fixed design in "
                  "hindsight; numbers: % of runs `biased` / `equivalent`", fontsize=10)  # fmt: skip
    top.grid(alpha=0.3, which="both", axis="y", lw=0.4)
    top.legend(fontsize=7.5, loc="upper left")
    bottom.axhline(GOAL, color="k", ls="--", lw=0.8, label=f"goal: {GOAL}×")
    bottom.axhline(1.0, color="k", ls=":", lw=0.6)
    bottom.set_yscale("log")
    bottom.set_xticks(x, [c.name for c in cases], fontsize=8)
    bottom.set_ylabel("check seconds / best fixed seconds (log)")
    bottom.set_title("Ratio to the best fixed design (defaults: tolerance 1 %; a run ending `equivalent` counts at "
                     "its stop)", fontsize=10)  # fmt: skip
    bottom.grid(alpha=0.3, which="both", axis="y", lw=0.4)
    bottom.legend(fontsize=7.5, ncol=3, loc="upper right")
    fig.suptitle(f"Chart 5: render seconds to a decision (α = 0.01; {rows[0]['runs']} runs per design and case)")
    fig.tight_layout()
    return save(fig, path)


# -- its section of docs/benchmarks/README.md --------------------------------------------------------------------------


def section(f: dict) -> list[str]:
    """Chart 5's section of docs/benchmarks/README.md from the figures `f`."""
    c5, b = f["chart5"], f["budget"]
    parts = [CHART5.format(runs=c5["runs"], passes=b["passes"], half=b["passes"] // 2)]
    parts += chart5_lines(c5) + ["", "Per case and test, the goal (median time to `biased` at most 1.25× the best "
                                 "fixed design's):", ""] + chart5_findings(c5)  # fmt: skip
    return parts + ["", BOUNDARIES, ""] + chart5_boundary_lines(c5)


CHART5 = """
## Chart 5: render seconds to a decision (`check` against the best fixed design)

![chart 5](chart5_decision.png)

`python -m batch check` renders both sides in chunks and stops once the data decide (`welch_core.looks`: a
group-sequential design with Pocock-type alpha spending over the looks and Bonferroni over tile-channels and
scales). Here it is simulated on chart 1's pools: {runs} runs per case and test, each drawing the passes in a random
order of the pool's seeds and calling `welch_core.sequential_look` at the looks of `look_schedule(budget)` (2, 3,
4, ... passes a side, then 15 % more each time) until a verdict, exactly as `check` does after each chunk, at its
defaults: α = 0.01, tolerance 1 %, finest tile 16 px and every scale above it, the pool as the budget ({passes}
passes a side paired, the same seeds on both sides, as `check` does on one build; {half} unpaired, as with
`--unpaired` or two builds). Render seconds count as on chart 1 (median seconds of a pass of each side times the
passes a side). The fixed design to beat is chosen in hindsight from chart 1: per case the fewest seconds to 80 %
detection over the tile sizes 16², 32², 64², 128² and the pass counts, Welch and paired separately. A fixed
design's 80 % point is the time by which 80 % of its trials say `biased`; the like-for-like figure of `check` is
its 80th percentile (p80); the median and p90 are shown as asked. Also simulated: `check` with the equivalence
verdict off (`SequentialPlan(tolerance=None)`, so a run can only stop at `biased`; the command line has no switch
for it) and, unpaired, the same with Welch-Satterthwaite's ν instead of the conservative n − 1 of the sequential
design (a what-if: only n − 1 is calibrated). Passes a side in brackets; the local bias is chart 7's.
"""


BOUNDARIES = """Why the first looks rarely decide: the critical values a single hypothesis must pass at the first looks
of `check` (Pocock spending of its Bonferroni share over 4 scales; t with n − 1 degrees of freedom) against a fixed
test of one tile size at the same n (Holm's first step α / tile-channels, halved for the KS test; ν = 2n − 2 for
Welch with equal variances, n − 1 paired):"""


def chart5_lines(c5: dict) -> list[str]:
    rows = c5["rows"]
    lines = [
        "| case | test | best fixed design (hindsight): seconds, passes a side | `check`: median | p80 | p90 "
        "| median / best | p80 / best | p90 / best | runs `biased` / `equivalent` / `inconclusive` "
        "| equivalence off: median / best, p90 / best |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r["mode"] not in MODE_NAMES:
            continue
        noeq = next(x for x in rows if x["case"] == r["case"] and x["mode"] == f"{r['mode']}_noeq")
        best = "not reached"
        if r["best_fixed_s"] is not None:
            best = f"{_s(r['best_fixed_s'])}, {r['best_fixed_passes']:.0f} ({LABELS[r['best_fixed_method']]})"
        lines.append(
            f"| {r['label']} | {r['mode']} | {best} | {_s(r['decision_median_s'])} "
            f"({_n(r['decision_median_passes'])}) | {_s(r['decision_p80_s'])} | {_s(r['decision_p90_s'])} "
            f"({_n(r['decision_p90_passes'])}) | {_x(r['decision_median_ratio'])} | {_x(r['decision_p80_ratio'])} | "
            f"{_x(r['decision_p90_ratio'])} | {r['biased']} / {r['equivalent']} / {r['inconclusive']} | "
            f"{_x(noeq['biased_median_ratio'])}, {_x(noeq['biased_p90_ratio'])} |"
        )
    return lines


def chart5_boundary_lines(c5: dict) -> list[str]:
    first = c5["boundaries"][0]
    fine, coarse = f"{first['finest']}²", f"{first['coarsest']}²"
    lines = [
        f"| test (budget) | look | passes a side | information | nominal level at {fine}: check / fixed "
        f"| critical t at {fine}: check / fixed | level at {coarse}: check / fixed | critical t at {coarse}: check / "
        "fixed |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in c5["boundaries"]:
        lines.append(
            f"| {r['test']} ({r['max_passes']}) | {r['look']} | {r['passes']} | {_pct(r['fraction'])} | "
            f"{r['level_seq_finest']:.2g} / {r['level_fixed_finest']:.2g} | {_tg(r['t_seq_finest'])} / "
            f"{_tg(r['t_fixed_finest'])} | {r['level_seq_coarsest']:.2g} / {r['level_fixed_coarsest']:.2g} | "
            f"{_tg(r['t_seq_coarsest'])} / {_tg(r['t_fixed_coarsest'])} |"
        )
    return lines


def chart5_findings(c5: dict) -> list[str]:
    rows = c5["rows"]
    changes = c5.get("changes", {})
    out = []
    for g in c5["goal"]:
        r = next(x for x in rows if x["case"] == g["case"] and x["mode"] == g["mode"])
        noeq = next(x for x in rows if x["case"] == g["case"] and x["mode"] == f"{g['mode']}_noeq")
        ws = next((x for x in rows if x["case"] == g["case"] and x["mode"] == f"{g['mode']}_noeq_ws"), None)
        head = f"- **{g['label']}, {g['mode']}**: "
        if g["best_fixed_s"] is None:
            out.append(head + "no fixed design reaches 80 % within the pool; `check` ends `biased` in "
                       f"{_pct(g['biased_share'], 0)} of the runs (median {_s(r['biased_median_s'])}).")  # fmt: skip
            continue
        met = g["median_ratio"] is not None and g["median_ratio"] <= 1.25
        met90 = g["p90_ratio"] is not None and g["p90_ratio"] <= 1.25
        verdict = "**met**" if met else "**not met**"
        if g["median_s"] is None and g["equivalent_share"] >= 0.5:
            verdict = "**not met at the defaults: most runs end `equivalent`**"
        text = (
            head
            + verdict
            + (
                f" (median time to `biased` {_x(g['median_ratio'])}, p80 {_x(g['p80_ratio'])}, "
                f"p90 {_x(g['p90_ratio'])} the best fixed design's {_s(g['best_fixed_s'])}"
                + ("; at p90 too" if met and met90 else "; not at p90" if met else "")
                + ")."
            )
        )
        why = []
        if g["equivalent_share"] >= 0.05:
            change = changes.get(g["case"])
            size = f" (mean change {_pct(change, 2)})" if change is not None else ""
            why.append(f"{_pct(g['equivalent_share'], 0)} of the runs end `equivalent`: the bias{size} is inside "
                       "the 1 % tolerance in every 16² tile, the answer the defaults ask for; with the equivalence "
                       f"verdict off the median is {_x(noeq['biased_median_ratio'])}")  # fmt: skip
        passes = g["median_s"] / r["seconds_per_pass_both"] if g["median_s"] else None
        fixed_n = r["best_fixed_passes"]
        bound = next(
            (x for x in c5["boundaries"] if x["test"] == g["mode"] and fixed_n and x["passes"] >= fixed_n), None
        )
        if bound is not None:
            why.append(
                f"the fixed design needs only {fixed_n:.0f} passes a side; there (look {bound['look']}, "
                f"{bound['passes']} passes, {_pct(bound['fraction'])} of the {bound['max_passes']}-pass budget) "
                f"`check`'s whole-image hypothesis must reach p ≤ {bound['level_seq_coarsest']:.1g} with t on "
                f"n − 1 = {bound['passes'] - 1} degrees of freedom (|t| ≥ {_tg(bound['t_seq_coarsest'])}), the fixed "
                f"test p ≤ {bound['level_fixed_coarsest']:.1g} (|t| ≥ {_tg(bound['t_fixed_coarsest'])}): Pocock "
                "spending gives the first looks of a large budget a few per cent of α, split over 4 scales, and "
                "few degrees of freedom make a small level expensive in t"
            )
        if ws is not None and ws["biased_median_ratio"] is not None and noeq["biased_median_ratio"] is not None:
            if ws["biased_median_ratio"] < 0.9 * noeq["biased_median_ratio"]:
                why.append(
                    "Welch-Satterthwaite's ν instead of the conservative n − 1 would bring the median "
                    f"(equivalence off) from {_x(noeq['biased_median_ratio'])} to "
                    f"{_x(ws['biased_median_ratio'])} (a what-if: the design is calibrated with n − 1)"
                )
        if passes is not None and passes >= 15:
            why.append("the looks come 15 % apart, so a run stops up to 15 % after the evidence first suffices")
        if why and not (met and met90):
            text += " Why: " + "; ".join(why) + "."
        out.append(text)
    return out
