"""Chart 1: detection rate against render seconds, per bias case and method, and the false-positive rates.

x: render seconds spent on both sides (the median seconds of a pass of each pool times the passes used; for the
RMSE baseline the converged reference's whole render time plus the test's passes). y: share of trials that call
the pair biased at alpha = 0.01, with a 95 % Wilson interval.
"""

from __future__ import annotations

from pathlib import Path

from ..common import fixed_designs, plan, trials
from ..common.plotting import COLORS, plt, save, write_csv
from ..common.trials import ALPHA, FIXED_PAIRED, LABELS, METHODS
from ..common.words import WELCH
from ..common.words import best as _best
from ..common.words import cell as _cell
from ..common.words import pct as _pct
from ..common.words import s as _s
from ..common.words import tile as _tile

#: The curves drawn on chart 1 (every method is in the CSV files): the paired test's other single tile sizes are
#: left off the plot to keep it readable.
PLOTTED = tuple(m for m in METHODS if m not in ("paired16", "paired64", "paired128"))


def run(b: plan.Budget, cache_dir: Path, out_dir: Path) -> dict:
    """Every trial, the CSVs and the chart; return the headline figures."""
    found = fixed_designs.compute(b, cache_dir)
    cases, pools, det_rows, fp_rows, summary = (found[k] for k in ("cases", "pools", "detection", "false_positives",
                                                                   "summary"))  # fmt: skip
    files = [
        write_csv(out_dir / "chart1_detection.csv", det_rows),
        write_csv(out_dir / "chart1_false_positives.csv", fp_rows),
        write_csv(out_dir / "chart1_seconds_to_80.csv", summary),
        _plot(out_dir / "chart1_detection.png", cases, det_rows, fp_rows, summary),
    ]
    return {"files": files, "summary": summary, "false_positives": _fp_totals(fp_rows), "pools": _pool_rows(pools),
            "detection": det_rows}  # fmt: skip


def _fp_totals(fp_rows: list[dict]) -> list[dict]:
    """False-positive rate per reference and method over all n."""
    out = []
    for group in dict.fromkeys(r["group"] for r in fp_rows):
        for m in METHODS:
            rows = [r for r in fp_rows if r["group"] == group and r["method"] == m]
            if rows:
                k, total = sum(r["biased"] for r in rows), sum(r["trials"] for r in rows)
                lo, hi = trials.wilson(k, total)
                inc = sum(r["inconclusive"] for r in rows)
                out.append({"group": group, "method": m, "trials": total, "biased": k, "rate": k / total,
                            "lo": lo, "hi": hi, "inconclusive": inc})  # fmt: skip
    return out


def _pool_rows(pools: dict) -> list[dict]:
    return [
        {"scene": p.spec.scene, "overrides": " ".join(p.spec.overrides), "resolution": p.spec.resolution,
         "spp": p.spec.spp, "passes": p.n, "pattern": p.spec.pattern, "seconds_per_pass": p.seconds_per_pass,
         "total_seconds": p.total_seconds, "key": p.spec.key}
        for p in pools.values()
    ]  # fmt: skip


