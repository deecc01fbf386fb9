"""What people read about a comparison, as one JSON-ready dict: report.json, and what every presenter reads.

`summarize` puts a comparison's `welch_core.Outcome` (the verdict and every number about it, decided once in
welch_core) into words (`batch.words`) beside the per-tile statistics the map draws: tile counts, the most
significant tiles (pointwise intervals, labelled as such), the notes, what differs between the runs, the sides by
what differs, and the reference tested against itself (paper §6). Nothing here decides a verdict.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._siblings import welch_core as wc
from ..jobs import samples
from ..jobs.seeds import format_seeds
from . import fmt, words

#: How many of the most significant tiles a summary lists.
TOP_TILES = 10

#: Identity fields of a run listed among the differences, in this order (settings and overrides follow).
_INFO_FIELDS = ("renderer", "renderer_version", "build_hash", "device", "sampling_pattern", "scene", "spp")

#: Settings that change only the noise of a render, never the image it converges to (when the renderer is
#: right): a difference in them that the test finds is a bug of the renderer, not of the comparison.
NOISE_ONLY = {
    "sampling_pattern",
    "device",
    "cycles.sampling_pattern",
    "cycles.scrambling_distance",
    "cycles.auto_scrambling_distance",
    "cycles.use_light_tree",
    "cycles.light_sampling_threshold",
    "cycles.use_guiding",
    "cycles.min_light_bounces",
    "cycles.min_transparent_bounces",
    "cycles.use_animated_seed",
}


def summarize(
    comparison: wc.Comparison,
    ref: wc.TileStats,
    test: wc.TileStats,
    ref_name: str | None = None,
    test_name: str | None = None,
    selftest: wc.Comparison | None = None,
    outcome: wc.Outcome | None = None,
    check: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The JSON-ready summary of `comparison` (the content of report.json, without its file list).

    `outcome` is the verdict to present (default: the comparison's own; a check passes its last look's, and
    `check` the design and its looks). Sides without a name are named by what differs between them. `selftest`
    is the reference tested against itself (`welch_core.selftest`), where it was."""
    c = comparison
    outcome = outcome or c.outcome
    data = outcome.to_json()
    significant = outcome.significant
    names = side_names(ref.info, test.info, ref_name, test_name)
    image, noise = differences(ref.info, test.info)
    fixed = fixed_notes(ref.info, test.info)
    sampled = sample_notes(ref.info, test.info, outcome.identical)
    hidden = fixed[1] + sampled[1]
    pixels = c.pixel_use.to_json() if c.pixel_use is not None else None
    summary = {
        "verdict": data["verdict"],
        "verdict_text": data["verdict_text"],
        "sentence": words.sentence(data),
        "alpha": outcome.alpha,
        "p_value": data["p_value"],
        "test": outcome.test,
        "method": words.method(data, c.pvalue_method, check, pixels),
        "pixel_variance": pixels,
        "pvalue_method": c.pvalue_method,
        "outcome": data,
        "n_ref": outcome.n_ref,
        "n_test": outcome.n_test,
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
            "significant": int(significant.sum()),
        },
        "tile_channels": c.reason_counts,
        "top_tiles": top_tiles(c, outcome),
        "notes": notes(c, outcome) + fixed[0] + sampled[0] + check_notes(check),
        "reference": {"name": names[0], "n": ref.n, "seeds": format_seeds(ref.seeds), "info": ref.info.to_json()},
        "test_run": {"name": names[1], "n": test.n, "seeds": format_seeds(test.seeds), "info": test.info.to_json()},
        "differences": image,
        "noise_differences": noise,
        "hidden_differences": hidden,
        "reference_selftest": selftest_summary(selftest),
        "dropped_pixels": ref.dropped_pixels,
        "check": check,
    }
    summary["warnings"] = warnings(summary)
    summary["next_step"] = words.next_step(data, check=check is not None, hidden=hidden)
    return summary


