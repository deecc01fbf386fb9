"""The report of a comparison: one self-contained ``report.html`` (no network, no other file needed), the summary
as ``report.json``, and the per-tile p-values as ``pvalues.exr`` at tile resolution.

The page carries the per-tile data (p-values, q-values, relative differences and their intervals, trust, the
reason a tile-channel has no p, the finest tested tile size) as little-endian float64 (p-values), float32 and
uint8 arrays in base64,
and the mean renders of both sides as PNG (shrunk to at most `DISPLAY_MAX` pixels a side, tone-mapped with the
reference's exposure so brightness compares); its script draws them on a canvas (`report_template.html`). No
plotting library is imported: the report of a 4K comparison is written in milliseconds, not seconds.
"""

from __future__ import annotations

import base64
import functools
import html
import json
import os
from pathlib import Path

import numpy as np

from .._siblings import welch_core as wc
from . import fmt
from .statuses import verdict_colour
from .summary import design_line, untested_lines

#: The longest side of the pictures in the page (what statistics files store as their preview); tiles are drawn
#: at their true place over them.
DISPLAY_MAX = wc.formats.PREVIEW_SIDE

#: Bins of the p-value histogram (the paper uses 30 and, at low sample counts, fewer: Fig. 16f).
HISTOGRAM_BINS = 20

TEMPLATE = Path(__file__).with_name("report_template.html")


def write_report(
    out_dir: str | os.PathLike,
    summary: dict,
    result: wc.Comparison,
    ref: wc.TileStats,
    test: wc.TileStats,
    full_maps: bool = False,
    previews: tuple[np.ndarray | None, np.ndarray | None] | None = None,
    layers: dict[str, wc.Comparison] | None = None,
    significant: np.ndarray | None = None,
) -> dict:
    """Write the report of a comparison into `out_dir` (created if missing); return the report dict (the
    summary of `batch.summary.summarize` and the files written). `full_maps` also writes the p-value map and
    the overlay at the image's resolution as PNG. `previews` are both sides' pixel sums shrunk to at most
    `DISPLAY_MAX` a side (`welch_core.load_preview`), for runs loaded without their pixel sums. `layers` are
    the comparisons of the light components and light groups, whose rows the summary holds (``layers``).
    `significant` are the finest tiles the verdict found significant (default: the comparison's own; a check's
    are its last look's), which the map outlines."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {"pvalues_exr": "pvalues.exr", "html": "report.html"}
    contents = {out / "pvalues.exr": wc.exr.exr_bytes(np.nan_to_num(result.pvalues, nan=-1.0))}
    if full_maps:
        maps = _full_maps(result, test if test.mean_image is not None else ref)
        files |= {key: name for key, (name, _data) in maps.items()}
        contents |= {out / name: data for name, data in maps.values()}
    report = dict(summary, files=files)
    significant = result.significant if significant is None else significant
    contents[out / "report.json"] = json.dumps(report, indent=2, allow_nan=False).encode("utf-8")
    page = render_html(report, result, ref, test, previews, layers, significant)
    contents[out / "report.html"] = page.encode("utf-8")
    wc.formats.atomic_write_all(contents)  # replaced whole or not at all: no new page beside an old summary
    return report


def _full_maps(result: wc.Comparison, run: wc.TileStats) -> dict:
    """The p-value map and its overlay on the mean render at the image's resolution: key -> (file, PNG)."""
    tiles_rgb = wc.pvalue_rgb(result, "min")
    map_rgb = wc.upscale_tiles(tiles_rgb, result.tile, result.height, result.width, fill=wc.colormap.EXCLUDED_GREY)
    base = wc.tonemap(run.mean_image) if run.mean_image is not None else np.full(map_rgb.shape, 0.5, np.float32)
    used = wc.upscale_tiles(result.used, result.tile, result.height, result.width, fill=False)
    overlay = wc.overlay(base, map_rgb, 0.6, used)
    return {
        "pvalue_map_png": ("pvalue_map.png", wc.png.png_bytes(wc.png.to_uint8(map_rgb))),
        "overlay_png": ("overlay.png", wc.png.png_bytes(wc.png.to_uint8(overlay))),
    }