def _plot(path: Path, cases, det_rows, fp_rows, summary) -> str:
    fig = plt.figure(figsize=(16, 13))
    grid = fig.add_gridspec(3, 3, height_ratios=[1, 1, 0.9], hspace=0.42, wspace=0.22, bottom=0.1, top=0.92)
    for i, c in enumerate(cases):
        ax = fig.add_subplot(grid[i // 3, i % 3])
        info = next(s for s in summary if s["case"] == c.name)
        for m in PLOTTED:
            rows = sorted((r for r in det_rows if r["case"] == c.name and r["method"] == m), key=lambda r: r["n"])
            if not rows:
                continue
            x = [r["seconds"] for r in rows]
            style = "s--" if m.endswith("_multi") else "o-"
            ax.plot(x, [r["rate"] for r in rows], style, ms=3, color=COLORS[m], label=LABELS[m])
            ax.fill_between(x, [r["lo"] for r in rows], [r["hi"] for r in rows], color=COLORS[m], alpha=0.15, lw=0)
            inconclusive = [r["inconclusive"] / r["trials"] for r in rows]
            if any(inconclusive):  # where the trust mask withholds a verdict: the method's failure mode
                ax.plot(x, inconclusive, ":", lw=1.2, color=COLORS[m])
        ax.axhline(fixed_designs.TARGET, color="k", ls=":", lw=0.8)
        ax.axhline(ALPHA, color="k", ls="--", lw=0.6)
        first = [min((r for r in det_rows if r["case"] == c.name and r["method"] == m), key=lambda r: r["n"])
                 for m in METHODS if any(r["case"] == c.name and r["method"] == m for r in det_rows)]  # fmt: skip
        if all(r["rate"] >= 0.99 for r in first):
            ax.text(0.5, 0.5, f"every method: ≥ 99 % at the first point\n({first[0]['n']} passes a side)",
                    transform=ax.transAxes, ha="center", va="center", fontsize=9)  # fmt: skip
        ax.set_xscale("log")
        ax.set_ylim(-0.02, 1.02)
        ax.set_title(
            f"{c.label}\nmean change {100 * info['mean_change']:+.2f} % (± {100 * info['mean_change_se']:.2f})",
            fontsize=10,
        )
        ax.set_xlabel("render seconds, both sides (log)")
        ax.set_ylabel("share of trials: biased")
        ax.grid(alpha=0.3, which="both", lw=0.4)
    handles, labels = ax.get_legend_handles_labels()
    ax = fig.add_subplot(grid[2, :])
    _plot_false_positives(ax, fp_rows)
    handles.append(plt.Line2D([], [], ls=":", color="k"))
    labels.append("share `inconclusive` (same colour: same method)")
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=9, bbox_to_anchor=(0.5, 0.0))
    trials_note = f"{det_rows[0]['trials']} trials per point" if det_rows else ""
    fig.suptitle(
        f"Chart 1: detection rate against render time (α = {ALPHA}; bands: 95 % Wilson; {trials_note})", y=0.97
    )
    return save(fig, path)


def _plot_false_positives(ax, fp_rows) -> None:
    totals = _fp_totals(fp_rows)
    groups = list(dict.fromkeys(r["group"] for r in totals))
    width = 0.8 / len(PLOTTED)
    for j, m in enumerate(PLOTTED):  # the CSV has the paired test's other tile sizes too
        for i, g in enumerate(groups):
            r = next((r for r in totals if r["group"] == g and r["method"] == m), None)
            if r is None:
                continue
            x = i + (j - (len(PLOTTED) - 1) / 2) * width
            ax.errorbar(
                x,
                r["rate"],
                yerr=[[max(0.0, r["rate"] - r["lo"])], [max(0.0, r["hi"] - r["rate"])]],
                fmt="o",
                color=COLORS[m],
                ms=5,
                capsize=3,
            )
            ax.annotate(
                f"{r['trials']}", (x, r["hi"]), textcoords="offset points", xytext=(0, 3), ha="center", fontsize=6
            )
    ax.axhline(ALPHA, color="k", ls="--", lw=0.8, label=f"α = {ALPHA}")
    ax.set_xticks(range(len(groups)), [f"unbiased pairs: {g}" for g in groups])
    ax.set_ylabel("false-positive rate")
    ax.set_title("False positives on unbiased pairs (reference vs reference, disjoint seeds; paired: Sobol vs "
                 "blue noise, "
                 "same seeds), all n pooled; numbers: trials", fontsize=10)  # fmt: skip
    ax.grid(alpha=0.3, axis="y")
    ax.legend(loc="upper right", fontsize=8)


# -- its section of docs/benchmarks/README.md --------------------------------------------------------------------------


def section(f: dict) -> list[str]:
    """Chart 1's section of docs/benchmarks/README.md from the figures `f`."""
    c1, b = f["chart1"], f["budget"]
    parts = [CHART1.format(res=b["resolution"], passes=b["passes"], trials=b["trials"],
                           null=b["null_trials"], calib=b["calibration_trials"], alpha=ALPHA,
                           conv_spp=b["converged_spp"] * b["converged_passes"],
                           max_n=max(b["n_grid"]))]  # fmt: skip
    parts += chart1_lines(c1) + ["", "False positives on unbiased pairs (all n pooled):", ""] + fp_lines(c1)
    return parts + ["", *chart1_findings(c1, c1.get("detection"))]


CHART1 = """
## Chart 1: detection rate against render time

![chart 1](chart1_detection.png)

Pools of {passes} passes at {res}×{res} px, 1 spp. {trials} trials per point on biased pairs; {null} trials per
pass count on unbiased pairs for the tool's tests. Methods: the tool's `compare` at α = {alpha}: Welch at one tile
size each, 16², 32², 64² and 128² (the whole image), passed as `compare(..., tile=N)` since `compare` tests every
scale by default; Welch at every scale from 16² (compare's default: 16², 32², 64², 128² combined by Bonferroni);
the paired test on identical seeds likewise (the table shows its best tile size; every size is in the CSV); the
paper's Gaussian approximation where ν ≥ 20 at 32²; and two
baselines with thresholds calibrated to the same false-positive rate on {calib} unbiased trials per pass count
(half set the threshold, the other half measure its false-positive rate): the RMSE of the test's mean image
against a converged reference of {conv_spp} spp (its render time is counted on the x axis), and the largest
absolute tile-mean difference at 16² tiles (a thresholded tile-wise difference image). The calibration is free
for the baselines here (it comes from the pools); a user would have to pay for it, so the comparison favours
them. A curve stops once two pass counts in a row found every trial biased.

Render seconds (both sides) until 80 % of the trials say `biased` ("not reached": not within {max_n} passes a side):
"""


def chart1_lines(c1: dict) -> list[str]:
    summary = c1["summary"]
    cases = list(dict.fromkeys(r["case"] for r in summary))
    head = ("| case | mean change | Welch 16² | Welch 32² | Welch 64² | Welch 128² | Welch, every scale "
            "| Gaussian 32² | paired, best tile | paired, every scale | RMSE (with / without its reference) "
            "| tile difference |")  # fmt: skip
    lines = [head, "|" + "---|" * 12]
    sentences = []
    for case in cases:
        rows = {r["method"]: r for r in summary if r["case"] == case}
        first = next(iter(rows.values()))
        rmse = rows["rmse"]["seconds_to_80"]
        conv = first["converged_seconds"]
        without = None if rmse is None else max(rmse - conv, 0.0)
        pm, ps = _best(summary, case, FIXED_PAIRED)
        lines.append(
            f"| {first['label']} | {_pct(first['mean_change'], 2)} ± {_pct(first['mean_change_se'], 2)} | "
            + " | ".join(_cell(rows, m) for m in (*WELCH, "welch_multi", "gauss32"))
            + f" | {_s(ps)}{f' ({_tile(pm)})' if pm else ''} | {_cell(rows, 'paired_multi')}"
            + f" | {_s(rmse)} / {_s(without)} | {_s(rows['tilediff16']['seconds_to_80'])} |"
        )
        m, s = _best(summary, case, WELCH)
        if m is None:
            sentences.append(f"- **{first['label']}**: no Welch tile size reached 80 % detection within the pool.")
            continue
        text = f"- **{first['label']}**: the Welch test ({LABELS[m]}) reaches 80 % detection after {_s(s)} of rendering"
        multi = rows.get("welch_multi", {}).get("seconds_to_80")
        if multi is not None:
            text += f", at every scale from 16² after {_s(multi)} ({multi / s:.2f}× the best tile size's)"
        if rmse is not None:
            text += (f"; the RMSE baseline after {_s(rmse)} ({rmse / s:.0f}× more), of which {_s(conv)} is its "
                     f"converged reference (without it: {_s(without)})")  # fmt: skip
        else:
            text += f"; the RMSE baseline does not get there (its reference alone costs {_s(conv)})"
        if ps is not None:
            text += f"; the paired test on the same seeds after {_s(ps)} ({LABELS[pm]})"
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
    paired = [(_best(summary, c, FIXED_PAIRED)[1], c) for c in cases]
    paired = [(s, c) for s, c in paired if s is not None]
    if paired:
        out.append(
            "- **Paired test** (at its best tile size). With the same seeds on both sides the shared noise cancels: "
            + ", ".join(f"{cases[c]['label']} {_s(s)}" for s, c in paired)
            + ". For a pure scale change (light ×1.005) the difference of two passes with the same seed is exactly "
            "0.5 % of the pass, so two passes a side suffice; the paired test needs a renderer whose random numbers "
            "follow the seed, which Cycles' do."
        )
    for case in cases:
        peaks = []
        for m in ("welch16", "welch32", "welch_multi", "gauss32", "paired32"):
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
                f"tiles (64²: {_s(rows[(case, 'welch64')])} to 80 %), every scale at once (compare's default: "
                f"{_s(rows.get((case, 'welch_multi')))}) or more spp per pass are the remedy."
            )
    return out