def side_names(ref: wc.RunInfo, test: wc.RunInfo, ref_name: str | None, test_name: str | None) -> tuple[str, str]:
    """Names of the two sides by what differs between them: the build, the scene, the overrides, the sampling
    pattern; the given names where they are given."""
    if ref.renderer_version != test.renderer_version or ref.build_hash != test.build_hash:
        derived = (_build(ref), _build(test))
    elif ref.scene != test.scene:
        derived = (ref.scene or "reference", test.scene or "test")
    elif ref.overrides != test.overrides:
        derived = (
            "; ".join(ref.overrides) if ref.overrides else "the scene as it is",
            "; ".join(test.overrides) if test.overrides else "the scene as it is",
        )
    elif ref.sampling_pattern != test.sampling_pattern:
        derived = (ref.sampling_pattern, test.sampling_pattern)
    else:
        derived = ("reference", "test")
    return ref_name or derived[0], test_name or derived[1]


def _build(info: wc.RunInfo) -> str:
    version = f"{info.renderer} {info.renderer_version}".strip() or "unknown build"
    return f"{version} ({info.build_hash})" if info.build_hash and info.build_hash != "Unknown" else version


def top_tiles(c: wc.Comparison, outcome: wc.Outcome | None = None, count: int = TOP_TILES) -> list[dict[str, Any]]:
    """The finest tiles with the smallest p-values, with their effect sizes (the channel with the smallest p) and
    pointwise (1 - alpha) intervals, led by the tile that decided a `biased` verdict where it is a larger one.

    One meaning of significant, the verdict's (`outcome`, default the comparison's own): `significant` says the
    family of `biased` found the tile itself, `within` names the size of a larger tile found around it (the map
    outlines both); `adjusted_pvalue` is the tile's p adjusted over that family (Holm within a size, Bonferroni over
    the sizes, both sides of the interval: what a fixed design compares with alpha); `trusted` says which have
    normal-looking Welch samples (an untrusted tile's p is not used)."""
    outcome = outcome or c.outcome
    found = outcome.found or (c.significant,)
    flat = np.where(np.isfinite(c.tile_pvalues), c.tile_pvalues, np.inf).ravel()
    order = np.argsort(flat, kind="stable")[: min(count, c.n_valid)]
    names = "RGB" if c.pvalues.shape[-1] == 3 else None
    tiles = [] if (decided := _deciding_tile(c, outcome)) is None else [decided]
    for index in order:
        row, col = np.unravel_index(index, c.tile_pvalues.shape)
        ch = int(np.nanargmin(c.pvalues[row, col]))
        x, y, w, h = _box(c, row, col)
        tiles.append(
            {
                "row": int(row),
                "col": int(col),
                "x": x,
                "y": y,
                "width": w,
                "height": h,
                "size": c.tile,
                "pvalue": _num(c.tile_pvalues[row, col]),
                "adjusted_pvalue": _num(c.adjusted_pvalues[row, col]),
                "qvalue": _num(c.qvalues[row, col]),
                "significant": bool(found[0][row, col]),
                "within": None if found[0][row, col] else _within(c, found, x, y),
                "decided": False,
                "trusted": bool(c.trusted[row, col]),
                "channel": names[ch] if names else ch,
                "rel_diff": _num(c.effect.rel_diff[row, col, ch]),
                "ci_low": _num(c.effect.ci_low[row, col, ch]),
                "ci_high": _num(c.effect.ci_high[row, col, ch]),
                "interval": f"pointwise {1 - c.alpha:.0%}",
                "min_detectable": _num(c.effect.min_detectable[row, col, ch]),
            }
        )
    return tiles


def _within(c: wc.Comparison, found, x: int, y: int) -> int | None:
    """The smallest larger tile size whose tile around pixel (x, y) the verdict found significant, or None."""
    for scale, mask in zip(c.scales[1:], found[1:], strict=False):
        row, col = y // scale.tile, x // scale.tile
        if row < mask.shape[0] and col < mask.shape[1] and mask[row, col]:
            return scale.tile
    return None


def _deciding_tile(c: wc.Comparison, outcome: wc.Outcome) -> dict[str, Any] | None:
    """The row of the tile that decided `biased` where it is larger than the finest (the finest ones are listed
    anyway): its interval is the simultaneous one the verdict states."""
    top = outcome.most_significant
    if outcome.verdict != wc.Verdict.BIASED or top is None or top.tile is None or top.tile == c.tile:
        return None
    return {
        "row": top.y // c.tile,
        "col": top.x // c.tile,
        "x": top.x,
        "y": top.y,
        "width": top.width,
        "height": top.height,
        "size": top.tile,
        "pvalue": top.p_value,
        "adjusted_pvalue": None,
        "qvalue": None,
        "significant": True,
        "within": None,
        "decided": True,
        "trusted": top.trusted,
        "channel": top.channel,
        "rel_diff": top.estimate,
        "ci_low": top.low,
        "ci_high": top.high,
        "interval": f"simultaneous {top.confidence:.0%}",
        "min_detectable": None,
    }


