"""Chart 6: A/A runs of `check`: a configuration against itself, rendered until decided.

Simulated runs (`checks`) at `check`'s defaults (alpha 1 %, tolerance 1 %, finest tile 16 px, every scale, the pool
as the budget) on the unbiased pools: the corner (chart 1's; unpaired, as ``check --unpaired`` on one build does),
the bright corner, the glossy scene and the glass sphere (chart 3's, the caustic case of §5.1), all unpaired, and
one paired pair (Sobol against blue noise on the same seeds: unbiased, chart 1's paired null). What is measured:
how often and how fast a run ends `equivalent`, how often `biased` (at most alpha is the design's promise; counts
with a 95 % Wilson interval) and how often `inconclusive` at the budget, with the bias it rules out then.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..common import checks, plan, trials
from ..common.plotting import plt, save, write_csv
from ..common.pools import load_or_render, say
from ..common.trials import ALPHA
from ..common.words import n as _n
from ..common.words import pct as _pct
from ..common.words import s as _s


def summarize(pair: dict, runs: list[dict], ref, per_pass: float) -> dict:
    """Outcome counts, the passes to `equivalent` and what the runs that spent the budget rule out."""
    total = len(runs)
    k = {v: sum(r["verdict"] == v for r in runs) for v in ("equivalent", "biased", "inconclusive")}
    lo, hi = trials.wilson(k["biased"], total)
    eq = [r["passes"] for r in runs if r["verdict"] == "equivalent"]
    stuck = [r for r in runs if r["verdict"] == "inconclusive"]
    bounds = [r["ruled_out"] for r in stuck if r["ruled_out"] is not None]
    tiles = [r["ruled_out_tile"] for r in stuck if r["ruled_out_tile"] is not None]
    eq_tiles = [r["ruled_out_tile"] for r in runs if r["verdict"] == "equivalent" and r["ruled_out_tile"]]
    q = lambda v, p: float(np.quantile(v, p, method="higher")) if v else None  # noqa: E731
    return {
        "pair": pair["name"], "label": pair["label"], "paired": pair["paired"], "runs": total,
        "max_passes": checks.budget(ref, pair["paired"]),
        **k, "equivalent_share": k["equivalent"] / total, "biased_rate": k["biased"] / total, "biased_lo": lo,
        "biased_hi": hi, "inconclusive_share": k["inconclusive"] / total,
        "equivalent_median_passes": q(eq, 0.5), "equivalent_p90_passes": q(eq, 0.9),
        "equivalent_median_s": None if not eq else q(eq, 0.5) * per_pass,
        "equivalent_p90_s": None if not eq else q(eq, 0.9) * per_pass,
        "inconclusive_median_ruled_out": q(bounds, 0.5),
        "inconclusive_tile": max(set(tiles), key=tiles.count) if tiles else None,
        # the scale of the tightest bound when a run ended `equivalent` (most often), and how often it was that one
        "equivalent_tile": max(set(eq_tiles), key=eq_tiles.count) if eq_tiles else None,
        "equivalent_tile_share": max(eq_tiles.count(t) for t in set(eq_tiles)) / len(eq_tiles) if eq_tiles else None,
        "equivalent_median_bound": q([r["ruled_out"] for r in runs if r["verdict"] == "equivalent"], 0.5),
        "inconclusive_uncovered_median": q([r["uncovered"] for r in stuck], 0.5),
    }  # fmt: skip


def run(b: plan.Budget, cache_dir: Path, out_dir: Path) -> dict:
    rows, all_runs = [], {}
    for pair in plan.aa_pairs(b):
        ref, test = load_or_render(pair["ref"], cache_dir), load_or_render(pair["test"], cache_dir)
        say(f"chart 6: A/A runs of check on {pair['label']}")
        runs = checks.simulate(ref, test, pair["paired"], pair["runs"], cache_dir)
        all_runs[pair["name"]] = runs
        row = summarize(pair, runs, ref, ref.seconds_per_pass + test.seconds_per_pass)
        rows.append(row)
        say(
            f"  {pair['name']}: equivalent {row['equivalent']}, biased {row['biased']}, inconclusive "
            f"{row['inconclusive']} of {row['runs']}; median passes to equivalent {row['equivalent_median_passes']}"
        )
    files = [write_csv(out_dir / "chart6_aa.csv", rows), _plot(out_dir / "chart6_aa.png", rows, all_runs)]
    return {"files": files, "rows": rows}


def _plot(path: Path, rows: list[dict], all_runs: dict) -> str:
    fig, (left, right) = plt.subplots(1, 2, figsize=(15, 5.5), width_ratios=[1, 1.2])
    colors = {"equivalent": "#2ca02c", "biased": "#d62728", "inconclusive": "#7f7f7f"}
    y = np.arange(len(rows))[::-1]
    start = np.zeros(len(rows))
    for verdict, color in colors.items():
        share = np.array([r[verdict] / r["runs"] for r in rows])
        left.barh(y, share, left=start, color=color, label=verdict)
        for yi, s0, s, r in zip(y, start, share, rows, strict=True):
            if s > 0:
                left.text(s0 + s / 2, yi, f"{r[verdict]}", ha="center", va="center", fontsize=8, color="white")
        start += share
    left.set_yticks(y, [f"{r['label']}\n({r['runs']} runs, ≤ {r['max_passes']} passes a side)" for r in rows],
                    fontsize=8)  # fmt: skip
    left.set_xlabel("share of runs")
    left.set_title("How each A/A run of `check` ended (tolerance 1 %, α = 0.01)", fontsize=10)
    left.legend(fontsize=8, loc="lower right")
    for r, color in zip(rows, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False):
        runs = all_runs[r["pair"]]
        passes = np.sort([x["passes"] for x in runs if x["verdict"] == "equivalent"])
        if len(passes):
            right.step(passes, np.arange(1, len(passes) + 1) / len(runs), where="post", color=color, label=r["label"])
    right.set_xscale("log")
    right.set_xlabel("passes a side at the decision (log)")
    right.set_ylabel("share of runs `equivalent` by then")
    right.set_title("When the A/A runs ended `equivalent`", fontsize=10)
    right.grid(alpha=0.3, which="both", lw=0.4)
    right.legend(fontsize=8)
    fig.suptitle(f"Chart 6: A/A runs of check (α = {ALPHA})")
    fig.tight_layout()
    return save(fig, path)


# -- its section of docs/benchmarks/README.md --------------------------------------------------------------------------


def section(f: dict) -> list[str]:
    """Chart 6's section of docs/benchmarks/README.md from the figures `f`."""
    return [CHART6, *chart6_lines(f["chart6"]), "", *chart6_findings(f["chart6"])]


