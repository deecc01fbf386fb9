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
        "top_tiles": top_tiles(c),
        "notes": notes(c),
        "reference": {"name": ref_name, "n": ref.n, "seeds": format_seeds(ref.seeds), "info": ref.info.to_json()},
        "test_run": {"name": test_name, "n": test.n, "seeds": format_seeds(test.seeds), "info": test.info.to_json()},
        "differences": differences(ref.info, test.info),
        "reference_selftest": reference_selftest(ref, c.alpha) if selftest else None,
        "dropped_pixels": ref.dropped_pixels,
    }
    summary["warnings"] = warnings(summary)
    return summary


def method_sentence(c: wc.Comparison) -> str:
    name = "paired t-test on per-pass differences" if c.test == "paired" else "Welch's t-test"
    return (
        f"{name} per {c.tile}x{c.tile} tile and channel (p: {c.pvalue_method}); channels combined by "
        "Bonferroni; tiles by Holm and a one-sided Kolmogorov-Smirnov test of uniformity, Bonferroni-combined"
    )


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
            f"all {valid} testable tiles have clearly non-normal Welch samples (fireflies or caustics) and are left "
            "out: use larger tiles, more samples per pass or more passes"
        )
    elif untrusted:
        out.append(
            f"{untrusted} of {valid} tiles have clearly non-normal Welch samples and are left out of the verdict"
        )
        if c.verdict == wc.Verdict.INCONCLUSIVE:
            out.append("too much of the image has non-normal Welch samples: use larger tiles or more spp per pass")
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
    check = wc.compare(*wc.split_halves(ref), alpha=alpha, test_kind="welch")
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


def verdict_line(summary: dict[str, Any]) -> str:
    """One line for the terminal: the verdict, alpha, the global p and the test."""
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
    lines += [f"note: {note}" for note in summary["notes"]]
    lines += [f"warning: {warning}" for warning in summary["warnings"]]
    return lines


def _num(x) -> float | None:
    """JSON has no NaN: None stands for 'not defined'."""
    x = float(x)
    return x if np.isfinite(x) else None