def _box(c: wc.Comparison, row: int, col: int) -> tuple[int, int, int, int]:
    x, y = int(col) * c.tile, int(row) * c.tile
    return x, y, min(c.tile, c.width - x), min(c.tile, c.height - y)


def notes(c: wc.Comparison, outcome: wc.Outcome | None = None) -> list[str]:
    """What a reader must know to trust the verdict: unchecked normality, tiles left out and why."""
    outcome = outcome or c.outcome
    out = []
    valid, untrusted = c.n_valid, c.n_untrusted
    if not outcome.normality_checked:
        out.append(
            f"fewer than {wc.diagnostics.MIN_PASSES_FOR_NORMALITY} passes a side: the normality of the Welch samples "
            "is unchecked"
        )
    if outcome.tolerance is not None and min(outcome.n_ref, outcome.n_test) < outcome.identical_needed:
        out.append(
            f"`equivalent` needs {outcome.identical_needed} passes a side, which rule out that a change altering one "
            "pass in ten went unseen: no tile is bounded before"
        )
    if outcome.deterministic:
        out.append(f"{words.deterministic(outcome.deterministic, outcome.test)}: a deterministic difference")
    if valid == 0 and not outcome.identical:
        out.append(
            "no tile can be tested: every tile-channel has too few passes, zero variance on both sides or non-finite "
            "values (see the counts per reason)"
        )
    elif untrusted == valid and valid:
        out.append(
            f"all {valid} testable {c.tile}x{c.tile} tiles have clearly non-normal Welch samples "
            + ("(fireflies, caustics, or differences that are mostly exact zeros)" if outcome.scales[0].sparse else
               "(fireflies or caustics)")
        )  # fmt: skip
    elif untrusted:
        out.append(f"{untrusted} of {valid} {c.tile}x{c.tile} tiles have clearly non-normal Welch samples")
    sparse = [f"{s.sparse} of {s.tiles} at {s.tile}x{s.tile}" for s in outcome.scales if s.sparse]
    if sparse:
        out.append(
            "tiles whose per-pass differences are mostly exact zeros (a change that alters a few light paths, not "
            f"fireflies): {', '.join(sparse)}"
        )
    unpaired = [f"{s.unpaired} of {s.tiles} at {s.tile}x{s.tile}" for s in outcome.scales if s.unpaired]
    if unpaired:
        out.append(
            "tiles whose per-pass differences are far from normal while each side's are not were tested by Welch's "
            "test on the two sides instead "
            f"({', '.join(unpaired)}; conservative, the shared seeds correlate the sides)"
        )
    if outcome.untestable:
        out.append(
            f"{outcome.untestable} {c.tile}x{c.tile} tiles can be tested at no tile size (their Welch samples "
            f"stay non-normal): `biased` speaks for the rest of the image"
        )
    elif untrusted and len(c.scales) > 1:
        out.append("their regions are tested at a larger tile size")
    out += words.resampling_notes(outcome.to_json())
    short = min(outcome.n_ref, outcome.n_test) < outcome.identical_needed
    if c.reason_counts.get("zero_variance") and not outcome.identical and short:
        out.append(
            f"{c.reason_counts['zero_variance']} tile-channels are the same on both sides in every pass: bounded at "
            f"0 once {outcome.identical_needed} passes are"
        )
    return out


def _setting_value(value) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    if value is None:
        return "unset"
    if isinstance(value, list | tuple):
        return "(" + ", ".join(_setting_value(v) for v in value) + ")"
    return str(value)


def _setting_name(key: str) -> str:
    return key.split(".", 1)[1] if key.startswith(("cycles.", "render.")) else key


