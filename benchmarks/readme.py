"""docs/benchmarks/README.md, written from the figures of the last run (figures.json) so text and charts agree."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .trials import ALPHA, LABELS

WELCH = ("welch16", "welch32", "welch64")


def _s(x) -> str:
    if x is None:
        return "not reached"
    return f"{x:.2g} s" if x < 10 else f"{x:.0f} s"


def _p(x: float) -> str:
    if x != x:
        return "—"
    return "< 1e-300" if x == 0 else f"{x:.2g}"


def _pct(x: float, digits: int = 1) -> str:
    return f"{100 * x:.{digits}f} %"


def _best(summary: list[dict], case: str, methods) -> tuple[str | None, float | None]:
    found = [(r["seconds_to_80"], r["method"]) for r in summary if r["case"] == case and r["method"] in methods]
    found = [f for f in found if f[0] is not None]
    if not found:
        return None, None
    s, m = min(found)
    return m, s


def chart1_lines(c1: dict) -> list[str]:
    summary = c1["summary"]
    cases = list(dict.fromkeys(r["case"] for r in summary))
    head = ("| case | mean change | Welch 16² | Welch 32² | Welch 64² | paired 32² | Gaussian 32² "
            "| RMSE (with / without its reference) | tile difference |")  # fmt: skip
    lines = [head, "|" + "---|" * 9]
    sentences = []
    for case in cases:
        rows = {r["method"]: r for r in summary if r["case"] == case}
        first = next(iter(rows.values()))
        rmse = rows["rmse"]["seconds_to_80"]
        conv = first["converged_seconds"]
        without = None if rmse is None else max(rmse - conv, 0.0)
        lines.append(
            f"| {first['label']} | {_pct(first['mean_change'], 2)} ± {_pct(first['mean_change_se'], 2)} | "
            + " | ".join(_s(rows[m]["seconds_to_80"]) for m in ("welch16", "welch32", "welch64", "paired32", "gauss32"))
            + f" | {_s(rmse)} / {_s(without)} | {_s(rows['tilediff16']['seconds_to_80'])} |"
        )
        m, s = _best(summary, case, WELCH)
        if m is None:
            sentences.append(f"- **{first['label']}**: no Welch tile size reached 80 % detection within the pool.")
            continue
        text = f"- **{first['label']}**: the Welch test ({LABELS[m]}) reaches 80 % detection after {_s(s)} of rendering"
        if rmse is not None:
            text += (f"; the RMSE baseline after {_s(rmse)} ({rmse / s:.0f}× more), of which {_s(conv)} is its "
                     f"converged reference (without it: {_s(without)})")  # fmt: skip
        else:
            text += f"; the RMSE baseline does not get there (its reference alone costs {_s(conv)})"
        p = rows["paired32"]["seconds_to_80"]
        if p is not None:
            text += f"; the paired test on the same seeds after {_s(p)}"
        sentences.append(text + ".")
    return lines + [""] + sentences


def fp_lines(c1: dict) -> list[str]:
    lines = [
        "| unbiased pairs | method | trials | `biased` | rate [95 % Wilson] | `inconclusive` |",
        "|---|---|---|---|---|---|",
    ]
    for r in c1["false_positives"]:
        lines.append(
            f"| {r['group']} | {LABELS[r['method']]} | {r['trials']} | {r['biased']} | {_pct(r['rate'])} "
            f"[{_pct(r['lo'])}, {_pct(r['hi'])}] | {r['inconclusive']} |"
        )
    return lines


def chart1_findings(c1: dict, det_rows: list[dict] | None = None) -> list[str]:
    """Plain sentences: which methods stay calibrated, where each one fails."""
    fp = c1["false_positives"]
    out = []
    tool = [r for r in fp if r["method"] not in ("rmse", "tilediff16")]
    base = [r for r in fp if r["method"] in ("rmse", "tilediff16")]
    worst = max(tool, key=lambda r: r["rate"])
    above = [r for r in fp if r["lo"] > ALPHA]
    out.append(
        f"- **Calibration.** On unbiased pairs the tool's tests said `biased` in at most {_pct(worst['rate'])} of the "
        f"trials ({LABELS[worst['method']]}, {worst['group']}; {worst['trials']} trials), below α = {_pct(ALPHA, 0)}: "
        "the "
        "verdict combines Holm's test and a KS test by Bonferroni, so it is conservative by design. The baselines "
        f"sit at {_pct(min(r['rate'] for r in base))}–{_pct(max(r['rate'] for r in base))} on held-out trials, as "
        "calibrated. "
        + ("No method's false-positive rate lies clearly above α." if not above else
           "Clearly above α: " + ", ".join(f"{r['method']} on {r['group']} ({_pct(r['rate'])})" for r in above) + ".")
    )  # fmt: skip
    summary = c1["summary"]
    cases = {r["case"]: r for r in summary}
    rows = {(r["case"], r["method"]): r["seconds_to_80"] for r in summary}
    lower_noise = [c for c, r in cases.items() if r.get("variance_ratio", 1.0) < 0.98]
    if lower_noise:
        what = ", ".join(f"{cases[c]['label']} (variance ×{cases[c]['variance_ratio']:.2f})" for c in lower_noise)
        missed = [c for c in lower_noise if rows[(c, "rmse")] is None]
        out.append(
            f"- **Where RMSE fails.** Several biases also lower the noise: {what}. Their RMSE is then *smaller* than "
            "that of an unbiased render until the bias outweighs the remaining noise, so an RMSE threshold stays "
            "silent for a long time"
            + (
                f" (never reached 80 % within the pool: {', '.join(cases[c]['label'] for c in missed)})"
                if missed
                else ""
            )
            + ". The RMSE also needs its converged reference, whose render time comes first on every curve."
        )
    paired = [(rows[(c, "paired32")], c) for c in cases if rows[(c, "paired32")] is not None]
    if paired:
        out.append(
            "- **Paired test.** With the same seeds on both sides the shared noise cancels: "
            + ", ".join(f"{cases[c]['label']} {_s(s)}" for s, c in paired)
            + ". For a pure scale change (light ×1.005) the difference of two passes with the same seed is exactly "
            "0.5 % of the pass, so two passes a side suffice; the paired test needs a renderer whose random numbers "
            "follow the seed, which Cycles' do."
        )
    for case in cases:
        peaks = []
        for m in ("welch16", "welch32", "gauss32", "paired32"):
            rs = [r for r in (det_rows or []) if r["case"] == case and r["method"] == m]
            peak = max(rs, key=lambda r: r["inconclusive"] / r["trials"], default=None)
            if peak and peak["inconclusive"] / peak["trials"] >= 0.25:
                peaks.append(f"{LABELS[m]} up to {_pct(peak['inconclusive'] / peak['trials'], 0)} (n = {peak['n']})")
        if peaks:
            out.append(
                f"- **Where Welch struggles: {cases[case]['label']}.** Trials ending `inconclusive`: "
                f"{'; '.join(peaks)}. At 1 spp the Welch samples of the tiles with fireflies are clearly not normal "
                "and the trust mask leaves those tiles out while a mean of so few of them is not yet near normal "
                "either; with more passes their shape measure (g1² + |g2|) / n falls below its limit, the tiles are "
                "trusted again and the detection rate climbs on. The tool says so instead of answering; larger "
                f"tiles (64²: {_s(rows[(case, 'welch64')])} to 80 %) or more spp per pass are the remedy."
            )
    return out


def chart2_lines(c2: dict) -> list[str]:
    lines = ["| method | ms per million tests | max rel. error of p | same, p ≥ 1e-7 "
             "| max rel. error of log p, p < 0.01 |",
             "|---|---|---|---|---|"]  # fmt: skip
    for r in c2["rows"]:
        lines.append(
            f"| {r['label']} | {r['ms_per_million']:.0f} | {r['max_rel_err_p']:.2g} "
            f"| {r['max_rel_err_p_decisive']:.2g} | {r['max_rel_err_log_p_small']:.2g} |"
        )
    return lines


def chart2_findings(c2: dict, c1: dict | None = None) -> list[str]:
    rows = {r["method"]: r for r in c2["rows"]}
    ex, g20, gall, aall = rows["exact"], rows["gauss_nu20"], rows["gauss_all"], rows["as_erf_all"]
    at = {(r["nu"], r["p"]): r for r in c2["at"]}
    a5, a20 = at.get((5, 0.01)), at.get((20, 1e-05))
    out = [
        f"- **Exact Student t** (the default): largest relative error of p {ex['max_rel_err_p']:.1g} over the whole "
        f"grid, of log p {ex['max_rel_err_log_p_small']:.1g}, at {ex['ms_per_million']:.0f} ms per million "
        "tile-channel tests: a 4K frame at 32² tiles has 24 120 tile-channels, so the exact p costs a few "
        "milliseconds a verdict. There is nothing to gain from an approximation.",
        f"- **Gaussian where ν ≥ 20** ('gauss'): {g20['ms_per_million']:.0f} ms per million, "
        + (
            "no faster than the exact p (welch_core evaluates the exact p everywhere, then replaces it where ν ≥ 20). "
            if g20["ms_per_million"] > 0.8 * ex["ms_per_million"]
            else f"{ex['ms_per_million'] / g20['ms_per_million']:.1f}× faster than the exact p. "
        )
        + f"Its largest relative error among p ≥ 1e-7 on the grid is {g20['max_rel_err_p_decisive']:.2g}"
        + (f"; at ν = 20, where the exact p is 1e-5, it gives {1e-5 * (1 + a20['gauss_nu20']):.2g}" if a20 else "")
        + ": the tails of t with 20 degrees of freedom are far heavier than the Gaussian's, so at the small p that "
        "Holm's correction compares against the approximation is anti-conservative." + (_gauss_fp(c1) if c1 else ""),
        f"- **Gaussian / A&S everywhere**: {gall['ms_per_million']:.0f} and {aall['ms_per_million']:.0f} ms per "
        f"million ({ex['ms_per_million'] / gall['ms_per_million']:.0f}× and "
        f"{ex['ms_per_million'] / aall['ms_per_million']:.0f}× faster than exact), but wrong where ν is small"
        + (
            f" (at ν = 5, where the exact p is 0.01, the Gaussian gives {0.01 * (1 + a5['gauss_all']):.2g})"
            if a5
            else ""
        )
        + " and underflowing to 0 in the far tail (infinite error of log p). Chart 3 shows what that does to the "
        "false-positive rate.",
    ]
    return out


def _gauss_fp(c1: dict) -> str:
    fp = {(r["group"], r["method"]): r for r in c1["false_positives"]}
    pairs = [(g, fp[(g, "welch32")], fp[(g, "gauss32")]) for g, m in fp if m == "gauss32" and (g, "welch32") in fp]
    text = ", ".join(f"{g} {_pct(w['rate'])} → {_pct(x['rate'])}" for g, w, x in pairs)
    return f" On unbiased pairs (chart 1) it moved the false-positive rate at 32² tiles from exact to Gaussian: {text}."


def chart3_findings(c3: dict) -> list[str]:
    rows = c3["rows"]
    silent = [r for r in rows if r["outcome"].startswith("SILENT")]
    flagged = [r for r in rows if "flagged" in r["outcome"] or r["outcome"].startswith("refused")]
    wrong = [r for r in rows if r["outcome"].startswith("miscalibrated")]
    out = []
    if silent:
        out.append("- **Silent false positives (a defect of the tool, to be fixed):** " + "; ".join(
            f"{r['situation']}: {_pct(r['rate'])} of {r['trials']}" for r in silent) + ".")  # fmt: skip
    else:
        out.append("- No situation produced silent false positives: every `biased` rate on unbiased pairs is "
                   f"compatible with α = {_pct(ALPHA, 0)} or below it.")  # fmt: skip
    for r in flagged:
        out.append(f"- {r['situation']}: `biased` {_pct(r['rate'])}; {r['outcome']}.")
    for r in wrong:
        out.append(f"- {r['situation']}: `biased` {_pct(r['rate'])} [{_pct(r['lo'])}, {_pct(r['hi'])}], above α: "
                   "this is why welch_core applies the Gaussian only where ν ≥ 20.")  # fmt: skip
    power = [r for r in rows if r["expected"] == "power"]
    if power:
        detected = "; ".join(
            f"{r['situation']}: detected {_pct(r['rate'], 0)}, median p {_p(r['median_p'])}" for r in power
        )
        out.append(
            f"- Seeds and power: {detected}. Welch's formula on passes with the same seeds ignores their "
            "correlation: on an unbiased pair every p is 1 (the p-values are not uniform), and for a bias its p-values "
            "are orders of magnitude larger than the paired test's on the same passes. The tool refuses it "
            "(SeedOverlapError)."
        )
    return out


def chart3_lines(c3: dict) -> list[str]:
    lines = [
        "| situation | trials | `biased` rate [95 %] | `inconclusive` | untrusted tiles | median global p | outcome |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in c3["rows"]:
        lines.append(
            f"| {r['situation']} | {r['trials']} | {_pct(r['rate'])} [{_pct(r['lo'])}, {_pct(r['hi'])}] | "
            f"{_pct(r['inconclusive'], 0)} | {_pct(r['untrusted_share'])} | {_p(r['median_p'])} | {r['outcome']} |"
        )
    return lines


def chart4_lines(c4: dict) -> list[str]:
    o, h = c4["overhead"], c4["persistent"]
    passes = ", ".join(f"{r['resolution']}²: {r['total_s']:.3g} s" for r in c4["passes"])
    verdicts = "; ".join(
        f"N = {r['passes']}: {r['compare_s'] * 1e3:.0f} ms + {r['report_s']:.2f} s" for r in c4["verdicts"]
    )
    core = ", ".join(
        f"{r['tiles']} tiles: {r['compare_s'] * 1e3:.0f} ms, {r['peak_bytes'] / 2**20:.1f} MiB" for r in c4["core"]
    )
    return [
        f"- Seconds per pass (corner, 1 spp; render + EXR write/read + accumulation): {passes}.",
        f"- Seconds per verdict (compare + report) at 128² px and 32² tiles: {verdicts}. The report (PNG maps and "
        "histograms written by matplotlib) is almost all of it; the statistics take milliseconds.",
        f"- welch_core's `compare` alone (N = 32 a side): {core}.",
        f"- Pipeline overhead at {o['resolution']}², 1 spp, corner: the bare `bpy.ops.render.render()` takes "
        f"{o['bare_s'] * 1e3:.1f} ms, a whole pass (re-seed, render, EXR write and read, accumulate) "
        f"{o['pipeline_s'] * 1e3:.1f} ms: "
        f"**{100 * o['overhead']:+.1f} %** (medians of {o['passes']} interleaved passes; the target was below 10 %)"
        + (
            f", of which the EXR write and read are {o['io_s'] * 1e3:.1f} ms and the accumulation "
            f"{o['accumulate_s'] * 1e3:.1f} ms."
            if "io_s" in o
            else "."
        ),
        f"- Persistent data on a heavy scene (corner + {h['triangles']:,} triangles, {h['resolution']}², 1 spp): "
        f"{h['median_off_s'] * 1e3:.0f} ms per pass off, {h['median_on_s'] * 1e3:.0f} ms on: **×{h['speedup']:.1f}** "
        f"(first pass {h['first_off_s']:.2f} s off, {h['first_on_s']:.2f} s on).",
    ]


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
        out += [f"{r['situation']}: {_pct(r['rate'])} -> {r['outcome']}" for r in f["chart3"]["rows"]]
    if "chart4" in f:
        out.append(f"pipeline overhead {100 * f['chart4']['overhead']['overhead']:+.1f} %, "
                   f"persistent data x{f['chart4']['persistent']['speedup']:.1f}")  # fmt: skip
    return out


def write(out_dir: Path, f: dict) -> None:
    """Write README.md into `out_dir` from the figures `f`."""
    (Path(out_dir) / "README.md").write_text(render(f))


def render(f: dict) -> str:
    b, m = f["budget"], f["machine"]
    minutes = f.get("last_run_seconds", 0) / 60
    how = (f"from an empty cache in {minutes:.0f} minutes ({f['pools_rendered']} pools rendered)"
           if f.get("pools_rendered") else f"in {minutes:.1f} minutes from cached pools")  # fmt: skip
    parts = [INTRO.format(command=f["command"], how=how, cores=m["cores"],
                          cpu=m["cpu"] or "unknown CPU", bpy=m["bpy"], numpy=m["numpy"], scipy=m["scipy"],
                          quick=" (QUICK RUN: tiny pools, the numbers mean nothing)" if f["quick"] else "",
                          )]  # fmt: skip
    if "chart1" in f:
        c1 = f["chart1"]
        parts.append(CHART1.format(res=b["resolution"], passes=b["passes"], trials=b["trials"],
                                   null=b["null_trials"], calib=b["calibration_trials"], alpha=ALPHA,
                                   conv_spp=b["converged_spp"] * b["converged_passes"],
                                   max_n=max(b["n_grid"])))  # fmt: skip
        parts += chart1_lines(c1) + ["", "False positives on unbiased pairs (all n pooled):", ""] + fp_lines(c1)
        parts += ["", *chart1_findings(c1, c1.get("detection"))]
    if "chart2" in f:
        parts.append(CHART2.format(nu=f["chart2"]["grid"]["nu"], t=f["chart2"]["grid"]["t"]))
        parts += chart2_lines(f["chart2"]) + [""] + chart2_findings(f["chart2"], f.get("chart1"))
    if "chart3" in f:
        parts.append(CHART3.format(trials=b["stability_trials"], pixel=b["pixel_trials"], alpha=ALPHA))
        parts += chart3_lines(f["chart3"]) + [""] + chart3_findings(f["chart3"])
    if "chart4" in f:
        parts.append(CHART4)
        parts += chart4_lines(f["chart4"])
    parts.append(sizes(f))
    return "\n".join(parts) + "\n"


INTRO = """# Benchmarks: speed against accuracy, and stability where the methods fail{quick}

