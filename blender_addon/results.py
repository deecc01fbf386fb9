"""What a comparison turns into in Blender: the p-value map over the mean render as an image, and a summary.

The image is built in numpy with ``welch_core`` (tone-mapped mean render, p-value colours blended over it) and
written into ``bpy.data.images`` in one ``foreach_set``; `refresh` also renews the overlay's vertices (the map
drawn over other images, ``overlay.py``). The summary is `batch.present.summary`'s (the words the command line prints
and the report shows) plus what only the panel needs, so ``draw()`` never computes. numpy, scipy and the
statistics are imported when a result is made, never when the add-on registers.
"""

from __future__ import annotations

import bpy

from . import _siblings, overlay
from ._siblings import welch_core
from .overlay import CHANNEL_INDEX, CORE_MAP_MODES, IMAGE_TAG
from .state import current

IMAGE_NAME = "Welch P-Value Map"
#: Blender icon of each verdict.
VERDICT_ICONS = {"biased": "ERROR", "equivalent": "CHECKMARK", "no_evidence": "CHECKMARK", "inconclusive": "QUESTION"}
HISTOGRAM_BINS = 10  # one bar each in the panel
TOP_TILES_SHOWN = 5
DIFFERENCES_SHOWN = 8


def shown_comparison(settings):
    """The comparison the map shows: the image's, or the chosen layer's."""
    return current.layers.get(settings.component, current.comparison)


def histogram_bars(pvalues, bins: int = HISTOGRAM_BINS) -> tuple[list[dict], float]:
    """The p-value histogram as one bar per bin (label, count, fill in [0, 1]) and the uniform count per bin.

    Bars are scaled to the larger of the highest bin and the uniform expectation, so a flat histogram (what an
    unbiased renderer gives) looks flat and a spike at small p stands out.
    """
    counts, edges, expected = welch_core.histogram(pvalues, bins=bins)
    top = max(float(counts.max(initial=0)), expected, 1e-12)
    bars = [
        {"label": f"{lo:.1f}-{hi:.1f}", "count": int(count), "fill": float(count / top)}
        for lo, hi, count in zip(edges[:-1], edges[1:], counts, strict=True)
    ]
    return bars, float(expected)


def summarize(assessment, sources: dict[str, str], report=None) -> dict:
    """Everything the panel shows, computed once: the command line's summary (notes and warnings included; a
    check's `report` as written) and the panel's histogram bars, verdict title and icon."""
    summary = dict(report if report is not None else assessment.summary)
    decided, comparison = assessment.outcome, assessment.comparison
    verdict = welch_core.Verdict(summary["verdict"])
    bars, expected = histogram_bars(comparison.tile_pvalues[comparison.used])
    title, icon = verdict.title + (" (Bit-Identical)" if decided.identical else ""), VERDICT_ICONS[verdict]
    if not decided.decided:  # a look of a check that goes on: numbers so far, no verdict yet
        title, icon = f"No Verdict Yet ({decided.n_test} Passes)", "TIME"
    summary.update(
        verdict_title=title,
        design=_siblings.pipeline.summaries.design_line(summary),
        verdict_icon=icon,
        histogram=bars,
        histogram_expected=expected,
        top_tiles=summary["top_tiles"][:TOP_TILES_SHOWN],
        differences=summary["differences"][:DIFFERENCES_SHOWN],
        excluded={k: v for k, v in summary["tile_channels"].items() if v and k != "valid"},
        sources=dict(sources),
        image="",
    )
    return summary


def _outline(rgb, row: int, col: int, tile: int) -> None:
    """Draw a white-and-black frame (visible on any colour) around one tile, in place, rows top first."""
    height, width = rgb.shape[:2]
    y0, x0 = row * tile, col * tile
    y1, x1 = min(y0 + tile, height) - 1, min(x0 + tile, width) - 1
    for inset, colour in ((0, 1.0), (1, 0.0)):
        top, bottom, left, right = y0 + inset, y1 - inset, x0 + inset, x1 - inset
        if top > bottom or left > right:
            return
        rgb[top, left : right + 1] = rgb[bottom, left : right + 1] = colour
        rgb[top : bottom + 1, left] = rgb[top : bottom + 1, right] = colour