def differences(ref: wc.RunInfo, test: wc.RunInfo) -> tuple[list[str], list[str]]:
    """What differs between what produced the two runs, as a person writes it ("max_bounces: 12 → 2"): those
    that may change the converged image, and those that change only the noise (`NOISE_ONLY`)."""
    image, noise = [], []
    for name in _INFO_FIELDS:
        a, b = getattr(ref, name), getattr(test, name)
        if a != b:
            (noise if name in NOISE_ONLY else image).append(f"{name}: {_setting_value(a)} → {_setting_value(b)}")
    for key in sorted(set(ref.settings) | set(test.settings)):
        a, b = ref.settings.get(key), test.settings.get(key)
        if a != b and not (key == "cycles.sampling_pattern" and ref.sampling_pattern != test.sampling_pattern):
            a, b = (
                _setting_value(v) if key in run.settings else "not in this build" for v, run in ((a, ref), (b, test))
            )
            (noise if key in NOISE_ONLY else image).append(f"{_setting_name(key)}: {a} → {b}")
    if ref.overrides != test.overrides:
        for side, overrides in (("reference", ref.overrides), ("test", test.overrides)):
            if overrides:
                image.append(f"overrides of the {side} side: {'; '.join(overrides)}")
    return image, noise


#: Fixed settings a note leaves out: the view layers' own samples only matter where a layer sets them.
_QUIET_FIXED = ("cycles.use_layer_samples",)


def fixed_notes(ref: wc.RunInfo, test: wc.RunInfo) -> tuple[list[str], list[str]]:
    """What the passes replaced of the scene files' own settings (`RunInfo.fixed`), as notes, and the settings in
    which the two files differ but the passes do not ("samples: 4096 → 2 in the files, 1 in the passes"): a
    difference the test cannot see. Built-in scenes are the tool's own: nothing of theirs is reported."""

    def replaced(info: wc.RunInfo) -> str:
        if info.scene_id.startswith("builtin:"):
            return ""
        return ", ".join(
            f"{_setting_name(key)} {_setting_value(a)} → {_setting_value(b)}"
            for key, (a, b) in sorted(info.fixed.items())
            if a != b and key not in _QUIET_FIXED
        )

    out = []
    mine, theirs = replaced(ref), replaced(test)
    if mine and mine == theirs:
        out.append(f"the passes replace settings of both scenes: {mine}")
    else:
        out += [f"the passes replace settings of the {side} scene: {text}"
                for side, text in (("reference", mine), ("test", theirs)) if text]  # fmt: skip
    hidden = []
    for key in sorted(set(ref.fixed) & set(test.fixed)):
        (a, rendered), (b, other) = ref.fixed[key], test.fixed[key]
        if a != b and rendered == other and key not in _QUIET_FIXED:
            hidden.append(
                f"{_setting_name(key)}: {_setting_value(a)} → {_setting_value(b)} in the files, "
                f"{_setting_value(rendered)} in the passes"
            )
    if hidden:
        out.append(f"the scene files differ in settings the passes replace on both sides, so the test cannot see "
                   f"them: {'; '.join(hidden)}")  # fmt: skip
    return out, hidden


def _file_samples(info: wc.RunInfo) -> int | None:
    """The samples per render of the scene file a run rendered (None: a built-in scene, or not recorded)."""
    if info.scene_id.startswith("builtin:"):
        return None
    own = info.fixed.get("cycles.samples")
    return int(own[0]) if isinstance(own, list | tuple) and isinstance(own[0], int) else None


def _per_pass(spp: int) -> str:
    return f"{spp} sample{'s' if spp != 1 else ''} per pass"