# -- the page ------------------------------------------------------------------------------------------------


def render_html(
    report: dict, result: wc.Comparison, ref: wc.TileStats, test: wc.TileStats, previews=None, layers=None,
    significant=None,
) -> str:  # fmt: skip
    significant = result.significant if significant is None else significant
    drawn = _pictures(result, ref, test, previews)
    data = {"summary": report, **_tile_data(result, report["grid"], significant), "display": drawn["display"]}
    text = script_json(data, drawn["pictures"])
    colour = verdict_colour(report["verdict"])
    replacements = {
        "{{TITLE}}": html.escape(f"Bias test: {report['verdict_text']}"),
        "{{VERDICT}}": html.escape(report["verdict_text"].capitalize()),
        "{{COLOUR}}": colour,
        "{{SENTENCE}}": html.escape(report["sentence"]),
        "{{HEADLINE}}": html.escape(design_line(report)),
        "{{NEXT_STEP}}": html.escape(report.get("next_step", "")),
        "{{HISTOGRAM}}": histogram_svg(result),
        "{{SELFTEST}}": _selftest_line(report),
        "{{LAYERS}}": layers_section(report.get("layers"), layers or {}),
    }
    head, _, tail = TEMPLATE.read_text(encoding="utf-8").partition("{{DATA}}")
    for key, value in replacements.items():
        head = head.replace(key, value)
    return head + text + tail  # the data last: it is most of the page and holds no placeholder


def script_json(data: dict, pictures: dict[str, str] | None = None) -> str:
    """`data` as JSON safe inside a ``<script>`` element: every ``<``, ``>`` and ``&`` escaped, so that no text in it
    (``</script>``, ``<!--<script>`` in a scene, layer or renderer name) can end or comment out the script.
    `pictures` (name -> a PNG data URL) are added as ``data["pictures"]`` as they are: base64 holds nothing JSON or
    a script escapes, and encoding their megabytes again took longer than the rest of the page (22 ms at
    1024x576)."""
    text = json.dumps(data, allow_nan=False, separators=(",", ":"))
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    if pictures is None:
        return text
    for url in pictures.values():
        if not url.isascii() or any(c in url for c in '"\\<>&'):
            raise ValueError("a picture must be a data URL in base64")
    urls = ",".join(f'{json.dumps(name)}:"{url}"' for name, url in pictures.items())
    return f'{text[:-1]}{"," if data else ""}"pictures":{{{urls}}}}}'