Produced by `{command}` (from the repository root; `./dev bench` does the same) {how} on
{cores} cores ({cpu}), no GPU: Cycles on the CPU through the `bpy` {bpy} module, numpy {numpy}, scipy {scipy}.
The machine was shared with other jobs, so seconds carry some noise; every render second on the charts is the
median seconds of a pass times the passes used. The CSV files beside this README hold every plotted number;
`figures.json` holds what this text quotes. A second run reads the pools and the trial results back from
`benchmarks/cache/` (keyed by configuration, bpy version and welch_core's source) and only redraws: seconds.

How the trials work: each configuration is rendered once into a pool of passes (one seed each, 1 sample per
pixel; the reference and its biased variant use the same seeds), cached in `benchmarks/cache/`, and the trials
draw passes from the pools. An unpaired trial takes the reference's passes from one random half of the seeds and
the test's from the other half; a paired trial takes the same seeds from both pools. Trials resample one pool, so
they are not fully independent (two trials at half the pool a side share most of their passes); the number of
trials sits in every CSV row and every rate has a 95 % Wilson interval.
"""

CHART1 = """
## Chart 1: detection rate against render time

![chart 1](chart1_detection.png)

Pools of {passes} passes at {res}×{res} px, 1 spp. {trials} trials per point on biased pairs; {null} trials per
pass count on unbiased pairs for the tool's tests. Methods: the tool's `compare` at α = {alpha} (Welch at tiles
16², 32², 64²; the paired test on identical seeds; the paper's Gaussian approximation where ν ≥ 20); and two
baselines with thresholds calibrated to the same false-positive rate on {calib} unbiased trials per pass count
(half set the threshold, the other half measure its false-positive rate): the RMSE of the test's mean image
against a converged reference of {conv_spp} spp (its render time is counted on the x axis), and the largest
absolute tile-mean difference at 16² tiles (a thresholded tile-wise difference image). The calibration is free
for the baselines here (it comes from the pools); a user would have to pay for it, so the comparison favours
them. A curve stops once two pass counts in a row found every trial biased.

Render seconds (both sides) until 80 % of the trials say `biased` ("not reached": not within {max_n} passes a side):
"""

CHART2 = """
## Chart 2: p-value methods, time against error

![chart 2](chart2_pvalue_methods.png)

Reference: mpmath at 40 digits on {nu} values of ν (log-spaced in [1, 10⁴]) × {t} values of |t| in [0, 40].
Timing: one million tile-channel tests with |t| uniform in [0, 40] and ν log-uniform, best of 5.
"""

CHART3 = """
## Chart 3: stability where the methods fail

![chart 3](chart3_stability.png)

{trials} trials per situation ({pixel} for the per-pixel tests, which test 16 384 pixels a trial), α = {alpha},
corner scene at 128² px and 1 spp unless stated. Expected of each: calibrated (the `biased` rate's interval
reaches down to α), or flagged by the tool (`inconclusive`, untrusted tiles, a note, a refusal). Rows marked
"by hand" are not the tool's behaviour: they show what it guards against.
"""

CHART4 = """
## Chart 4: how the cost grows

![chart 4](chart4_cost.png)
"""

SIZES = """
## Why these sizes suffice (model no more than a scene needs)

- {res}×{res} px is the smallest square that holds four {half}² tiles (64² is the largest tile the paper uses).
  Every effect here is a change of a material, a light or an integrator setting that covers most of the frame, so
  more pixels would add tiles of the same kind, not new information.
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