def sample_notes(ref: wc.RunInfo, test: wc.RunInfo, identical: bool = False) -> tuple[list[str], list[str]]:
    """Where a verdict holds at its passes' samples only (`batch.jobs.samples`), as notes, and the differences
    the passes cannot show (``hidden``, as `fixed_notes`'): a setting the sides differ in that acts only from more
    samples per render than the passes have (or that left every pass as it was), and one both scene files have on
    that their own renders reach but the passes do not."""
    if not ref.settings or not test.settings:  # another renderer's passes, or an ingested run
        return [], []
    files = max((n for n in (_file_samples(ref), _file_samples(test)) if n is not None), default=None)
    spp = min(ref.spp, test.spp)

    def advice(fewest: int) -> str:
        need = max(fewest, files or 0, 2 * spp if fewest <= spp else 0)
        if files is not None and need == files:
            return f" (the scene files render {files}: --spp {files} renders the passes as they do)"
        return (
            f"; --spp {need} or more renders it"
            if fewest > spp
            else f"; more samples per pass (--spp {need} or more) may show it"
        )

    out, hidden = [], []
    for d in samples.differing(ref.settings, test.settings):
        shown = [a.value if (a := samples.acting(info.settings).get(d.path)) and a.fewest <= info.spp else None
                 for info in (ref, test)]  # fmt: skip
        if shown[0] != shown[1] and not identical:
            continue  # it acts in the passes: the test sees it
        values = tuple(_setting_value(v) for v in d.values)
        hidden.append(words.sample_hidden(d.name, values, d.fewest, spp))
        why = (f"which acts only from {d.fewest} samples per render" if d.fewest > spp else
               f"which left every pass as it was at these samples (it acts from {d.fewest} at best)")  # fmt: skip
        out.append(f"the verdict holds at {_per_pass(spp)} only: the sides differ in {d.name} ({values[0]} → "
                   f"{values[1]}), {why}{advice(d.fewest)}")  # fmt: skip
    if files is not None:
        both = samples.acting(ref.settings)
        for path, mine in samples.acting(test.settings).items():
            theirs = both.get(path)
            if theirs is not None and theirs.value == mine.value and spp < mine.fewest <= files:
                out.append(f"the verdict holds at {_per_pass(spp)} only: both scenes have {mine.name} "
                           f"{_setting_value(mine.value)}, which acts only from {mine.fewest} samples per render"
                           f"{advice(mine.fewest)}")  # fmt: skip
    return out, hidden


def check_notes(check: dict[str, Any] | None) -> list[str]:
    """What a check's own choices and ending add to the notes: the samples ``--spp auto`` chose, where more than
    1; that its time budget ended a pass."""
    out = []
    if (check or {}).get("ended_pass"):
        out.append(f"{check['ended_pass']}: the verdict is on the passes rendered before it")
    auto = (check or {}).get("auto_samples")
    if not auto:
        return out
    names = "; ".join(f"{d['name']} ({' → '.join(_setting_value(v) for v in d['values'])}, from {d['fewest']})"
                      for d in auto["differing"])  # fmt: skip
    source = "the scene files' own" if auto["files"] == auto["spp"] else "the fewest at which that acts"
    return out + [f"--spp auto: {_per_pass(auto['spp'])}, {source}, since the sides differ in what acts only from "
                  f"some samples per render: {names}"]  # fmt: skip