def layers_section(summary: dict | None, comparisons: dict[str, wc.Comparison]) -> str:
    """A row per light component and light group: its share of the image, verdict, p, significant tiles, largest
    difference with its interval and its p-value map; which components explain the image's difference; the
    check that the components add up to the image."""
    if not summary:
        return ""
    rows = []
    for row in summary["layers"]:
        c = comparisons.get(row["name"])
        picture = ""
        if c is not None:
            url = wc.png.data_url(wc.colorize(wc.colormap.map_values(c.pvalues, "log10")))
            picture = f'<img class="layer-map" alt="p-value map of {html.escape(row["name"])}" src="{url}">'
        largest = row["largest"]
        difference = (
            f"{fmt.difference(largest)} ({largest['channel']} at {largest['x']}, {largest['y']}, {largest['tile']} px "
            f"tile, {largest['confidence']:.0%} simultaneous)"
            if largest
            else "—"
        )
        share = f"{row['share']:.1%}" if row["share"] is not None else "—"
        rows.append(
            f'<tr class="layer" data-layer="{html.escape(row["name"])}"><td>{html.escape(row["name"])}</td>'
            f'<td class="num">{share}</td><td>{html.escape(row["verdict_text"])}</td>'
            f'<td class="num">{fmt.p_value(row["p_value"])}</td><td class="num">{row["significant_tiles"]}</td>'
            f"<td>{difference}</td><td>{picture}</td></tr>"
        )
    notes = []
    if summary.get("after_looks"):
        notes.append(f"each layer is tested once on the final passes at alpha {summary['alpha']:.3g} (Bonferroni over "
                     "the layers): descriptive, it says where the difference is; the verdict is the image's, decided "
                     "under the stopping rule")  # fmt: skip
    else:
        notes.append(f"each layer is tested at alpha {summary['alpha']:.3g} (Bonferroni over the layers)")
    if summary["explanation"]:
        notes.append(summary["explanation"])
    notes += untested_lines(summary)
    for side, check in summary["component_sum"].items():
        if check is None:
            notes.append(f"{side}: the components were not all rendered, so their sum was not checked")
        elif not check["ok"]:
            notes.append(f"{side}: the components do not add up to the image (largest relative difference "
                         f"{check['relative_error']:.2g}): a component is missing or counted twice")  # fmt: skip
        else:
            notes.append(f"{side}: the components add up to the image (within {check['relative_error']:.1g})")
    head = "<tr><th>layer</th><th>share</th><th>verdict</th><th>p</th><th>significant tiles</th>"
    head += "<th>most significant difference (interval)</th><th>map</th></tr>"
    items = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    return (
        '<section style="flex:1 1 100%" id="layers"><h2>Light components and light groups</h2>'
        f'<table class="grid">{head}{"".join(rows)}</table><ul>{items}</ul></section>'
    )


def _selftest_line(report: dict) -> str:
    """The reference tested against itself (paper §6), in the page's text so it reads without the script."""
    selftest = report.get("reference_selftest")
    if selftest is None:
        return ""
    verdict = wc.Verdict(selftest["verdict"])
    text = (
        f"the reference against itself (two halves of {report['n_ref']} passes): "
        f"{verdict.text}, p {fmt.p_is(selftest['p_value'])}"
    )
    return f'<p id="selftest" class="muted">{html.escape(text)}</p>'


