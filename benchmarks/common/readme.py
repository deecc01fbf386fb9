"""docs/benchmarks/README.md, written from the figures of the last run (figures.json) so text and charts agree.

Each chart writes its own section (its module's ``section(figures)``); `render` puts them in order between the
introduction and the parts that read several charts' figures (the goals, the studies, the sizes)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from .words import WELCH
from .words import best as _best
from .words import fine_share as _fine_share
from .words import n as _n
from .words import pct as _pct
from .words import s as _s
from .words import x as _x


def goal_lines(f: dict) -> list[str]:
    """The goals of issue 11, each with what was measured."""
    out = []
    if "chart5" in f:
        goal = f["chart5"]["goal"]
        met = [g for g in goal if g["median_ratio"] is not None and g["median_ratio"] <= 1.25]
        out.append(
            f"- *`check` reaches `biased` in at most 1.25× the render time of the best fixed design in hindsight, on "
            f"every case*: **met in {len(met)} of {len(goal)}** case-and-test pairs at the median ("
            + ", ".join(f"{g['case']} {g['mode']} {_x(g['median_ratio'])}" for g in goal)
            + "); see chart 5 for p80, p90 and the reasons."
        )  # fmt: skip
    if "chart6" in f:
        c = next((r for r in f["chart6"]["rows"] if r["pair"] == "corner"), None)
        if c:
            out.append(
                "- *A/A on the built-in corner scene ends `equivalent` at tolerance 1 % without the user choosing N*: "
                + ("**met**" if c["equivalent_share"] >= 0.95 else "**not met**")
                + f": {_pct(c['equivalent_share'])} of {c['runs']} runs, median {_n(c['equivalent_median_passes'])} "
                f"passes a side; `biased` {c['biased']} of {c['runs']}."
                + (
                    ""
                    if c["equivalent_share"] >= 0.95
                    else " `equivalent` now claims every 16² tile within ±1 %, which "
                    f"{c['max_passes']} passes a side of 1 spp do not reach in the darkest tiles; `--equivalence-tile` "
                    "claims it for larger tiles, and chart 8 measures the passes each size needs."
                )
            )
    if "chart7" in f:
        multi = [r for r in f["chart7"]["glass"] if r["tile"] == "multi"]
        if multi:
            worst = max(multi, key=lambda r: r["inconclusive_share"])
            fine = [r for r in f["chart7"]["glass"] if r["tile"] in ("16", "32")]
            glass6 = next((r for r in f.get("chart6", {}).get("rows", []) if r["pair"] == "glass"), None)
            text = (
                "- *No A/A of the glass-sphere scene ends inconclusive at the defaults merely because tiles are too "
                "small*: `compare` at its defaults ends `inconclusive` in at most "
                f"{_pct(worst['inconclusive_share'], 0)} of the trials (n = {worst['n']}; whole image flagged in "
                f"{worst['coarsest_untrusted']} of {worst['trials']}), against {_fine_share(fine)} at 16² or 32² "
                "alone"
                + (": **met** for `compare`." if worst["inconclusive_share"] <= worst["coarsest_untrusted"]
                   / worst["trials"] else ": **not met** for `compare`.")
            )  # fmt: skip
            if glass6:
                text += (f" `check` on the glass A/A ends `inconclusive` in {_pct(glass6['inconclusive_share'], 0)} of "
                         f"its runs, not for the tiles (median tiles tested at no scale: "
                         f"{_n(glass6['inconclusive_uncovered_median'])}) but because ±1 % is not reached within "
                         f"{glass6['max_passes']} passes a side in every 16² tile"
                         + (f" (it rules out ±{_pct(glass6['inconclusive_median_ruled_out'], 2)})"
                            if glass6["inconclusive_median_ruled_out"] else
                            " (some caustic tile is not bounded at all)"))  # fmt: skip
                text += "."
            out.append(text)
    if "chart3" in f:
        rows = f["chart3"]["rows"]
        bad = [(r["situation"], k) for r in rows for k in ("outcome", "multi_outcome", "check_outcome")
               if k in r and (r[k].startswith("SILENT") or r[k].startswith("false positives"))]  # fmt: skip
        out.append(
            "- *Calibration of every verdict at alpha, or flagged, in every situation of chart 3*: "
            + ("**met**: no silent false positives at one tile size, at every scale or with `check`." if not bad else
               "**not met**: " + "; ".join(f"{s} ({k})" for s, k in bad) + ".")
            + " Calibration of `equivalent` (at most α when the true difference is at the tolerance) is not measured "
            "here."
        )  # fmt: skip
    return out


def headlines(f: dict) -> list[str]:
    """The figures worth printing at the end of a run."""
    out = []
    if "chart1" in f:
        for case in dict.fromkeys(r["case"] for r in f["chart1"]["summary"]):
            rows = {r["method"]: r["seconds_to_80"] for r in f["chart1"]["summary"] if r["case"] == case}
            m, s = _best(f["chart1"]["summary"], case, WELCH)
            out.append(f"{case}: 80 % detection: Welch {_s(s)}, paired {_s(rows['paired32'])}, RMSE {_s(rows['rmse'])}")
        for r in f["chart1"]["false_positives"]:
            out.append(f"false positives {r['group']} {r['method']}: {_pct(r['rate'])} of {r['trials']}")
    if "chart3" in f:
        out += [f"{r['situation']}: {_pct(r['rate'])} -> {r['outcome']}; every scale {_pct(r['multi_rate'])} -> "
                f"{r['multi_outcome']}" for r in f["chart3"]["rows"]]  # fmt: skip
    if "chart5" in f:
        for g in f["chart5"]["goal"]:
            out.append(f"check {g['mode']} on {g['case']}: median {_s(g['median_s'])} ({_x(g['median_ratio'])}), p90 "
                       f"{_s(g['p90_s'])} ({_x(g['p90_ratio'])}) against the best fixed {_s(g['best_fixed_s'])}; "
                       f"equivalent {_pct(g['equivalent_share'], 0)}")  # fmt: skip
    if "chart6" in f:
        for r in f["chart6"]["rows"]:
            out.append(f"check A/A {r['pair']}: equivalent {_pct(r['equivalent_share'])}, biased {r['biased']} of "
                       f"{r['runs']}, inconclusive {_pct(r['inconclusive_share'])}")  # fmt: skip
    if "chart7" in f:
        for r in f["chart7"]["cases"]:
            out.append(f"every scale vs best tile on {r['case']}: {_x(r['multi_over_best'])}")
    out += goal_lines(f)
    if "chart4" in f:
        out.append(f"pipeline overhead {100 * f['chart4']['overhead']['overhead']:+.1f} %, "
                   f"persistent data x{f['chart4']['persistent']['speedup']:.1f}")  # fmt: skip
    return out


#: A chart's section: its lines of the README from the figures of every chart.
Section = Callable[[dict], list[str]]


def write(out_dir: Path, f: dict, sections: dict[str, Section]) -> None:
    """Write README.md into `out_dir` from the figures `f` (see `render`)."""
    (Path(out_dir) / "README.md").write_text(render(f, sections))


def render(f: dict, sections: dict[str, Section]) -> str:
    """The README from the figures `f`; `sections` maps each chart's key in `f` ("chart1", ...) to its section, in
    the order they are written (a chart without figures is left out)."""
    m = f["machine"]
    minutes = f.get("last_run_seconds", 0) / 60
    how = (f"from an empty cache in {minutes:.0f} minutes ({f['pools_rendered']} pools rendered)"
           if f.get("pools_rendered") else f"in {minutes:.1f} minutes from cached pools")  # fmt: skip
    parts = [INTRO.format(command=f["command"], how=how, cores=m["cores"],
                          cpu=m["cpu"] or "unknown CPU", bpy=m["bpy"], numpy=m["numpy"], scipy=m["scipy"],
                          quick=" (QUICK RUN: tiny pools, the numbers mean nothing)" if f["quick"] else "",
                          )]  # fmt: skip
    for chart, note in sorted(f.get("notes", {}).items()):
        parts.append(f"Chart {chart}: {note}\n")
    for key, section in sections.items():
        if key in f:
            parts += section(f)
    goals = goal_lines(f)
    if goals:
        parts += [GOALS] + goals
    parts.append(STUDIES)
    parts.append(sizes(f))
    return "\n".join(parts) + "\n"


INTRO = """# Benchmarks: speed against accuracy, and stability where the methods fail{quick}

