"""docs/benchmarks/README.md, written from the figures of the last run (figures.json) so text and charts agree."""

from __future__ import annotations

from pathlib import Path

from .trials import ALPHA, LABELS

WELCH = ("welch16", "welch32", "welch64")


def _s(x) -> str:
    if x is None:
        return "not reached"
    return f"{x:.2g} s" if x < 10 else f"{x:.0f} s"


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


def chart3_lines(c3: dict) -> list[str]:
    lines = [
        "| situation | trials | `biased` rate [95 %] | `inconclusive` | untrusted tiles | median global p | outcome |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in c3["rows"]:
        lines.append(
            f"| {r['situation']} | {r['trials']} | {_pct(r['rate'])} [{_pct(r['lo'])}, {_pct(r['hi'])}] | "
            f"{_pct(r['inconclusive'], 0)} | {_pct(r['untrusted_share'])} | {r['median_p']:.2g} | {r['outcome']} |"
        )
    return lines


def chart4_lines(c4: dict) -> list[str]:
    o, h = c4["overhead"], c4["persistent"]
    passes = ", ".join(f"{r['resolution']}²: {r['total_s']:.3g} s" for r in c4["passes"])
    verdicts = ", ".join(
        f"N = {r['passes']}: {r['compare_s'] * 1e3:.0f} ms + {r['report_s']:.2f} s" for r in c4["verdicts"]
    )
    core = ", ".join(
        f"{r['tiles']} tiles: {r['compare_s'] * 1e3:.0f} ms, {r['peak_bytes'] / 2**20:.1f} MiB" for r in c4["core"]
    )
    return [
        f"- Seconds per pass (corner, 1 spp; render + EXR write/read + accumulation): {passes}.",
        f"- Seconds per verdict (compare + report) at 128² px and 32² tiles: {verdicts}.",
        f"- welch_core's `compare` alone (N = 32 a side): {core}.",
        f"- Pipeline overhead at {o['resolution']}², 1 spp, corner: the bare `bpy.ops.render.render()` takes "
        f"{o['bare_s'] * 1e3:.1f} ms, a whole pass (re-seed, render, EXR write and read, accumulate) "
        f"{o['pipeline_s'] * 1e3:.1f} ms: "
        f"**{100 * o['overhead']:+.1f} %** (medians of {o['passes']} interleaved passes; the target was below 10 %).",
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
    parts = [INTRO.format(command=f["command"], minutes=f.get("last_run_seconds", 0) / 60, cores=m["cores"],
                          cpu=m["cpu"] or "unknown CPU", bpy=m["bpy"], numpy=m["numpy"], scipy=m["scipy"],
                          quick=" (QUICK RUN: tiny pools, the numbers mean nothing)" if f["quick"] else "",
                          )]  # fmt: skip
    if "chart1" in f:
        c1 = f["chart1"]
        parts.append(CHART1.format(res=b["resolution"], passes=b["passes"], trials=b["trials"],
                                   null=b["null_trials"], calib=b["calibration_trials"], alpha=ALPHA,
                                   conv_spp=b["converged_spp"] * b["converged_passes"]))  # fmt: skip
        parts += chart1_lines(c1) + ["", "False positives on unbiased pairs (all n pooled):", ""] + fp_lines(c1)
    if "chart2" in f:
        parts.append(CHART2.format(nu=f["chart2"]["grid"]["nu"], t=f["chart2"]["grid"]["t"]))
        parts += chart2_lines(f["chart2"])
    if "chart3" in f:
        parts.append(CHART3.format(trials=b["stability_trials"], pixel=b["pixel_trials"], alpha=ALPHA))
        parts += chart3_lines(f["chart3"])
    if "chart4" in f:
        parts.append(CHART4)
        parts += chart4_lines(f["chart4"])
    parts.append(FINDINGS_HEADER)
    parts.append(SIZES.format(res=b["resolution"], passes=b["passes"]))
    return "\n".join(parts) + "\n"


INTRO = """# Benchmarks: speed against accuracy, and stability where the methods fail{quick}

Produced by `{command}` (from the repository root; `./dev bench` does the same) in {minutes:.0f} minutes on
{cores} cores ({cpu}), no GPU: Cycles on the CPU through the `bpy` {bpy} module, numpy {numpy}, scipy {scipy}.
The machine was shared with other jobs, so seconds carry some noise; every render second on the charts is the
median seconds of a pass times the passes used. The CSV files beside this README hold every plotted number;
`figures.json` holds what this text quotes.

How the trials work: each configuration is rendered once into a pool of passes (one seed each, 1 sample per
pixel; the reference and its biased variant use the same seeds), cached in `benchmarks/cache/`, and the trials
draw passes from the pools. An unpaired trial takes the reference's passes from one random half of the seeds and
the test's from the other half; a paired trial takes the same seeds from both pools. Trials resample one pool, so
they are not fully independent (two trials at n = 200 a side share most of their passes); the number of trials
sits in every CSV row and every rate has a 95 % Wilson interval.
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

Render seconds (both sides) until 80 % of the trials say `biased` ("not reached": not within 200 passes a side):
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

FINDINGS_HEADER = ""

SIZES = """
## Why these sizes suffice (model no more than a scene needs)

- {res}×{res} px is the smallest square that holds four 64² tiles, the largest tile the paper uses; every effect
  here is a change of a material, a light or an integrator setting that covers most of the frame, so more pixels
  would add tiles of the same kind, not new information.
- 1 spp per pass: one pass is one Welch sample of one Monte Carlo sample per pixel, as in the paper; at 1 spp a
  128² pass costs a few hundredths of a second, so the pass count, not the resolution, sets the render budget.
- {passes} passes per pool let unpaired trials use up to 200 passes a side with disjoint seeds; the hardest case
  here needs fewer than that for the Welch test, and the RMSE baseline is given the same budget.
- The grey corner (walls 0.2, 60 W) is the paper's scene; the bright corner (walls 0.8, 600 W, bounce limits
  1024) exists because in the grey corner no indirect sample reaches the clamp of 10 and almost nothing survives
  beyond two bounces, so clamping and bounce limits change nothing there (measured: equal means to 7 digits).
"""
