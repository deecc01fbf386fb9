"""docs/benchmarks/README.md, written from the figures of the last run (figures.json) so text and charts agree."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .trials import ALPHA, FIXED_PAIRED, FIXED_WELCH, LABELS

WELCH = FIXED_WELCH


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
    found = [(r["seconds_to_80"], methods.index(r["method"]), r["method"]) for r in summary
             if r["case"] == case and r["method"] in methods and r["seconds_to_80"] is not None]  # fmt: skip
    if not found:
        return None, None
    s, _order, m = min(found)  # a tie goes to the first of `methods` (the smallest tile)
    return m, s


def _cell(rows: dict, method: str) -> str:
    """Seconds to 80 % of a method, or '—' where it did not run (a tile larger than the image)."""
    return _s(rows[method]["seconds_to_80"]) if method in rows else "—"


def _tile(method: str) -> str:
    return {"16": "16²", "32": "32²", "64": "64²", "128": "128²"}.get("".join(filter(str.isdigit, method)), method)


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


def _rate(r: dict, prefix: str = "") -> str:
    return f"{_pct(r[prefix + 'rate'])} [{_pct(r[prefix + 'lo'])}, {_pct(r[prefix + 'hi'])}]"


def chart3_findings(c3: dict) -> list[str]:
    rows = c3["rows"]
    outcomes = [(r, key) for r in rows for key in ("outcome", "multi_outcome", "check_outcome") if key in r]
    silent = [(r, key) for r, key in outcomes if r[key].startswith("SILENT")]
    wrong = [r for r in rows if r["outcome"].startswith("miscalibrated")]
    out = []
    names = {"outcome": "one tile size", "multi_outcome": "every scale", "check_outcome": "check"}
    if silent:
        out.append("- **Silent false positives (a defect of the tool, to be fixed):** " + "; ".join(
            f"{r['situation']} ({names[key]}): {r[key]}" for r, key in silent) + ".")  # fmt: skip
    else:
        out.append("- No situation produced silent false positives, at one tile size, at every scale or with `check`: "
                   f"every `biased` rate on unbiased pairs is compatible with α = {_pct(ALPHA, 0)} or below it, or "
                   "flagged.")  # fmt: skip
    changed = []
    for r in rows:
        if r["expected"] in ("not offered", "refused"):
            continue
        d_inc = r["multi_inconclusive"] - r["inconclusive"]
        if abs(d_inc) >= 0.05 or r["multi_biased"] != r["biased"] and r["expected"] == "power":
            text = (
                f"{r['situation']}: `inconclusive` {_pct(r['inconclusive'], 0)} → "
                f"{_pct(r['multi_inconclusive'], 0)}, `biased` {_pct(r['rate'])} → {_pct(r['multi_rate'])}"
            )
            changed.append(text)
    if changed:
        out.append("- **What every scale at once changed** (one tile size → every scale from it, same passes): "
                   + "; ".join(changed) + ". Elsewhere the verdicts are those of the one tile size within a few "
                   "trials.")  # fmt: skip
    checked = [r for r in rows if "check_runs" in r and r["expected"] != "power"]
    if checked:
        worst = max(checked, key=lambda r: r["check_rate"])
        out.append(
            f"- **`check` in these situations** (its defaults, the situation's N as the budget, its tile as the "
            f"finest, {checked[0]['check_runs']} runs each): `biased` in at most {_pct(worst['check_rate'])} "
            f"({worst['situation']}); "
            + "; ".join(
                f"{r['situation']}: `equivalent` {_pct(r['check_equivalent'], 0)}, `inconclusive` "
                f"{_pct(r['check_inconclusive'], 0)}"
                for r in checked
            )  # fmt: skip
            + ". A budget of a few passes rarely suffices to bound every tile within 1 %: those runs end "
            "`inconclusive`, which is the flag."
        )
    for r in wrong:
        out.append(f"- {r['situation']}: `biased` {_rate(r)}, above α: this is why welch_core applies the Gaussian "
                   "only where ν ≥ 20.")  # fmt: skip
    power = [r for r in rows if r["expected"] == "power"]
    if power:
        detected = "; ".join(
            f"{r['situation']}: detected {_pct(r['rate'], 0)} (every scale {_pct(r['multi_rate'], 0)}), median p "
            f"{_p(r['median_p'])}"
            for r in power
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
        "| situation | trials | one tile: `biased` [95 %] | one tile: `inconclusive` | every scale: `biased` [95 %] "
        "| every scale: `inconclusive` | untrusted tiles | tested at no scale | `check`: `biased` / `equivalent` / "
        "`inconclusive` | outcome: one tile → every scale → check |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in c3["rows"]:
        check = "—"
        if "check_runs" in r:
            check = (f"{r['check_biased']} of {r['check_runs']} / {_pct(r['check_equivalent'], 0)} / "
                     f"{_pct(r['check_inconclusive'], 0)}")  # fmt: skip
        outcome = r["outcome"]
        if r["multi_outcome"] != r["outcome"]:
            outcome += f" → {r['multi_outcome']}"
        if "check_outcome" in r:
            outcome += f" → check: {r['check_outcome']}"
        lines.append(
            f"| {r['situation']} | {r['trials']} | {_rate(r)} | {_pct(r['inconclusive'], 0)} | {_rate(r, 'multi_')} | "
            f"{_pct(r['multi_inconclusive'], 0)} | {_pct(r['multi_untrusted_share'])} | "
            f"{_pct(r['multi_uncovered_share'])} | {check} | {outcome} |"
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


def _x(x) -> str:
    return "—" if x is None else f"{x:.2f}×"


def _n(x) -> str:
    return "—" if x is None else f"{x:.0f}"


MODE_NAMES = {"paired": "paired", "unpaired": "unpaired"}


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


def _tg(t) -> str:
    if t is None:
        return "∞"
    return f"{t:.3g}" if t < 1000 else f"{t:.2g}"


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
            why.append(f"{_pct(g['equivalent_share'], 0)} of the runs end `equivalent`: the bias{size} is inside the "
                       "1 % tolerance at some scale, the answer the defaults ask for; with the equivalence verdict off "
                       f"the median is {_x(noeq['biased_median_ratio'])}")  # fmt: skip
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
                f" The tightest bound at the stop (median ±{_pct(c['equivalent_median_bound'], 2)}) was at the "
                f"{c['equivalent_tile']}² scale in {_pct(c['equivalent_tile_share'], 0)} of those runs "
                "(`equivalent` holds once some scale bounds every one of its tiles within the tolerance)."
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
        out.append(
            f"- **{r['label']}**: {_pct(r['inconclusive_share'], 0)} of the runs spend the budget of "
            f"{r['max_passes']} passes a side and end `inconclusive`; they rule out a bias beyond "
            f"±{_pct(r['inconclusive_median_ruled_out'] or float('nan'), 2)} (median) at the {r['inconclusive_tile']}² "
            "scale, but not ±1 %: at 1 spp its noise needs more passes for a 1 % bound than the pool holds"
            + (f" (tiles tested at no scale at the end: median {_n(r['inconclusive_uncovered_median'])})"
               if r["inconclusive_uncovered_median"] else ", with every tile testable at some scale")
            + "."
        )  # fmt: skip
    return out


def chart7_lines(c7: dict) -> list[str]:
    lines = [
        "| case | Welch 16² | 32² | 64² | 128² | every scale | best tile | every scale / best tile |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in c7["cases"]:
        cells = " | ".join("—" if r[f"{m}_s"] is None else _s(r[f"{m}_s"]) for m in (*WELCH, "welch_multi"))
        best = _tile(r["best_fixed_method"]) if r["best_fixed_method"] else "—"
        lines.append(f"| {r['label']} | {cells} | {best} | {_x(r['multi_over_best'])} |")
    glass = c7["glass"]
    tiles = list(dict.fromkeys(r["tile"] for r in glass))
    lines += ["", "Glass sphere A/A, share of trials ending `inconclusive` (and `biased`):", "",
              "| passes a side | " + " | ".join("every scale" if t == "multi" else f"{t}² alone" for t in tiles)
              + " | every scale: trials with tiles tested at no scale | whole image untrusted |",
              "|---|" + "---|" * (len(tiles) + 2)]  # fmt: skip
    for n in dict.fromkeys(r["n"] for r in glass):
        cells = []
        for t in tiles:
            r = next(x for x in glass if x["n"] == n and x["tile"] == t)
            cells.append(f"{_pct(r['inconclusive_share'], 0)} ({_pct(r['biased_share'], 1)})")
        m = next(x for x in glass if x["n"] == n and x["tile"] == "multi")
        lines.append(f"| {n} | " + " | ".join(cells) + f" | {m['uncovered_trials']} of {m['trials']} | "
                     f"{m['coarsest_untrusted']} of {m['trials']} |")  # fmt: skip
    return lines


def chart7_findings(c7: dict) -> list[str]:
    out = []
    ratios = [(r["multi_over_best"], r) for r in c7["cases"] if r["multi_over_best"] is not None]
    if ratios:
        worst = max(ratios, key=lambda x: x[0])
        out.append(
            "- **Every scale against the best tile size in hindsight**: "
            + ", ".join(f"{r['case']} {_x(x)}" for x, r in ratios)
            + f" (worst: {worst[1]['label']}). The Bonferroni factor of 4 scales costs little, and nobody has to "
            "know the best tile size in advance: it differs from case to case ("
            + ", ".join(f"{r['case']} {_tile(r['best_fixed_method'])}" for _x_, r in ratios)
            + ")."
        )  # fmt: skip
    t = c7.get("local_tiles")
    if t:
        out.append(
            f"- **Local bias** ({c7['local_label']}): the largest change of a tile mean is "
            + ", ".join(f"{_pct(v['largest'], 1)} at {k}²" for k, v in t.items())
            + f"; {t['16']['tiles_over_1pct']} of {t['16']['tiles']} tiles of 16² change by more than 1 %."
        )
    glass = c7["glass"]
    if glass:
        multi = [r for r in glass if r["tile"] == "multi"]
        fine = [r for r in glass if r["tile"] in ("16", "32")]
        out.append(
            "- **Glass sphere A/A**: at 16² or 32² alone "
            + _fine_share(fine)
            + " of the trials end `inconclusive` (the caustic tiles' Welch samples are clearly not normal and they are "
            "more than a quarter of the image); at every "
            f"scale {_pct(min(r['inconclusive_share'] for r in multi), 0)}–"
            f"{_pct(max(r['inconclusive_share'] for r in multi), 0)}"
            + (". The remaining ones are trials where even the whole image's Welch samples are flagged (a caustic "
               "firefly in a pass; column 'whole image untrusted'): no tile size is too small there, the image is."
               if all(r["inconclusive"] <= r["coarsest_untrusted"] for r in multi) else
               ", some of them with the whole image trusted (column 'whole image untrusted').")
        )  # fmt: skip
    ex = c7.get("example")
    if ex:
        out.append(
            f"- **One such trial** (n = {ex['n']}, right of the chart): {ex['uncovered']} of {ex['tiles']} tiles of "
            f"16² can be tested at no scale; the verdict is `{ex['verdict']}` (p {_p(ex['p_value'])}) for the rest. "
            "The report says: " + " / ".join(f"“{n}”" for n in ex["notes"]) + ". Per scale, tiles used: "
            + ", ".join(f"{s['tile']}²: {s['used']} of {s['tiles']}" for s in ex["scales"]) + "."
        )  # fmt: skip
    return out


def _fine_share(rows: list[dict]) -> str:
    """'99–100 % from 16 passes a side on (0 % at 8)': the inconclusive share of one tile size alone."""
    high = [r for r in rows if r["inconclusive_share"] >= 0.95]
    if not high:
        return f"at most {_pct(max(r['inconclusive_share'] for r in rows), 0)}"
    start = min(r["n"] for r in high)
    later = [r["inconclusive_share"] for r in rows if r["n"] >= start]
    text = f"{_pct(min(later), 0)}–{_pct(max(later), 0)} from {start} passes a side on"
    earlier = sorted({r["n"] for r in rows if r["n"] < start})
    if earlier:
        shares = [f"{_pct(max(r['inconclusive_share'] for r in rows if r['n'] == n), 0)} at {n}" for n in earlier]
        text += f" (at most {', '.join(shares)})"
    return text


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
                         f"{glass6['max_passes']} passes a side (it rules out ±"
                         f"{_pct(glass6['inconclusive_median_ruled_out'] or float('nan'), 2)})")  # fmt: skip
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
    for chart, note in sorted(f.get("notes", {}).items()):
        parts.append(f"Chart {chart}: {note}\n")
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
        parts.append(CHART3.format(trials=b["stability_trials"], pixel=b["pixel_trials"], alpha=ALPHA,
                                   check=b.get("stability_check_trials", "")))  # fmt: skip
        parts += chart3_lines(f["chart3"]) + [""] + chart3_findings(f["chart3"])
    if "chart4" in f:
        parts.append(CHART4)
        parts += chart4_lines(f["chart4"])
    if "chart5" in f:
        c5 = f["chart5"]
        parts.append(CHART5.format(runs=c5["runs"], passes=b["passes"], half=b["passes"] // 2))
        parts += chart5_lines(c5) + ["", "Per case and test, the goal (median time to `biased` at most 1.25× the best "
                                     "fixed design's):", ""] + chart5_findings(c5)  # fmt: skip
        parts += ["", BOUNDARIES, ""] + chart5_boundary_lines(c5)
    if "chart6" in f:
        parts.append(CHART6)
        parts += chart6_lines(f["chart6"]) + [""] + chart6_findings(f["chart6"])
    if "chart7" in f:
        parts.append(CHART7.format(trials=b.get("scale_trials"), local=f["chart7"].get("local_label", "")))
        parts += chart7_lines(f["chart7"]) + [""] + chart7_findings(f["chart7"])
    goals = goal_lines(f)
    if goals:
        parts += [GOALS] + goals
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

Each trial runs `compare` twice on the same passes: at the situation's tile size alone (`tile=`, what compare did
before it tested every scale) and at its default, every scale from that tile size up to the image, combined by
Bonferroni. "Untrusted tiles" and "tested at no scale" are the shares of the finest tiles of the latter whose Welch
samples are clearly not normal, and that no scale can test (`Comparison.uncovered`). Where it is cheap (disjoint
seeds, the exact p, tiles of 16² or more) {check} simulated runs of `check` at its defaults (tolerance 1 %) with
the situation's N as the budget and its tile size as the finest give check's verdicts.
"""

CHART4 = """
## Chart 4: how the cost grows

![chart 4](chart4_cost.png)
"""

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

CHART6 = """
## Chart 6: A/A runs of `check`

![chart 6](chart6_aa.png)

`check` at its defaults (as in chart 5) on unbiased pairs: a configuration against itself with disjoint seeds
(`check --unpaired`), and one paired pair (Sobol against blue noise on the same seeds: two sampling patterns of
one scene, unbiased). The budget is the pool. The design promises `biased` in at most α of the runs, however many
looks they take.
"""

CHART7 = """
## Chart 7: every scale at once against each fixed tile size

![chart 7](chart7_scales.png)

Seconds to 80 % detection of Welch's test at one tile size (`compare(..., tile=N)`) and at every scale from 16²
(compare's default), from chart 1's trials and, for a local bias, from the same trials on a new pool: {local}.
Then the glass sphere's A/A (`corner_glass` against itself, disjoint seeds; the caustic failure case of the paper,
§5.1), {trials} trials per pass count, each compared at every tile size alone and at every scale.
"""

GOALS = """
## The goals of issue 11, measured
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
