"""What people read about a comparison, made in one place for the report, the command line and the add-on.

`summarize` turns a `welch_core.Comparison` (statistics only) and its two runs into a JSON-ready dict: the
verdict, the method in a sentence, tile counts, the most significant tiles with their effect sizes, the notes,
what differs between the runs and the reference tested against itself (paper §6). Every reader of a comparison
shows the same words because they all read this dict.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import fmt
from ._siblings import welch_core as wc
from .seeds import format_seeds

#: How many of the most significant tiles a summary lists.
TOP_TILES = 10

#: Identity fields of a run listed among the differences, in this order (settings and overrides follow).
_INFO_FIELDS = ("renderer", "renderer_version", "build_hash", "device", "sampling_pattern", "scene", "spp")


def summarize(
    comparison: wc.Comparison,
    ref: wc.TileStats,
    test: wc.TileStats,
    ref_name: str = "reference",
    test_name: str = "test",
    selftest: bool = True,
) -> dict[str, Any]:
    """The JSON-ready summary of `comparison` (the content of report.json, without its file list).

    With `selftest`, the reference's two halves are compared too (see `reference_selftest`).
    """
    c = comparison
    finite = np.isfinite(c.effect.min_detectable) & (c.reasons == wc.Reason.VALID)
    summary = {
        "verdict": c.verdict.label,
        "verdict_text": c.verdict.text,
        "alpha": c.alpha,
        "p_value": _num(c.p_value),
        "test": c.test,
        "method": method_sentence(c),
        "pvalue_method": c.pvalue_method,
        "components": {
            "holm_min_pvalue": _num(c.global_test.holm_pvalue),
            "uniformity_pvalue": _num(c.global_test.uniformity_pvalue),
        },
        "n_ref": c.n_ref,
        "n_test": c.n_test,
        "grid": {
            "width": c.width,
            "height": c.height,
            "tile": c.tile,
            "tiles_x": int(c.tile_pvalues.shape[1]),
            "tiles_y": int(c.tile_pvalues.shape[0]),
        },
        "tiles": {
            "total": int(c.tile_pvalues.size),
            "valid": c.n_valid,
            "used": int(c.used.sum()),
            "untrusted": c.n_untrusted,
            "significant": int(c.significant.sum()),
        },
        "tile_channels": c.reason_counts,
        "median_min_detectable_rel_bias": _num(np.median(c.effect.min_detectable[finite])) if finite.any() else None,
        "scales": [scale_summary(scale) for scale in c.scales],
        "equivalence": equivalence_summary(c.equivalence),
        "uncovered_tiles": int(c.uncovered.sum()) if c.uncovered is not None else 0,
        "top_tiles": top_tiles(c),
        "notes": notes(c),
        "reference": {"name": ref_name, "n": ref.n, "seeds": format_seeds(ref.seeds), "info": ref.info.to_json()},
        "test_run": {"name": test_name, "n": test.n, "seeds": format_seeds(test.seeds), "info": test.info.to_json()},
        "differences": differences(ref.info, test.info),
        "reference_selftest": reference_selftest(ref, c.alpha) if selftest else None,
        "dropped_pixels": ref.dropped_pixels,
    }
    summary["warnings"] = warnings(summary)
    summary["uncovered_region"] = _region(c.uncovered, c.tile) if c.uncovered is not None else None
    summary["next_step"] = next_step(summary)
    return summary


def _region(mask: np.ndarray, tile: int) -> dict[str, int] | None:
    """The pixel box around the tiles of `mask` (x, y, width, height), or None if there are none."""
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return None
    return {
        "x": int(cols.min() * tile),
        "y": int(rows.min() * tile),
        "width": int((cols.max() - cols.min() + 1) * tile),
        "height": int((rows.max() - rows.min() + 1) * tile),
    }


def next_step(summary: dict[str, Any]) -> str:
    """What to do with this verdict, in a sentence or two."""
    verdict = wc.Verdict(summary["verdict"])
    n_ref, n_test = summary["n_ref"], summary["n_test"]
    more = (
        f"render more passes into both runs (the same render commands with --resume and seeds after the "
        f"{n_ref} and {n_test} used), then compare again, or let `python -m batch check` render until it decides"
    )
    if verdict == wc.Verdict.BIASED:
        top = summary["top_tiles"][0] if summary["top_tiles"] else None
        where = (
            f" The strongest difference is at x {top['x']}, y {top['y']} ({top['size']} px tile), "
            f"{fmt.percent(top['rel_diff'])} in {top['channel']}."
            if top
            else ""
        )
        return (
            "The two do not converge to the same image." + where + " Look at the recorded differences and the tiles "
            "outlined in the map; a difference you expected (a setting changed on purpose) confirms the test works."
        )
    if verdict == wc.Verdict.EQUIVALENT:
        return "Nothing to do: the difference is bounded within the tolerance in every tested tile."
    if verdict == wc.Verdict.INCONCLUSIVE:
        region = summary.get("uncovered_region")
        if summary["tiles"]["valid"] == 0:
            return "No tile could be tested (too few passes, or constant images): " + more + "."
        if region:
            x, y = region["x"], region["y"]
            where = f"the region x {x}..{x + region['width']}, y {y}..{y + region['height']}"
        else:
            where = "too much of the image"
        return (
            f"The Welch samples of {where} are clearly not normal (fireflies or caustics) at every tile size, so "
            f"that part can't be tested yet: more samples per pass (--spp) make each pass's tile sums more normal; "
            f"or {more}."
        )
    detectable = summary["median_min_detectable_rel_bias"]
    smaller = (
        f"a bias below {fmt.percent(detectable).lstrip('+')} per tile" if detectable is not None else "a small bias"
    )
    return (
        f"No bias was found, but {smaller} could still hide: to rule it out, {more}; with --tolerance the verdict "
        "says whether the two are equivalent within it."
    )


def method_sentence(c: wc.Comparison) -> str:
    name = "paired t-test on per-pass differences" if c.test == "paired" else "Welch's t-test"
    sizes = ", ".join(str(scale.tile) for scale in c.scales or (c,))
    text = (
        f"{name} per tile and channel (p: {c.pvalue_method}) at tile sizes {sizes}; channels combined by "
        "Bonferroni; the tiles of a scale by Holm and a one-sided Kolmogorov-Smirnov test of uniformity, "
        "Bonferroni-combined; the scales by Bonferroni"
    )
    if c.equivalence is not None:
        text += (
            f"; equivalence: simultaneous {1 - c.alpha:.0%} intervals of the relative difference (Bonferroni over "
            f"tile-channels and scales) inside ±{fmt.percent(c.equivalence.tolerance).lstrip('+')}"
        )
    return text


def scale_summary(scale: wc.Comparison) -> dict[str, Any]:
    """One tile scale: its size, global p-value and tile counts."""
    return {
        "tile": scale.tile,
        "tiles": int(scale.tile_pvalues.size),
        "p_value": _num(scale.p_value),
        "used": int(scale.used.sum()),
        "untrusted": scale.n_untrusted,
        "significant": int(scale.significant.sum()),
    }


def equivalence_summary(eq: wc.Equivalence | None) -> dict[str, Any] | None:
    """The tolerance, the finest tile size at which every tile is bounded within it, and the bounds per scale."""
    if eq is None:
        return None
    best = eq.best
    return {
        "tolerance": eq.tolerance,
        "equivalent": eq.equivalent,
        "tile": eq.tile,
        "beyond": eq.beyond,
        "ruled_out": {str(tile): _num(bound) for tile, bound in eq.ruled_out.items()},
        "best": None if best is None else {"tile": best[0], "ruled_out": best[1]},
    }


def equivalence_sentence(summary: dict[str, Any]) -> str | None:
    """'... within ±1.00 % in every 64x64 tile' or '... a bias beyond 1.80 % is ruled out in every 128x128 tile'."""
    eq = summary.get("equivalence")
    if eq is None:
        return None
    tolerance = fmt.percent(eq["tolerance"]).lstrip("+")
    if eq["equivalent"]:
        tile = eq["tile"]
        return f"the test converges to the reference within ±{tolerance} in every {tile}x{tile} tile" + finer_clause(
            summary, tile
        )
    if eq.get("beyond"):
        return f"not equivalent within ±{tolerance}: a tile found biased differs by more than that"
    if eq["best"] is None:
        return f"not shown within ±{tolerance}: no tile size bounds the difference in every tile"
    tile, bound = eq["best"]["tile"], eq["best"]["ruled_out"]
    return (
        f"not shown within ±{tolerance}: a bias beyond {fmt.percent(bound).lstrip('+')} is ruled out in every "
        f"{tile}x{tile} tile"
    )


def finer_clause(summary: dict[str, Any], tile: int) -> str:
    """What `equivalent` at `tile` does not say about the finest tiles: the bias their intervals leave open
    (a local bias in a small tile can hide in a larger tile's mean)."""
    eq, finest = summary.get("equivalence"), summary["grid"]["tile"]
    if eq is None or tile == finest:
        return ""
    bound = eq["ruled_out"].get(str(finest))
    open_ = "any bias" if bound is None else f"a bias up to {fmt.percent(bound).lstrip('+')}"
    return f"; in {finest}x{finest} tiles {open_} is not ruled out"


def layers_summary(
    combined: wc.Comparison,
    ref: wc.TileStats,
    test: wc.TileStats,
    ref_layers: dict[str, wc.TileStats],
    test_layers: dict[str, wc.TileStats],
) -> tuple[dict[str, Any], dict[str, wc.Comparison]] | None:
    """Every layer both runs have (light components, light groups) tested as the image is, which components
    explain a difference of the image, and the check that the components add up to the image in each run; with
    the layers' comparisons (for the report's maps). None when the runs have no layer in common."""
    from .lobes import COMPONENT_SUM_TOLERANCE, COMPONENTS

    names = [name for name in ref_layers if name in test_layers]
    if not names:
        return None
    rows, comparisons = [], {}
    for name in names:
        if not (np.any(ref_layers[name].sums) or np.any(test_layers[name].sums)):
            rows.append({"name": name, "verdict": "empty", "verdict_text": "no light in either run", "p_value": None,
                         "significant_tiles": 0, "share": 0.0, "largest": None})  # fmt: skip
            continue
        c = wc.compare(ref_layers[name], test_layers[name], combined.alpha, combined.test, combined.pvalue_method)
        comparisons[name] = c
        rows.append({
            "name": name,
            "verdict": c.verdict.label,
            "verdict_text": c.verdict.text,
            "p_value": _num(c.p_value),
            "significant_tiles": sum(int(s.significant.sum()) for s in c.scales),
            "share": _num(float(ref_layers[name].sums.sum() / ref.sums.sum())) if ref.sums.sum() else None,
            "largest": _largest_effect(c),
        })  # fmt: skip
    biased = [r["name"] for r in rows if r["verdict"] == wc.Verdict.BIASED and r["name"] in COMPONENTS]
    sums = {}
    for side, run, layers in (("reference", ref, ref_layers), ("test", test, test_layers)):
        if all(name in layers for name in COMPONENTS):
            error = lobes_sum_error(run, layers)
            sums[side] = {"relative_error": error, "ok": error <= COMPONENT_SUM_TOLERANCE}
        else:
            sums[side] = None
    if combined.verdict != wc.Verdict.BIASED:
        explanation = None
    elif biased:
        explanation = f"the difference is in {', '.join(biased)}"
    else:
        explanation = "no single component is biased on its own: the difference is spread over several"
    return {"layers": rows, "explained_by": biased, "explanation": explanation, "component_sum": sums}, comparisons


def lobes_sum_error(run: wc.TileStats, layers: dict[str, wc.TileStats]) -> float:
    from .lobes import COMPONENTS, component_sum_error

    return component_sum_error(run.sums, [layers[name].sums for name in COMPONENTS])


def _largest_effect(c: wc.Comparison) -> dict[str, Any] | None:
    """The difference of the most significant tile-channel, at the tile size that tested it best (a layer's
    difference is often clearest in larger tiles than the image's)."""
    scales = [s for s in c.scales if (s.used[..., None] & (s.reasons == wc.Reason.VALID)).any()]
    if not scales:
        return None
    s = min(scales, key=lambda scale: np.nan_to_num(scale.p_value, nan=2.0))
    tested = s.used[..., None] & (s.reasons == wc.Reason.VALID)
    p = np.where(tested, s.pvalues, np.inf)
    row, col, ch = np.unravel_index(int(np.argmin(p)), p.shape)
    c = s
    return {
        "size": int(c.tile),
        "x": int(col * c.tile),
        "y": int(row * c.tile),
        "channel": "RGB"[ch] if c.pvalues.shape[-1] == 3 else int(ch),
        "rel_diff": _num(c.effect.rel_diff[row, col, ch]),
        "ci_low": _num(c.effect.ci_low[row, col, ch]),
        "ci_high": _num(c.effect.ci_high[row, col, ch]),
    }


def top_tiles(c: wc.Comparison, count: int = TOP_TILES) -> list[dict[str, Any]]:
    """The most significant tiles with their effect sizes (the channel with the smallest p)."""
    flat = np.where(np.isfinite(c.tile_pvalues), c.tile_pvalues, np.inf).ravel()
    order = np.argsort(flat, kind="stable")[: min(count, c.n_valid)]
    names = "RGB" if c.pvalues.shape[-1] == 3 else None
    tiles = []
    for index in order:
        row, col = np.unravel_index(index, c.tile_pvalues.shape)
        ch = int(np.nanargmin(c.pvalues[row, col]))
        tiles.append(
            {
                "row": int(row),
                "col": int(col),
                "x": int(col * c.tile),
                "y": int(row * c.tile),
                "size": c.tile,
                "pvalue": _num(c.tile_pvalues[row, col]),
                "adjusted_pvalue": _num(c.global_test.adjusted[row, col]),
                "qvalue": _num(c.qvalues[row, col]),
                "significant": bool(c.significant[row, col]),
                "trusted": bool(c.trusted[row, col]),
                "channel": names[ch] if names else ch,
                "rel_diff": _num(c.effect.rel_diff[row, col, ch]),
                "ci_low": _num(c.effect.ci_low[row, col, ch]),
                "ci_high": _num(c.effect.ci_high[row, col, ch]),
                "min_detectable": _num(c.effect.min_detectable[row, col, ch]),
            }
        )
    return tiles


def notes(c: wc.Comparison) -> list[str]:
    """What a reader must know to trust the verdict: unchecked normality, tiles left out and why."""
    out = []
    valid, untrusted = c.n_valid, c.n_untrusted
    if not c.normality_checked:
        out.append(
            f"fewer than {wc.diagnostics.MIN_PASSES_FOR_NORMALITY} passes a side: the normality of the Welch samples "
            "is unchecked"
        )
    if c.n_deterministic:
        out.append(
            f"{c.n_deterministic} tile-channels are constant on both sides but differ: a deterministic difference"
        )
    if valid == 0:
        out.append(
            "no tile can be tested: every tile-channel has too few passes, zero variance on both sides or non-finite "
            "values (see the counts per reason)"
        )
    elif untrusted == valid:
        out.append(
            f"all {valid} testable {c.tile}x{c.tile} tiles have clearly non-normal Welch samples "
            "(fireflies or caustics)"
        )
    elif untrusted:
        out.append(f"{untrusted} of {valid} {c.tile}x{c.tile} tiles have clearly non-normal Welch samples")
    if c.uncovered is not None and c.uncovered.any():
        out.append(
            f"{int(c.uncovered.sum())} {c.tile}x{c.tile} tiles can be tested at no tile size (their Welch samples "
            "stay non-normal): the verdict covers the rest of the image"
        )
        if c.verdict == wc.Verdict.INCONCLUSIVE:
            out.append("too much of the image can't be tested: render more samples per pass or more passes")
    elif untrusted and len(c.scales) > 1:
        out.append("their regions are tested at a larger tile size")
    return out


def differences(ref: wc.RunInfo, test: wc.RunInfo) -> list[str]:
    """What differs between what produced the two runs: renderer, build, device, settings, overrides."""
    lines = []
    for name in _INFO_FIELDS:
        a, b = getattr(ref, name), getattr(test, name)
        if a != b:
            lines.append(f"{name}: {a!r} -> {b!r}")
    for key in sorted(set(ref.settings) | set(test.settings)):
        a, b = ref.settings.get(key), test.settings.get(key)
        if a != b:
            lines.append(f"{key}: {a!r} -> {b!r}")
    if ref.overrides != test.overrides:
        lines.append(f"overrides: {list(ref.overrides)} -> {list(test.overrides)}")
    return lines


def reference_selftest(ref: wc.TileStats, alpha: float) -> dict[str, Any] | None:
    """The paper's advice (§6): test the reference against itself first. Its two halves (alternate passes),
    compared; None when the reference has fewer than 4 passes."""
    if ref.n < 4:
        return None
    # The stored tile size only: the finest tiles are where a miscalibration shows first, at half the cost.
    check = wc.compare(*wc.split_halves(ref), alpha=alpha, test_kind="welch", tile=ref.tile)
    return {
        "verdict": check.verdict.label,
        "p_value": _num(check.p_value),
        "n_ref": check.n_ref,
        "n_test": check.n_test,
        "notes": notes(check),
    }


def warnings(summary: dict[str, Any]) -> list[str]:
    """Reasons to doubt the verdict that are not about the test itself."""
    out = []
    selftest = summary.get("reference_selftest")
    if selftest is not None and selftest["verdict"] != wc.Verdict.NO_EVIDENCE:
        out.append(
            f"the reference against itself (two halves) is {wc.Verdict(selftest['verdict']).text}: trust this with care"
        )
    return out


def check_summary(comparison, ref, test, look, verdict, job, looks: list[dict], max_passes: int) -> dict[str, Any]:
    """The summary of a `check`: the comparison of the final data (maps, tiles, effects) under the verdict of the
    sequential design (whose budget was `max_passes` a side), with the design and every look. The fixed-sample
    global p-value is left out: after looks it is not a valid p-value."""
    summary = summarize(comparison, ref, test, "reference", "test")
    summary.update(
        verdict=verdict.label,
        verdict_text=verdict.text,
        p_value=None,
        check={
            "max_passes": max_passes,
            "max_seconds": job.max_seconds,
            "tolerance": job.tolerance,
            "paired": job.paired,
            "spending": "pocock",
            "passes": look.passes,
            "looks": looks,
            "stopped": "decided" if look.verdict is not None else "budget spent",
            "ruled_out": _num(look.ruled_out),
            "ruled_out_tile": look.ruled_out_tile,
        },
    )
    summary["warnings"] = warnings(summary)
    return summary


def verdict_line(summary: dict[str, Any]) -> str:
    """One line for the terminal: the verdict, alpha, the global p and the test."""
    check = summary.get("check")
    if check is not None:
        looks = check["looks"]
        seconds = looks[-1]["seconds"] if looks else 0.0
        return (
            f"verdict: {summary['verdict_text']} (alpha {summary['alpha']:g}, {summary['test']} test, after "
            f"{len(looks)} looks at {check['passes']} passes a side, {fmt.duration(seconds)} of rendering)"
        )
    return (
        f"verdict: {summary['verdict_text']} (alpha {summary['alpha']:g}, global p {fmt.p_is(summary['p_value'])}, "
        f"{summary['test']} test, {summary['tiles']['used']} of {summary['tiles']['total']} tiles used, "
        f"n = {summary['n_ref']} vs {summary['n_test']})"
    )


def console_lines(summary: dict[str, Any]) -> list[str]:
    """The lines the command line prints under the verdict."""
    lines = []
    detectable = summary["median_min_detectable_rel_bias"]
    if summary["verdict"] == wc.Verdict.NO_EVIDENCE and detectable is not None:
        lines.append(
            f"a tile with a bias of {detectable:.1%} (median over tiles) would have been found with 80 % power"
        )
    check = summary.get("check")
    if check is not None and check["stopped"] == "budget spent":
        bound = check["ruled_out"]
        lines.append(
            "the budget is spent before a decision: "
            + (
                f"a bias beyond {fmt.percent(bound).lstrip('+')} is ruled out in every {check['ruled_out_tile']}x"
                f"{check['ruled_out_tile']} tile; render more passes (--max-passes) to decide"
                if bound is not None
                else "no tile size bounds the difference yet; render more passes (--max-passes) to decide"
            )
        )
    if check is not None and summary["verdict"] == wc.Verdict.EQUIVALENT:
        tile, bound = check["ruled_out_tile"], check["ruled_out"]
        lines.append(
            f"the test converges to the reference within ±{fmt.percent(check['tolerance']).lstrip('+')} in every "
            f"{tile}x{tile} tile (a bias beyond {fmt.percent(bound).lstrip('+')} is ruled out)"
            + finer_clause(summary, tile)
        )
    equivalence = equivalence_sentence(summary) if check is None else None
    if equivalence is not None:
        lines.append(equivalence)
    lines += [f"note: {note}" for note in summary["notes"]]
    lines += [f"warning: {warning}" for warning in summary["warnings"]]
    lines += layer_lines(summary.get("layers"))
    return lines


def layer_lines(layers: dict[str, Any] | None) -> list[str]:
    """A line per light component or light group, and what they say together."""
    if not layers:
        return []
    lines = []
    for row in layers["layers"]:
        if row["verdict"] == "empty":
            lines.append(f"layer {row['name']}: {row['verdict_text']}")
            continue
        largest = row["largest"]
        effect = f", largest difference {fmt.percent(largest['rel_diff'])}" if largest else ""
        lines.append(f"layer {row['name']}: {row['verdict_text']} (p {fmt.p_is(row['p_value'])}{effect})")
    if layers["explanation"]:
        lines.append(layers["explanation"])
    for side, check in layers["component_sum"].items():
        if check is not None and not check["ok"]:
            lines.append(
                f"warning: the {side}'s components do not add up to its image (relative difference "
                f"{check['relative_error']:.2g}): a component is missing or counted twice"
            )
    return lines


def _num(x) -> float | None:
    """JSON has no NaN: None stands for 'not defined'."""
    x = float(x)
    return x if np.isfinite(x) else None
