"""Chart 3: stability where the methods fail, on unbiased pairs (a configuration against itself, disjoint seeds).

For each situation: the false-positive (`biased`) rate over trials with its Wilson interval, the p-value histogram
of the tile-channels that entered the verdicts, and what the diagnostics said (share of `inconclusive`, share of
untrusted tiles, the notes). Expected: "calibrated" (rate not above alpha), or the tool flags the situation
(`inconclusive`, untrusted tiles, a note, or a refusal). A clearly raised rate without a flag is a defect of the
tool, printed as ``SILENT FALSE POSITIVES``.

Every situation's trials run `compare` twice on the same passes: at the situation's one tile size (``tile=``, as
before compare tested every scale) and at its default, every scale from that tile size up (Bonferroni over the
scales). Where it is cheap (disjoint seeds, the exact p, tiles of 16² or more) simulated runs of `check` at its
defaults with the situation's N as the budget and its tile as the finest (`checks`) give check's verdicts too.

Two rows are not the tool's own behaviour, to show what it guards against: the paper's Gaussian p used everywhere
(§5.7), and Welch's formula forced onto passes with identical seeds.
"""

from __future__ import annotations

import re
from collections import Counter
from pathlib import Path

import numpy as np

import welch_core as wc
from batch.present.summary import notes

from ..common import checks, plan, trials
from ..common.cache import digest, memo_json, welch_digest
from ..common.plotting import plt, save, write_csv
from ..common.pools import load_or_render, say
from ..common.trials import ALPHA
from ..common.words import p as _p
from ..common.words import pct as _pct
from ..common.words import rate as _rate

BINS = 20
FLAG_SHARE = 0.05


def _tally(outcomes: list[dict]) -> dict:
    """Aggregate per-trial outcomes into counts, shares, a p-value histogram and the notes."""
    total = len(outcomes)
    hist = np.zeros(BINS, int)
    notes = Counter()
    for o in outcomes:
        hist += o["hist"]
        notes.update(o["notes"])
    biased = sum(o["verdict"] == "biased" for o in outcomes)
    flagged_biased = sum(o["verdict"] == "biased" and bool(o["notes"] or o["untrusted"]) for o in outcomes)
    lo, hi = trials.wilson(biased, total)
    return {
        "trials": total,
        "biased": biased,
        "rate": biased / total,
        "lo": lo,
        "hi": hi,
        "inconclusive": sum(o["verdict"] == "inconclusive" for o in outcomes) / total,
        "refused": sum(o["verdict"] == "refused" for o in outcomes) / total,
        "untrusted_share": float(np.mean([o["untrusted"] / max(o["valid"], 1) for o in outcomes])),
        "uncovered_share": float(np.mean([o.get("uncovered", 0) / max(o["valid"], 1) for o in outcomes])),
        "biased_with_flag": flagged_biased,
        "median_p": float(np.median([o["p"] for o in outcomes])),
        "hist": hist.tolist(),
        "notes": dict(notes.most_common(4)),
    }


def _outcome(comparison: wc.Comparison) -> dict:
    p = comparison.pvalues[comparison.used]
    return {
        "verdict": comparison.verdict,
        "p": float(comparison.p_value),
        "hist": np.histogram(p, BINS, (0, 1))[0],
        "untrusted": int((np.isfinite(comparison.tile_pvalues) & ~comparison.trusted).sum()),
        "valid": comparison.n_valid,
        "uncovered": int(comparison.uncovered.sum()) if comparison.uncovered is not None else 0,
        # Numbers vary from trial to trial; the note's kind is what counts.
        "notes": [re.sub(r"\d+", "#", note) for note in notes(comparison)],
    }


def _by_hand(result: wc.TTestResult, pvalues: np.ndarray) -> dict:
    """A verdict from p-values welch_core does not produce itself: channels by Bonferroni, tiles by the global test."""
    glob = wc.global_test(wc.combine_channels(pvalues), ALPHA)
    finite = pvalues[np.isfinite(pvalues)]
    return {
        "verdict": "biased" if glob.rejected else "no_evidence",
        "p": float(glob.pvalue),
        "hist": np.histogram(finite, BINS, (0, 1))[0],
        "untrusted": 0,
        "valid": int(np.isfinite(result.pvalue).any(axis=-1).sum()),
        "notes": [],
    }