def result_rgba(comparison, base_stats, map_mode: str, channel: str, opacity: float, highlight=None):
    """The result image as float32 RGBA, rows bottom-up (Blender's order), height x width x 4."""
    import numpy as np

    height, width, tile = base_stats.height, base_stats.width, base_stats.tile
    core_mode = CORE_MAP_MODES[map_mode]
    tiles_rgb = welch_core.pvalue_rgb(comparison, mode=core_mode, channel=CHANNEL_INDEX.get(channel))
    map_rgb = welch_core.upscale_tiles(tiles_rgb, tile, height, width)
    shown = overlay.significant_of(comparison) if map_mode == "SIGNIFICANT" else comparison.used
    mask = welch_core.upscale_tiles(shown.astype(np.float32), tile, height, width)
    mean = base_stats.mean_image
    base = welch_core.tonemap(mean) if mean is not None else np.full((height, width, 3), 0.5, np.float32)
    rgb = np.array(welch_core.overlay(base, map_rgb, float(opacity), mask), dtype=np.float32)
    if highlight is not None:
        _outline(rgb, highlight[0], highlight[1], tile)
    rgba = np.concatenate([rgb, np.ones((height, width, 1), np.float32)], axis=2)
    return np.ascontiguousarray(rgba[::-1])


def write_image(rgba, name: str = IMAGE_NAME) -> bpy.types.Image:
    """Put the pixels into a float image of ``bpy.data`` (reused when it is ours), colour space Non-Color."""
    height, width = rgba.shape[:2]
    image = bpy.data.images.get(name)
    if image is None or not image.get(IMAGE_TAG):
        image = bpy.data.images.new(name, width, height, alpha=True, float_buffer=True)
        image[IMAGE_TAG] = True
    elif tuple(image.size) != (width, height):
        image.scale(width, height)
    # The map is display-referred already (tone-mapped and sRGB-encoded): no view transform on top.
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(rgba.ravel())
    image.update()
    return image


def _image_editors(context):
    screens = [context.screen] if context.screen else []
    screens += [w.screen for w in context.window_manager.windows if w.screen not in screens]
    for screen in screens:
        for area in screen.areas:
            if area.type == "IMAGE_EDITOR":
                yield area


#: The workspace of the default layout whose Image Editor shows renders (factory startup and most startup files).
RENDER_WORKSPACE = "Rendering"
#: The Image Editor sidebar's tab where the result is (`blender_addon.ui.WELCH_BIAS_PT_image_editor`).
SIDEBAR_TAB = "Welch"


def show_in_image_editor(context, image, sidebar: bool = False) -> bool:
    """Show ``image`` in an Image Editor: an open one, else the Image Editor of the Rendering workspace (switched
    to, as the place a default layout keeps for renders), else the render window Blender opens with F11 (whose
    size follows the render resolution: a few hundred pixels for a small test scene). With `sidebar` (a finished
    run), also open the editor's sidebar, where the result is, and fit the image to it."""
    area = next(_image_editors(context), None)
    workspace = bpy.data.workspaces.get(RENDER_WORKSPACE)
    if area is None and not bpy.app.background and context.window is not None and workspace is not None:
        context.window.workspace = workspace
        area = next((a for a in workspace.screens[0].areas if a.type == "IMAGE_EDITOR"), None)
    if area is None and not bpy.app.background:
        try:
            bpy.ops.render.view_show("INVOKE_DEFAULT")
        except RuntimeError:
            pass
        area = next(_image_editors(context), None)
    if area is None:
        return False
    space = area.spaces.active
    newly = space.image != image
    space.image = image
    if sidebar:
        space.show_region_ui = True
        for ui in (r for r in area.regions if r.type == "UI"):
            if hasattr(ui, "active_panel_category"):  # Blender 4.2+; 3.4 keeps the tab last chosen
                ui.active_panel_category = SIDEBAR_TAB
    if (sidebar or newly) and not bpy.app.background:
        # Once the editor has drawn: a workspace just switched to has no region size yet.
        tries = iter(range(FIT_TRIES))
        bpy.app.timers.register(lambda: _fit(area) if next(tries, None) is not None else None, first_interval=0.1)
    area.tag_redraw()
    return True


#: Times a fit is tried, FIT_INTERVAL seconds apart, until the editor has drawn at its size (5.2 takes longer
#: than 3.4 to give a workspace just switched to its regions' sizes).
FIT_TRIES, FIT_INTERVAL = 30, 0.1


def _fit(area) -> float | None:
    """Fit the image to its Image Editor (the map opened at 1:1 is a small square in a large editor); the
    interval to try again while the view is not fitted yet (a timer's return), else None."""
    try:
        window = next((w for w in bpy.context.window_manager.windows if area in w.screen.areas[:]), None)
        region = next((r for r in area.regions if r.type == "WINDOW"), None)
        if window is None or region is None:
            return None  # the area is not shown any more (another workspace, a closed window)
        space = area.spaces.active
        with bpy.context.temp_override(window=window, area=area, region=region, space_data=space):
            bpy.ops.image.view_all(fit_view=True)
        # The zoom at once (the view's own rectangle follows at the next draw); before its editor is ready, 5.2
        # takes the operator and leaves the zoom as it was.
        shown = space.zoom[0] * max(space.image.size) if space.image is not None else 0.0
        return None if shown >= 0.5 * min(region.width, region.height) else FIT_INTERVAL
    except (RuntimeError, TypeError, ReferenceError):  # the area was freed meanwhile
        return None