CHART6 = """
## Chart 6: A/A runs of `check`

![chart 6](chart6_aa.png)

`check` at its defaults (as in chart 5) on unbiased pairs: a configuration against itself with disjoint seeds
(`check --unpaired`), and one paired pair (Sobol against blue noise on the same seeds: two sampling patterns of
one scene, unbiased). The budget is the pool. The design promises `biased` in at most α of the runs, however many
looks they take.
"""


def chart6_lines(c6: dict) -> list[str]:
    lines = [
        "| unbiased pair | runs (budget a side) | `equivalent` | passes a side to `equivalent`: median, p90 "
        "| render seconds: median, p90 | `biased` [95 % Wilson] | `inconclusive` at the budget "
        "| those rule out (median) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in c6["rows"]:
        rule = "—"
        if r["inconclusive_median_ruled_out"] is not None:
            rule = f"±{_pct(r['inconclusive_median_ruled_out'], 2)} at {r['inconclusive_tile']}²"
        lines.append(
            f"| {r['label']} | {r['runs']} ({r['max_passes']}) | {_pct(r['equivalent_share'])} | "
            f"{_n(r['equivalent_median_passes'])}, {_n(r['equivalent_p90_passes'])} | "
            f"{_s(r['equivalent_median_s'])}, {_s(r['equivalent_p90_s'])} | {r['biased']} = "
            f"{_pct(r['biased_rate'])} [{_pct(r['biased_lo'])}, {_pct(r['biased_hi'])}] | "
            f"{_pct(r['inconclusive_share'])} | {rule} |"
        )
    return lines


def chart6_findings(c6: dict) -> list[str]:
    rows = {r["pair"]: r for r in c6["rows"]}
    out = []
    c = rows.get("corner")
    if c:
        out.append(
            f"- **Corner A/A** ({c['runs']} runs): `equivalent` in {_pct(c['equivalent_share'])}, after a median of "
            f"{_n(c['equivalent_median_passes'])} passes a side ({_s(c['equivalent_median_s'])} of rendering, 90 % "
            f"by {_n(c['equivalent_p90_passes'])}); `biased` {c['biased']} times ({_pct(c['biased_rate'])}, 95 % "
            f"Wilson [{_pct(c['biased_lo'])}, {_pct(c['biased_hi'])}], α = {_pct(ALPHA, 0)}); `inconclusive` "
            f"{_pct(c['inconclusive_share'])}. Nobody chose N: the budget is only a ceiling."
            + (
                f" The bias ruled out at the stop (median ±{_pct(c['equivalent_median_bound'], 2)}) held at the "
                f"{c['equivalent_tile']}² scale in {_pct(c['equivalent_tile_share'], 0)} of those runs "
                "(`equivalent` holds once every tile of the finest scale is bounded within the tolerance)."
                if c.get("equivalent_tile")
                else ""
            )
        )
    above = [r for r in c6["rows"] if r["biased_lo"] > ALPHA]
    out.append(
        "- **Calibration of `biased`**: "
        + ("every pair's `biased` rate is compatible with α or below it." if not above else
           "above α: " + ", ".join(f"{r['label']} {_pct(r['biased_rate'])}" for r in above) + ".")
    )  # fmt: skip
    stuck = [r for r in c6["rows"] if r["inconclusive_share"] >= 0.05]
    for r in stuck:
        bound = r["inconclusive_median_ruled_out"]
        scale = f"{r['inconclusive_tile']}²"
        rules = (f"they rule out a bias beyond ±{_pct(bound, 2)} (median) at the {scale} scale" if bound else
                 f"at the {scale} scale some tile is not bounded at all (its interval spans more than ±1000 %: a "
                 "dark tile, or one of fireflies)")  # fmt: skip
        out.append(
            f"- **{r['label']}**: {_pct(r['inconclusive_share'], 0)} of the runs spend the budget of "
            f"{r['max_passes']} passes a side and end `inconclusive`; {rules}, so not every 16² tile within ±1 %, "
            "the claim `equivalent` makes: at 1 spp its noise needs more passes for a 1 % bound in every tile than "
            "the pool holds (chart 8: the passes each scale needs)"
            + (f" (tiles tested at no scale at the end: median {_n(r['inconclusive_uncovered_median'])})"
               if r["inconclusive_uncovered_median"] else ", with every tile testable at some scale")
            + "."
        )  # fmt: skip
    return out