def compare_trials(
    rng, ref, test, n, tile, count, draw="unpaired", kind="auto", pvalue_method="exact", forced=None
) -> list[dict]:
    """`count` trials of `welch_core.compare` (or a forced variant) at n passes a side: ``{"single": outcome,
    "multi": outcome}`` each, the first at `tile` alone, the second at every scale from `tile` (compare's default;
    a forced variant has one outcome, used for both).

    `draw` chooses disjoint ("unpaired") or identical ("paired") seeds; `kind` is compare's `test_kind`.
    """
    drawer = trials.draw_paired if draw == "paired" else trials.draw_unpaired
    out = []
    for _ in range(count):
        draw_ = drawer(rng, ref.n, n)
        a, b = ref.stats(draw_.ref, tile), test.stats(draw_.test, tile)
        if forced == "gauss_everywhere":
            # The paper's p_inf for every tile-channel, even at small nu (§5.7, Fig. 22 b).
            r = wc.welch_from_stats(a.mean, a.variance, a.n, b.mean, b.variance, b.n)
            one = _by_hand(r, wc.pvalue_gauss(r.statistic))
            out.append({"single": one, "multi": one})
        elif forced == "welch_same_seeds":
            # Welch's formula on passes with the same seeds: what compare refuses to do.
            r = wc.welch_from_stats(a.mean, a.variance, a.n, b.mean, b.variance, b.n)
            one = _by_hand(r, r.pvalue)
            out.append({"single": one, "multi": one})
        else:
            try:
                single = wc.compare(a, b, ALPHA, test_kind=kind, pvalue_method=pvalue_method, tile=tile)
                multi = wc.compare(a, b, ALPHA, test_kind=kind, pvalue_method=pvalue_method)
                out.append({"single": _outcome(single), "multi": _outcome(multi)})
            except wc.SeedOverlapError as error:
                refused = {"verdict": "refused", "p": float("nan"), "hist": np.zeros(BINS, int), "untrusted": 0}
                refused |= {"valid": 0, "notes": [f"SeedOverlapError: {error}"]}
                out.append({"single": refused, "multi": refused})
    return out


def check_cheap(s: dict) -> bool:
    """Simulated `check` runs make sense and cost little: disjoint seeds, the exact p, tiles of 16² or more."""
    return not s["options"] and s["tile"] >= 16 and s["n"] >= 2


def check_tally(runs: list[dict]) -> dict:
    total = len(runs)
    k = {v: sum(r["verdict"] == v for r in runs) for v in ("biased", "equivalent", "inconclusive")}
    lo, hi = trials.wilson(k["biased"], total)
    return {"check_runs": total, "check_biased": k["biased"], "check_rate": k["biased"] / total, "check_lo": lo,
            "check_hi": hi, "check_equivalent": k["equivalent"] / total,
            "check_inconclusive": k["inconclusive"] / total}  # fmt: skip