def _b64(array: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def _tile_data(c: wc.Comparison, grid: dict, significant: np.ndarray) -> dict:
    """The per-tile arrays of the finest scale, row-major, for the page's script (`grid`: the summary's)."""
    sizes, region_p = c.region_scales()
    effect = c.effect
    valid = c.reasons == wc.Reason.VALID
    return {
        "grid": {
            **grid,
            "channels": int(c.pvalues.shape[-1]),
            "reasons": [r.label for r in wc.Reason],
        },
        "tiles": {
            "p": _b64(c.pvalues, "<f8"),  # p-values far below float32's range (1e-38) are common
            "tile_p": _b64(c.tile_pvalues, "<f8"),
            "adjusted": _b64(c.global_test.adjusted, "<f8"),
            "q": _b64(c.qvalues, "<f8"),
            "rel": _b64(np.where(valid, effect.rel_diff, np.nan), "<f4"),
            "low": _b64(np.where(valid, effect.ci_low, np.nan), "<f4"),
            "high": _b64(np.where(valid, effect.ci_high, np.nan), "<f4"),
            "reason": _b64(c.reasons, "u1"),
            "trusted": _b64(c.trusted, "u1"),
            "significant": _b64(significant, "u1"),
            "uncovered": _b64(c.uncovered if c.uncovered is not None else np.zeros(c.trusted.shape, bool), "u1"),
            "scale": _b64(sizes, "<f4"),
            "scale_p": _b64(region_p, "<f8"),
        },
    }


def _pictures(c: wc.Comparison, ref: wc.TileStats, test: wc.TileStats, previews=None) -> dict:
    """PNG data URLs of both sides' mean renders, with one exposure (the reference's) so brightness compares; the
    page draws their difference itself."""
    if previews is None:
        previews = [None if run.pixel_sum is None else wc.shrink(run.pixel_sum, DISPLAY_MAX) for run in (ref, test)]
    # The pixel sums shrunk, then divided: no full-size mean image is made.
    means = [
        preview / np.float32(run.n) if preview is not None and run.n else None
        for run, preview in zip((ref, test), previews, strict=True)
    ]
    known = [m for m in means if m is not None]
    if not known:
        return {"pictures": {}, "display": None}
    height, width = known[0].shape[:2]
    factor = max(1, -(-max(c.height, c.width) // DISPLAY_MAX))  # as `shrink` divides: image pixels per display pixel
    scale = wc.exposure(known[0])
    tasks = {name: functools.partial(_side_png, m, scale) for name, m in zip(("reference", "test"), means, strict=True)
             if m is not None}  # fmt: skip
    if len(known) == 2:
        tasks["difference"] = functools.partial(_difference_png, *means)
    made = dict(zip(tasks, wc.parallel.at_once(*tasks.values()), strict=True))  # each picture on a core of its own
    difference, limit = made.pop("difference", (None, None))
    pictures = made | ({"difference": difference} if difference is not None else {})
    # the difference map's ends, relative to the reference's mean brightness
    display = {"width": width, "height": height, "factor": factor, "difference_scale": limit}
    return {"pictures": pictures, "display": display}


def _side_png(mean: np.ndarray, scale: float) -> str:
    return wc.png.data_url(wc.tonemap(mean, scale=scale))


def _difference_png(ref_mean: np.ndarray, test_mean: np.ndarray) -> tuple[str | None, float | None]:
    levels, limit = wc.difference_picture(ref_mean, test_mean)
    return (None, None) if levels is None else (wc.png.data_url(levels, wc.colormap.DIFFERENCE_PALETTE), limit)


def histogram_svg(c: wc.Comparison, width: int = 420, height: int = 150) -> str:
    """The p-values of the tested tile-channels in `HISTOGRAM_BINS` bins, as inline SVG: flat if unbiased, a spike
    at the left is bias (paper §3.2, Fig. 10)."""
    p = c.pvalues[c.used]
    counts, _edges, expected = wc.histogram(p, HISTOGRAM_BINS)
    top = max(float(counts.max(initial=0)), expected, 1.0)
    left, bottom, plot_w, plot_h = 34, 22, width - 44, height - 34
    bar = plot_w / HISTOGRAM_BINS
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" role="img" '
        f'aria-label="histogram of {p.size} p-values">'
    ]
    for i, count in enumerate(counts):
        h = plot_h * count / top
        parts.append(
            f'<rect x="{left + i * bar + 1:.1f}" y="{height - bottom - h:.1f}" width="{bar - 2:.1f}" height="{h:.1f}" '
            f'fill="#3b6fb6"><title>p {i / HISTOGRAM_BINS:.2f}-{(i + 1) / HISTOGRAM_BINS:.2f}: {count}</title></rect>'
        )
    y = height - bottom - plot_h * expected / top
    parts += [
        f'<line x1="{left}" x2="{left + plot_w}" y1="{y:.1f}" y2="{y:.1f}" stroke="#222" stroke-dasharray="4 3"/>',
        f'<text x="{left + plot_w}" y="{y - 4:.1f}" text-anchor="end" font-size="11">uniform (no bias)</text>',
        f'<line x1="{left}" x2="{left + plot_w}" y1="{height - bottom}" y2="{height - bottom}" stroke="#222"/>',
        f'<text x="{left}" y="{height - 6}" font-size="11">0</text>',
        f'<text x="{left + plot_w}" y="{height - 6}" font-size="11" text-anchor="end">p = 1</text>',
        f'<text x="{left - 4}" y="{height - bottom - plot_h + 10}" font-size="11" text-anchor="end">{int(top)}</text>',
        "</svg>",
    ]
    return "".join(parts)