def selftest_summary(check: wc.Comparison | None) -> dict[str, Any] | None:
    """report.json's record of the reference tested against itself (`welch_core.selftest`)."""
    if check is None:
        return None
    return {
        "verdict": check.verdict.label,
        "verdict_text": check.outcome.verdict_text,
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
    if summary.get("dropped_pixels"):
        out.append(
            f"{summary['dropped_pixels']} pixels at the right and bottom edges are in no tile and untested (a file "
            "written before partial edge tiles): render it again to test them"
        )
    return out


def check_record(
    job,
    looks: list[dict],
    max_passes: int,
    last,
    early: tuple[float, int] | None = None,
    ended_pass: str | None = None,
    durations=None,
) -> dict[str, Any]:
    """What a `check` adds to its summary: the design (budget, tolerance, pairing, the early design's share of
    `biased` and the passes where it ends), the looks, how it ended (`ended_pass`: what its time budget ended, in
    a sentence, where it ended a pass still rendering), and how long it took (`durations`: the wall clock seconds
    and each side's render seconds, ``{"wall": s, "sides": {"reference": s, "test": s} or None}``)."""
    share, passes = early if early is not None else (0.0, None)
    stopped = "decided" if last.verdict is not None else "budget spent"
    durations = durations or {}
    return {
        "wall_seconds": durations.get("wall"),
        "side_seconds": durations.get("sides"),
        "max_passes": max_passes,
        "max_seconds": job.max_seconds,
        "min_passes": job.min_passes,
        "tolerance": job.tolerance,
        "paired": job.paired,
        "seed_offset": job.seed_offset,
        "auto_samples": job.auto_samples,
        "spending": "pocock",
        "early_share": share,
        "early_passes": passes if share else None,
        "passes": last.passes,
        "looks": looks,
        "stopped": "time budget ended a pass" if ended_pass else stopped,
        "ended_pass": ended_pass,
    }


def verdict_line(summary: dict[str, Any]) -> str:
    """One line for the terminal: the verdict sentence."""
    return f"verdict: {summary['sentence']}"


def design_line(summary: dict[str, Any]) -> str:
    """How much was rendered and tested, in a line."""
    check = summary.get("check")
    if check is not None:
        looks = check["looks"]
        return (
            f"alpha {summary['alpha']:g}, {summary['test']} test, {fmt.count(len(looks), 'look')}, "
            f"{fmt.count(check['passes'], 'pass')} a side, {durations_text(check)}"
        )
    return (
        f"alpha {summary['alpha']:g}, global p {fmt.p_is(summary['p_value'])}, {summary['test']} test, "
        f"{summary['tiles']['used']} of {summary['tiles']['total']} tiles used, n = {summary['n_ref']} vs "
        f"{summary['n_test']}"
    )


def durations_text(check: dict[str, Any]) -> str:
    """How long a check took, each number named: '13 s wall clock, rendering: reference 11 s, test 12 s' (the
    sides render at once, so their seconds add up to more than the wall clock's; a suite's reference is stored)."""
    sides = check.get("side_seconds")
    if sides:
        rendering = ", ".join(f"{name} {fmt.duration(seconds)}" for name, seconds in sides.items() if seconds > 0)
    else:  # a check started before each side's seconds were kept
        looks = check["looks"]
        rendering = f"{fmt.duration(looks[-1]['seconds'] if looks else 0.0)}, sides summed"
    wall = check.get("wall_seconds")
    text = f"rendering: {rendering or 'none'}"
    return text if wall is None else f"{fmt.duration(wall)} wall clock, {text}"


def console_lines(summary: dict[str, Any]) -> list[str]:
    """The lines the command line prints under the verdict."""
    lines = [design_line(summary)]
    pixels = words.pixel_line(summary.get("pixel_variance"))
    lines += [pixels] if pixels else []
    lines += [f"note: {note}" for note in summary["notes"]]
    lines += [f"warning: {warning}" for warning in summary["warnings"]]
    lines += layer_lines(summary.get("layers"))
    lines.append(f"next: {summary['next_step']}")
    return lines


def layers_summary(family: wc.LayerFamily) -> dict[str, Any]:
    """report.json's record of the layers (`welch_core.compare_layers`): a row per layer in words, which
    components explain a difference, and whether the components add up to the image in each run."""
    rows = []
    for layer in family.layers:
        c = layer.comparison
        if c is None:
            empty = "no light in either run"
            rows.append({"name": layer.name, "verdict": "empty", "verdict_text": empty, "sentence": empty,
                         "p_value": None, "significant_tiles": 0, "share": 0.0, "largest": None})  # fmt: skip
            continue
        data = c.outcome.to_json()
        rows.append({
            "name": layer.name,
            "verdict": c.verdict.label,
            "verdict_text": c.outcome.verdict_text,
            "sentence": words.sentence(data),
            "p_value": _num(c.p_value),
            "significant_tiles": sum(s["significant"] for s in data["scales"]),
            "share": None if layer.share is None else _num(layer.share),
            "largest": data["most_significant"],
        })  # fmt: skip
    sums = {side: None if error is None else {"relative_error": error, "ok": error <= wc.layers.SUM_TOLERANCE}
            for side, error in family.component_sum.items()}  # fmt: skip
    return {
        "layers": rows,
        "alpha": family.alpha,
        "after_looks": family.after_looks,
        "explained_by": list(family.explained_by),
        "explanation": words.attribution(family.attribution, family.explained_by),
        "component_sum": sums,
        "untested": {side: list(names) for side, names in family.untested.items()},
    }


def untested_lines(layers: dict[str, Any]) -> list[str]:
    """What was not tested because only one run has it."""
    return [f"not tested: {', '.join(names)} (only the {side} has {'them' if len(names) > 1 else 'it'})"
            for side, names in layers.get("untested", {}).items() if names]  # fmt: skip


def layer_lines(layers: dict[str, Any] | None) -> list[str]:
    """A line per light component or light group, and what they say together."""
    if not layers:
        return []
    how = f"layers, each at alpha {layers['alpha']:.3g}" + (
        " on the final passes (descriptive: not decided under the stopping rule)" if layers["after_looks"] else ""
    )
    lines = [how + ":"]
    for row in layers["layers"]:
        if row["verdict"] == "empty":
            lines.append(f"layer {row['name']}: {row['verdict_text']}")
            continue
        lines.append(f"layer {row['name']}: {row['sentence']}")
    if layers["explanation"]:
        lines.append(layers["explanation"])
    lines += untested_lines(layers)
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
