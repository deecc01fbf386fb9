"""Chart 7: every tile scale at once (compare's default) against each fixed tile size.

Three parts:

1. Seconds to 80 % detection of Welch's test at one tile size (16², 32², 64², 128² = the whole image) and at every
   scale from 16² (Bonferroni over the four scales), on chart 1's bias cases (chart 1's trials) and on a local
   bias: the glossy scene's metal sphere with its red 0.90 -> 0.85 (`plan.local_case`; a new pool).
2. The glass sphere's A/A (corner_glass against itself, disjoint seeds; the caustic failure case of the paper, §5.1):
   the share of trials that end `inconclusive` at one tile size against every scale, per pass count.
3. One such A/A trial in which part of the image can be tested at no scale (`Comparison.uncovered`), drawn as the
   report draws it (the finest tested tile size per tile, the uncovered tiles marked), with its verdict and notes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import welch_core as wc
from batch.present.summary import notes

from ..common import fixed_designs, plan, trials
from ..common.cache import digest, memo_json, welch_digest
from ..common.plotting import COLORS, plt, save, write_csv
from ..common.pools import load_or_render, say
from ..common.trials import ALPHA, BASE_TILE, FIXED_WELCH, LABELS
from ..common.words import WELCH
from ..common.words import fine_share as _fine_share
from ..common.words import p as _p
from ..common.words import pct as _pct
from ..common.words import s as _s
from ..common.words import tile as _tile
from ..common.words import x as _x

SCALE_METHODS = (*FIXED_WELCH, "welch_multi")
SCALES_VERSION = 1


def glass_results(b: plan.Budget, cache_dir: Path) -> dict:
    """A/A trials on the glass sphere: verdict counts per pass count and tile size (None: every scale), the
    uncovered tiles of the multi-scale verdicts, and the draw of one trial with some, but not too many, uncovered
    tiles (the example)."""
    pool = load_or_render(plan.glass(b), cache_dir)
    sizes = [t for t in (16, 32, 64, 128) if t <= b.resolution]

    def compute():
        rng = np.random.default_rng(int(key[:8], 16))
        rows, example = [], None
        for n in b.scale_n:
            if 2 * n > pool.n:
                continue
            counts = {str(t): {"biased": 0, "no_evidence": 0, "inconclusive": 0, "equivalent": 0}
                      for t in [*sizes, "multi"]}  # fmt: skip
            uncovered, whole_untrusted = [], 0
            for _ in range(b.scale_trials):
                draw = trials.draw_unpaired(rng, pool.n, n)
                a, c = pool.stats(draw.ref, BASE_TILE), pool.stats(draw.test, BASE_TILE)
                for t in sizes:
                    counts[str(t)][wc.compare(a, c, ALPHA, test_kind="welch", tile=t).verdict.label] += 1
                multi = wc.compare(a, c, ALPHA, test_kind="welch")
                counts["multi"][multi.verdict.label] += 1
                share = float(multi.uncovered.sum() / multi.uncovered.size)
                uncovered.append(share)
                whole_untrusted += int(not multi.scales[-1].used.all())
                if example is None and multi.uncovered.any() and multi.verdict != "inconclusive":
                    example = {"n": n, "ref": draw.ref.tolist(), "test": draw.test.tolist()}
            rows.append({"n": n, "trials": b.scale_trials, "counts": counts,
                         "uncovered_trials": int(sum(u > 0 for u in uncovered)),
                         "uncovered_mean_share": float(np.mean(uncovered)),
                         "coarsest_untrusted": whole_untrusted})  # fmt: skip
            say(f"  glass A/A n = {n}: " + ", ".join(f"{t} {v['inconclusive']}" for t, v in counts.items()))
        return {"rows": rows, "example": example}

    key = digest("glass-scales", pool.spec.key, b.scale_n, b.scale_trials, sizes, welch_digest(),
                 SCALES_VERSION)  # fmt: skip
    say("chart 7: glass sphere A/A at every tile size")
    return memo_json(cache_dir, "glass-scales", key, compute) | {"pool": pool}


def example(glass: dict) -> dict | None:
    """The example trial again: its comparison, the finest tested tile size per 16² tile, the notes."""
    ex = glass["example"]
    if ex is None:
        return None
    pool = glass["pool"]
    a, c = pool.stats(np.array(ex["ref"]), BASE_TILE), pool.stats(np.array(ex["test"]), BASE_TILE)
    comparison = wc.compare(a, c, ALPHA, test_kind="welch")
    sizes, _p = comparison.region_scales()
    mean = np.asarray(pool.images[np.array(ex["ref"])], dtype=np.float64).mean(axis=0)
    relevant = ~(comparison.reasons == wc.Reason.ZERO_VARIANCE).all(axis=-1)
    return {"n": ex["n"], "verdict": comparison.verdict.label, "p_value": float(comparison.p_value),
            "uncovered": int(comparison.uncovered.sum()), "relevant": int(relevant.sum()),
            "tiles": int(comparison.uncovered.size), "notes": notes(comparison),
            "scales": [{"tile": s.tile, "used": int(s.used.sum()), "tiles": int(s.used.size), "p": float(s.p_value)}
                       for s in comparison.scales],
            "sizes": sizes.tolist(), "uncovered_mask": comparison.uncovered.tolist(), "mean": mean}  # fmt: skip


def run(b: plan.Budget, cache_dir: Path, out_dir: Path) -> dict:
    found = fixed_designs.compute(b, cache_dir)
    local = fixed_designs.local_results(b, cache_dir)
    summary = [*found["summary"], *local["summary"]]
    cases = [*found["cases"], local["case"]]
    per_case = []
    for case in cases:
        rows = {r["method"]: r for r in summary if r["case"] == case.name}
        best = fixed_designs.best_fixed(summary, case.name, FIXED_WELCH)
        multi = rows.get("welch_multi", {}).get("seconds_to_80")
        per_case.append({"case": case.name, "label": case.label,
                         **{f"{m}_s": rows[m]["seconds_to_80"] if m in rows else None for m in SCALE_METHODS},
                         "best_fixed_method": best["method"] if best else None,
                         "best_fixed_s": best["seconds_to_80"] if best else None,
                         "multi_over_best": multi / best["seconds_to_80"] if multi and best else None})  # fmt: skip
    glass = glass_results(b, cache_dir)
    glass_rows = []
    for row in glass["rows"]:
        for tile, counts in row["counts"].items():
            total = sum(counts.values())
            glass_rows.append({"n": row["n"], "tile": tile, "trials": total, **counts,
                               "inconclusive_share": counts["inconclusive"] / total,
                               "biased_share": counts["biased"] / total,
                               "uncovered_trials": row["uncovered_trials"] if tile == "multi" else None,
                               "coarsest_untrusted": row["coarsest_untrusted"] if tile == "multi" else None,
                               })  # fmt: skip
    shown = example(glass)
    local_rows = local["rows"]
    files = [
        write_csv(out_dir / "chart7_scales.csv", per_case),
        write_csv(out_dir / "chart7_local_detection.csv", local_rows),
        write_csv(out_dir / "chart7_glass_aa.csv", glass_rows),
        _plot(out_dir / "chart7_scales.png", cases, per_case, local_rows, glass_rows, shown),
    ]
    if shown is not None:
        shown = {k: v for k, v in shown.items() if k not in ("mean", "sizes", "uncovered_mask")}
    return {"files": files, "cases": per_case, "glass": glass_rows, "example": shown, "local_tiles": local["tiles"],
            "local_label": local["case"].label, "local_summary": local["summary"]}  # fmt: skip


def _plot(path: Path, cases, per_case, local_rows, glass_rows, shown) -> str:
    fig = plt.figure(figsize=(17, 11))
    grid = fig.add_gridspec(2, 3, hspace=0.38, wspace=0.28)
    ax = fig.add_subplot(grid[0, :2])
    width = 0.8 / len(SCALE_METHODS)
    for j, m in enumerate(SCALE_METHODS):
        xs, ys = [], []
        for i, r in enumerate(per_case):
            if r[f"{m}_s"] is not None:
                xs.append(i + (j - (len(SCALE_METHODS) - 1) / 2) * width)
                ys.append(r[f"{m}_s"])
        if xs:
            ax.bar(xs, ys, width, color=COLORS[m], label=LABELS[m], edgecolor="k" if m == "welch_multi" else None)
    ax.set_yscale("log")
    ax.set_xticks(range(len(per_case)), [r["label"] for r in per_case], fontsize=8, rotation=10)
    ax.set_ylabel("render seconds to 80 % detection (log)")
    ax.set_title("Welch's test at one tile size against every scale (no bar: not reached within the pool)",
                 fontsize=10)  # fmt: skip
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y", which="both", lw=0.4)

    ax = fig.add_subplot(grid[0, 2])
    for m in SCALE_METHODS:
        rows = sorted((r for r in local_rows if r["method"] == m), key=lambda r: r["n"])
        if rows:
            ax.plot([r["seconds"] for r in rows], [r["rate"] for r in rows], "s--" if m == "welch_multi" else "o-",
                    ms=3, color=COLORS[m], label=LABELS[m])  # fmt: skip
    ax.axhline(0.8, color="k", ls=":", lw=0.8)
    ax.set_xscale("log")
    ax.set_title(f"local bias: {cases[-1].label}", fontsize=9)
    ax.set_xlabel("render seconds, both sides (log)")
    ax.set_ylabel("share of trials: biased")
    ax.grid(alpha=0.3, which="both", lw=0.4)
    ax.legend(fontsize=7)

    ax = fig.add_subplot(grid[1, :2])
    tiles = list(dict.fromkeys(r["tile"] for r in glass_rows))
    for tile in tiles:
        rows = [r for r in glass_rows if r["tile"] == tile]
        name = "welch_multi" if tile == "multi" else f"welch{tile}"
        ax.plot([r["n"] for r in rows], [r["inconclusive_share"] for r in rows], "s--" if tile == "multi" else "o-",
                color=COLORS[name], label=LABELS[name])  # fmt: skip
        ax.plot([r["n"] for r in rows], [r["biased_share"] for r in rows], ":", color=COLORS[name], lw=1)
    ax.axhline(ALPHA, color="k", ls="--", lw=0.6)
    ax.set_xscale("log")
    ax.set_xlabel("passes a side (log)")
    ax.set_ylabel("share of A/A trials")
    ax.set_title("Glass sphere A/A (caustics, §5.1): share `inconclusive` (solid) and `biased` (dotted)", fontsize=10)
    ax.grid(alpha=0.3, which="both", lw=0.4)
    ax.legend(fontsize=8)

    ax = fig.add_subplot(grid[1, 2])
    if shown is None:
        ax.text(0.5, 0.5, "no A/A trial with uncovered tiles\nand a verdict", ha="center", va="center")
        ax.axis("off")
    else:
        mean = shown["mean"]
        ax.imshow(np.clip((mean / (mean.mean() * 4)) ** (1 / 2.2), 0, 1), interpolation="nearest")
        sizes = np.array(shown["sizes"])
        uncovered = np.array(shown["uncovered_mask"])
        t = mean.shape[0] // sizes.shape[0]
        for (row, col), size in np.ndenumerate(sizes):
            if uncovered[row, col]:
                ax.add_patch(plt.Rectangle((col * t - 0.5, row * t - 0.5), t, t, fill=True, alpha=0.45,
                                           facecolor="red", edgecolor="red", hatch="xx"))  # fmt: skip
            elif size:
                ax.text(col * t + t / 2, row * t + t / 2, str(size), ha="center", va="center", fontsize=6,
                        color="white")  # fmt: skip
        ax.set_title(f"one glass A/A at n = {shown['n']}: {shown['verdict']}, {shown['uncovered']} of "
                     f"{shown['tiles']} 16² tiles tested at no scale (red)\nnumbers: finest tile size that tests the "
                     "tile", fontsize=8)  # fmt: skip
        ax.axis("off")
    fig.suptitle("Chart 7: multi-scale tiles against fixed tile sizes (α = 0.01)")
    return save(fig, path)


# -- its section of docs/benchmarks/README.md --------------------------------------------------------------------------


def section(f: dict) -> list[str]:
    """Chart 7's section of docs/benchmarks/README.md from the figures `f`."""
    b = f["budget"]
    parts = [CHART7.format(trials=b.get("scale_trials"), local=f["chart7"].get("local_label", ""))]
    return parts + chart7_lines(f["chart7"]) + [""] + chart7_findings(f["chart7"])


CHART7 = """
## Chart 7: every scale at once against each fixed tile size

![chart 7](chart7_scales.png)

Seconds to 80 % detection of Welch's test at one tile size (`compare(..., tile=N)`) and at every scale from 16²
(compare's default), from chart 1's trials and, for a local bias, from the same trials on a new pool: {local}.
Then the glass sphere's A/A (`corner_glass` against itself, disjoint seeds; the caustic failure case of the paper,
§5.1), {trials} trials per pass count, each compared at every tile size alone and at every scale.
"""


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