Produced by `{command}` (from the repository root; `./dev bench` does the same) {how} on
{cores} cores ({cpu}), no GPU: Cycles on the CPU through the `bpy` {bpy} module, numpy {numpy}, scipy {scipy}.
The machine was shared with other jobs, so seconds carry some noise; every render second on the charts is the
median seconds of a pass times the passes used. The CSV files beside this README hold every plotted number;
`figures.json` holds what this text quotes. A second run reads the pools and the trial results back from
`benchmarks/cache/` (keyed by configuration, bpy version and the source of welch_core's statistics) and only
redraws: seconds. `python -m benchmarks --charts 1 3 5 6 7` re-runs some charts (the others keep their figures).

How the trials work: each configuration is rendered once into a pool of passes (one seed each, 1 sample per
pixel; the reference and its biased variant use the same seeds), cached in `benchmarks/cache/`, and the trials
draw passes from the pools. An unpaired trial takes the reference's passes from one random half of the seeds and
the test's from the other half; a paired trial takes the same seeds from both pools. Trials resample one pool, so
they are not fully independent (two trials at half the pool a side share most of their passes); the number of
trials sits in every CSV row and every rate has a 95 % Wilson interval.
"""


GOALS = """
## The goals of issue 11, measured
"""

STUDIES = """
## Studies beside the charts

Each is its own command, run from the repository root on the same cached pools; its files sit beside this README.

- `python -m benchmarks.studies.power` (power.csv, power_aa.csv, power.png): passes a side to `biased` of `check` at its
  defaults against the best fixed design in hindsight and a matched-filter oracle told the bias pattern, with and
  without the early design (half of each `biased` level spent by 16 passes a side), on chart 5's cases and a
  rendered glass caustic and fog volume; and the A/A pairs of chart 6 under both designs. Charts 5, 6 and 8 above
  were last run before the early design existed: power.csv holds chart 5's comparison for the current one.
  Findings: [docs/findings/power.md](../findings/power.md).
- `python -m benchmarks.studies.moderated` (moderated.csv): moderated variances (limma-trend empirical Bayes across
  tiles) against `check`'s t-tests at 2–8 passes a side: power on the bias cases, `biased` on the A/A pairs.
- `python -m benchmarks.studies.sparse` (sparse.csv, sparse.png): changes that alter a few light paths, paired alone
  against the default and Welch's test
  ([docs/findings/sparse_paired_differences.md](../findings/sparse_paired_differences.md)).
- `python -m benchmarks.studies.production`: a 1920×1080 `check`, its wall time split into rendering and everything
  else.
- `python -m benchmarks.studies.unequal` (unequal.csv, unequal.png): `biased` on rendered A/A splits whose sides differ
  in passes (4 v 256 to 256 v 8, suites blessed at 256 and 512), before and after the permutation test, with
  detection and paired A/A beside them. Findings: [docs/findings/unequal_passes.md](../findings/unequal_passes.md).
- `python -m benchmarks.studies.same` (same_*.csv, same.png): what `check` says on unbiased pairs of every built-in
  scene at 128², the tile size of its `equivalent`, a local bias, the futility stop's price, `compare` at 2-4
  passes of a caustic ([docs/results.md](../results.md#saying-the-same)).
"""


SIZES = """
## Why these sizes suffice (model no more than a scene needs)

- {res}×{res} px is the smallest square that holds four {half}² tiles (64² is the largest tile the paper uses).
  Every effect of chart 1 is a change of a material, a light or an integrator setting that covers most of the
  frame, so more pixels would add tiles of the same kind, not new information; chart 7's local bias (the metal
  sphere) covers a few tiles of 16² on purpose.
- 1 spp per pass: one pass is one Welch sample of one Monte Carlo sample per pixel, as in the paper. A pass costs
  {pass_ms} of rendering, so the pass count, not the resolution, sets the budget, and the smallest
  detectable change is set by how many passes one can afford.
- {passes} passes per pool let unpaired trials use up to {half_pool} passes a side with disjoint seeds. {slowest}
- The grey corner (walls 0.2, 60 W) is the paper's scene; the bright corner (walls 0.8, 600 W; like every
  built-in scene its bounce limits are at the maximum, 1024) exists because in the grey corner no indirect sample
  reaches the clamp of 10 and almost nothing survives beyond two bounces, so clamping and bounce limits change
  nothing there (measured: equal means to 7 digits).
- The converged reference of the RMSE baseline has {conv_spp} spp ({conv_n} passes of {conv_pass} spp); a larger one
  would cost proportionally more render time before the first RMSE verdict.
"""


def sizes(f: dict) -> str:
    b = f["budget"]
    slowest = ""
    pass_ms = "a few milliseconds"
    if "chart1" in f:
        summary = f["chart1"]["summary"]
        spp = [p["seconds_per_pass"] for p in f["chart1"]["pools"] if p["spp"] == 1]
        pass_ms = f"{1e3 * min(spp):.0f}–{1e3 * max(spp):.0f} ms"
        best = {}
        for r in summary:
            if r["method"] in WELCH and r["passes_to_80"] is not None:
                best[r["label"]] = min(best.get(r["label"], np.inf), r["passes_to_80"])
        if best:
            label = max(best, key=best.get)
            slowest = (f"The slowest case for the Welch test ({label}) reaches 80 % detection at {best[label]:.0f} "
                       "passes a side at its best tile size.")  # fmt: skip
    return SIZES.format(res=b["resolution"], half=b["resolution"] // 2, passes=b["passes"], half_pool=b["passes"] // 2,
                        pass_ms=pass_ms, slowest=slowest, conv_spp=b["converged_spp"] * b["converged_passes"],
                        conv_pass=b["converged_spp"], conv_n=b["converged_passes"])  # fmt: skip