def frame_tile(context, x: int, y: int, size: int) -> bool:
    """Put the Image Editor's 2D cursor on a tile's centre and centre the view there, where Blender allows it."""
    area = next(_image_editors(context), None)
    if area is None:
        return False
    space = area.spaces.active
    image = space.image
    if image is None:
        return False
    width, height = image.size
    # The cursor is in pixels (bottom-up) when the editor shows pixel coordinates, else in 0..1 UV units.
    cx, cy = x + size / 2, height - (y + size / 2)
    space.cursor_location = (cx, cy) if space.uv_editor.show_pixel_coords else (cx / width, cy / height)
    region = next((r for r in area.regions if r.type == "WINDOW"), None)
    try:
        with context.temp_override(area=area, region=region, space_data=space):
            bpy.ops.image.view_center_cursor()
    except RuntimeError:
        return False  # no drawable region (background mode): the outline in the image still marks the tile
    area.tag_redraw()
    return True


def save_with_file(scene, key: tuple) -> None:
    """Keep the last result's summary in the scene (saved with the .blend), with the settings it was made with."""
    import json

    scene.welch_bias.last_result = json.dumps(current.result, default=str)
    scene.welch_bias.last_result_key = repr(key)


#: What the panel reads of a saved result, and of which type: a result saved by another version of the add-on,
#: or damaged, is left out (one line in the console) instead of failing every draw of the panel.
SAVED_FIELDS = {"verdict": str, "verdict_title": str, "verdict_icon": str, "sentence": str, "design": str,
                "tiles": dict, "n_ref": int, "n_test": int, "excluded": dict, "notes": list, "warnings": list,
                "histogram": list, "histogram_expected": (int, float), "top_tiles": list, "differences": list,
                "image": str}  # fmt: skip
SAVED_TILES = ("valid", "total", "used", "significant")


def _saved_problem(result) -> str | None:
    """Why `result` (a saved summary, parsed) can't be shown, or None."""
    if not isinstance(result, dict):
        return f"it is a {type(result).__name__}, not a summary"
    wrong = [k for k, kind in SAVED_FIELDS.items() if not isinstance(result.get(k), kind)]
    if not wrong and any(not isinstance(result["tiles"].get(k), int) for k in SAVED_TILES):
        wrong = ["tiles"]
    if not wrong and result["verdict_icon"] not in {*VERDICT_ICONS.values(), "TIME"}:
        wrong = ["verdict_icon"]
    return f"{', '.join(wrong)} missing or of another kind" if wrong else None


def restore_from_file(scene) -> bool:
    """The summary saved with the file, back into the panel (its map needs the run's statistics: not kept)."""
    import json

    text = scene.welch_bias.last_result
    if current.result is not None or not text:
        return False
    try:
        result = json.loads(text)
    except ValueError:
        result = text
        problem = "it is not JSON"
    else:
        problem = _saved_problem(result)
    if problem is not None:
        print(f"Welch bias: the result saved in this file is from another version or damaged ({problem}): not shown")
        return False
    current.result = result
    current.result["saved"] = True
    return True


def store(assessment, reference, test, sources: dict[str, str], report=None) -> dict:
    """Cache a new assessment (`batch.present.pipeline.Assessment`: its comparison and its layers') for the
    panels and the display settings; a finished check's `report` is what the panel says, the comparison only
    draws the map. The layers' verdicts are the report's (at the layers' alpha), never decided here."""
    current.comparison, current.stats, current.highlight = assessment.comparison, (reference, test), None
    current.significant = assessment.outcome.significant
    current.layers = dict(assessment.layers)
    current.result = summarize(assessment, sources, report)
    rows = (current.result.get("layers") or {}).get("layers", [])
    current.result["layers"] = [
        {"name": row["name"], "verdict": row["verdict"],
         "title": "No Light" if row["verdict"] == "empty" else welch_core.Verdict(row["verdict"]).title}
        for row in rows
    ]  # fmt: skip
    return current.result


def refresh(context) -> bpy.types.Image | None:
    """Rebuild the result image and the overlay from the cached comparison with the scene's display settings."""
    if current.comparison is None or not current.stats:
        return None
    settings = context.scene.welch_bias
    overlay.update(settings)
    overlay.tag_redraw(context)
    reference, test = current.stats
    # The test side is the render under suspicion: its mean is the picture under the map.
    base = test if test.mean_image is not None else reference
    rgba = result_rgba(
        shown_comparison(settings), base, settings.map_mode, settings.channel, settings.opacity, current.highlight
    )
    image = write_image(rgba)
    current.result["image"] = image.name
    return image