def situations(b: plan.Budget) -> list[dict]:
    """Every situation: label, pools, n, tile, how trials are drawn, what is expected."""
    corner, glass = b.pool("corner"), plan.glass(b)
    _ref, blue = plan.paired_null(b)
    light = next(c for c in plan.cases(b) if c.name == "light")
    big, mid, few = (min(n, b.passes // 2) for n in (64, 32, 16))
    wide = min(64, b.resolution)
    out = []

    def add(label, ref, test, n, tile, expected, trials=b.stability_trials, **options):
        out.append({"label": label, "ref": ref, "test": test, "n": n, "tile": tile, "trials": trials,
                    "options": options, "expected": expected})  # fmt: skip

    calibrated, flagged, power = "calibrated", "calibrated or flagged", "power"
    add("corner (baseline), 32² tiles, N = 16", corner, corner, few, 32, calibrated)
    add("corner, 16² tiles, N = 64", corner, corner, big, 16, calibrated)
    add("corner + glass sphere (caustics, §5.1), 32² tiles, N = 32", glass, glass, mid, 32, flagged)
    add(f"corner + glass sphere, {wide}² tiles, N = 32", glass, glass, mid, wide, flagged)
    add("corner + glass sphere, 32² tiles, N = 64", glass, glass, big, 32, flagged)
    for n in (2, 3, 5):
        add(f"very few passes: N = {n}", corner, corner, n, 32, flagged)
    add("per-pixel tests (tile 1, §5.6), N = 16", corner, corner, few, 1, flagged, b.pixel_trials)
    add("per-pixel tests (tile 1), N = 64", corner, corner, big, 1, flagged, b.pixel_trials)
    add("Gaussian p where ν ≥ 20 (the tool's 'gauss'), N = 5", corner, corner, 5, 32, calibrated, pvalue_method="gauss")
    for n in (5, 10):
        add(f"Gaussian p everywhere (§5.7, by hand), N = {n}", corner, corner, n, 32, "not offered",
            forced="gauss_everywhere")  # fmt: skip
    add("blue noise against blue noise, N = 16", blue, blue, few, 32, calibrated)
    add("blue noise against Sobol (disjoint seeds), N = 16", corner, blue, few, 32, calibrated)
    add("unpaired test on identical seeds (A/A)", corner, corner, few, 32, "refused", draw="paired", kind="welch")
    add("Welch forced on identical seeds (A/A, by hand)", corner, corner, few, 32, "not offered", draw="paired",
        forced="welch_same_seeds")  # fmt: skip
    add("light ×1.005 (biased), identical seeds: Welch forced by hand", light.ref, light.test, few, 32, power,
        draw="paired", forced="welch_same_seeds")  # fmt: skip
    add("light ×1.005 (biased), identical seeds: paired test", light.ref, light.test, few, 32, power, draw="paired")
    add("light ×1.005 (biased), disjoint seeds: Welch", light.ref, light.test, few, 32, power)
    return out


def classify(row: dict) -> str:
    """Compare a situation's result with what is expected of it."""
    if row["expected"] == "power":
        return f"detected in {100 * row['rate']:.0f} %"
    if row["refused"] == 1.0:
        return "refused (SeedOverlapError)"
    if row["expected"] == "not offered":
        if row["lo"] > ALPHA:
            return "miscalibrated (why the tool does not do this)"
        return "never rejects (p-values not uniform)" if row["rate"] == 0 else "within alpha"
    # A few untrusted tiles are the normality check's own false alarms (it runs at 1e-4 per tile-channel); a flag
    # is what a user would notice: a note, or a sizeable share of untrusted tiles or inconclusive verdicts.
    flags = []
    if row["inconclusive"] >= FLAG_SHARE:
        flags.append(f"inconclusive {100 * row['inconclusive']:.0f} %")
    if row["untrusted_share"] >= FLAG_SHARE:
        flags.append(f"untrusted tiles {100 * row['untrusted_share']:.0f} %")
    if row.get("uncovered_share", 0) >= FLAG_SHARE:
        flags.append(f"tiles tested at no scale {100 * row['uncovered_share']:.0f} %")
    if any("unchecked" in note for note in row["notes"]):
        flags.append("note: normality unchecked")
    flag = f" ({'; '.join(flags)})" if flags else ""
    if row["lo"] <= ALPHA:
        return ("calibrated" if not flags else "calibrated, flagged") + flag
    if row["biased_with_flag"] == row["biased"]:
        return "false positives above alpha, every one flagged" + flag
    return "SILENT FALSE POSITIVES" + flag


def run(b: plan.Budget, cache_dir: Path, out_dir: Path) -> dict:
    plan_rows = situations(b)
    pools = {}
    for s in plan_rows:
        for spec in (s["ref"], s["test"]):
            if spec.key not in pools:
                pools[spec.key] = load_or_render(spec, cache_dir)
    rows = []
    for s in plan_rows:
        ref, test = pools[s["ref"].key], pools[s["test"].key]
        opt = dict(s["options"])
        key = digest(s["label"], ref.spec.key, test.spec.key, s["n"], s["tile"], s["trials"], opt,
                     welch_digest(), trials.TRIALS_VERSION, "single+multi")  # fmt: skip

        def compute(s=s, ref=ref, test=test, opt=opt, key=key):
            rng = np.random.default_rng(int(key[:8], 16))
            outcomes = compare_trials(rng, ref, test, s["n"], s["tile"], s["trials"], **opt)
            return {kind: _tally([o[kind] for o in outcomes]) for kind in ("single", "multi")}

        say(f"chart 3: {s['label']}")
        tallies = memo_json(cache_dir, "stability", key, compute)
        row = {"situation": s["label"], "n": s["n"], "tile": s["tile"], "expected": s["expected"], **tallies["single"]}
        row["outcome"] = classify(row)
        multi = tallies["multi"] | {"expected": s["expected"]}
        row |= {f"multi_{k}": v for k, v in multi.items() if k != "expected"}
        row["multi_outcome"] = classify(multi)
        if check_cheap(s):
            runs = checks.simulate(ref, test, False, b.stability_check_trials, cache_dir, max_passes=s["n"],
                                   tile=s["tile"])  # fmt: skip
            row |= check_tally(runs)
            row["check_outcome"] = _check_outcome(row)
        for name in ("outcome", "multi_outcome", "check_outcome"):
            if row.get(name, "").startswith("SILENT"):
                say(f"  WARNING: {row['situation']}: {name} {row[name]}")
        rows.append(row)
    csv_rows = [{k: (" ".join(map(str, v)) if k.endswith("hist") else " | ".join(v) if k.endswith("notes") else v)
                 for k, v in r.items()} for r in rows]  # fmt: skip
    files = [write_csv(out_dir / "chart3_stability.csv", csv_rows), _plot(out_dir / "chart3_stability.png", rows)]
    return {"files": files, "rows": rows}


def _check_outcome(row: dict) -> str:
    if row["expected"] == "power":
        return f"detected in {100 * row['check_rate']:.0f} %"
    flags = []
    if row["check_inconclusive"] >= FLAG_SHARE:
        flags.append(f"inconclusive {100 * row['check_inconclusive']:.0f} %")
    if row["check_lo"] <= ALPHA:
        return ("calibrated" if not flags else "calibrated, flagged") + (f" ({'; '.join(flags)})" if flags else "")
    return "SILENT FALSE POSITIVES" if not flags else "false positives above alpha, flagged"


def _plot(path: Path, rows: list[dict]) -> str:
    cols = 4
    nrows = -(-len(rows) // cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(20, 3.4 * nrows), squeeze=False)
    edges = np.linspace(0, 1, BINS + 1)
    for ax, r in zip(axes.ravel(), rows, strict=False):
        hist = np.asarray(r["hist"], float)
        if hist.sum():
            ax.bar(edges[:-1], hist / hist.sum() * BINS, width=1 / BINS, align="edge", color="#4c72b0")
        ax.axhline(1.0, color="k", ls="--", lw=0.7)
        ax.set_xlim(0, 1)
        rate = f"one tile: biased {r['biased']}/{r['trials']} [{100 * r['lo']:.1f}, {100 * r['hi']:.1f}] %"
        multi = f"all scales: {r['multi_biased']}/{r['trials']}, inconclusive {100 * r['multi_inconclusive']:.0f} %"
        check = ""
        if "check_runs" in r:
            check = (f"\ncheck: biased {r['check_biased']}/{r['check_runs']}, equivalent "
                     f"{100 * r['check_equivalent']:.0f} %, "
                     f"inconclusive {100 * r['check_inconclusive']:.0f} %")  # fmt: skip
        ax.set_title(f"{r['situation']}\n{rate}; {r['outcome']}\n{multi}; {r['multi_outcome']}{check}", fontsize=6.5)
        ax.tick_params(labelsize=7)
    for ax in axes.ravel()[len(rows) :]:
        ax.axis("off")
    fig.suptitle(
        f"Chart 3: stability on unbiased pairs (α = {ALPHA}): histograms of the tile-channel p-values that entered "
        "the verdicts (density; flat = uniform), false-positive rate [95 % Wilson], outcome",
        y=1.0,
    )
    fig.tight_layout()
    return save(fig, path)


# -- its section of docs/benchmarks/README.md --------------------------------------------------------------------------


def section(f: dict) -> list[str]:
    """Chart 3's section of docs/benchmarks/README.md from the figures `f`."""
    b = f["budget"]
    parts = [CHART3.format(trials=b["stability_trials"], pixel=b["pixel_trials"], alpha=ALPHA,
                           check=b.get("stability_check_trials", ""))]  # fmt: skip
    return parts + chart3_lines(f["chart3"]) + [""] + chart3_findings(f["chart3"])


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
