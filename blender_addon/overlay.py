"""The p-value map drawn over the image in every Image Editor by a draw handler, live and crisp at any zoom.

`update` turns the cached comparison and the display settings into vertices once per change: two triangles per
tile with the map's colour and the opacity as alpha (transparent where a tile is not used), and line segments
around the tiles significant after correction, all in normalised image coordinates (0..1, v up, tile row 0 at
the top). `draw` only uploads them as GPU batches on its first call after a change and places them with the
view's transform. The map image itself is skipped: its pixels carry the map already. Blender calls no draw
handlers in background mode, so there nothing here runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import bpy

from ._siblings import fmt, rna, welch_core
from .state import current

IMAGE_TAG = "welch_bias_result"  # custom property marking the result images this add-on may overwrite
#: The panel's map modes as welch_core.colormap's, and its channel names as indices.
CORE_MAP_MODES = {"MIN": "min", "CHANNEL": "channel", "SQRT": "sqrt", "LOG10": "log10", "Q": "q", "SIGNIFICANT": "min"}
CHANNEL_INDEX = {"R": 0, "G": 1, "B": 2}

OUTLINE_COLORS = ((0.0, 0.0, 0.0, 1.0), (1.0, 1.0, 1.0, 1.0))  # a dark line under a light one: visible on any tile
OUTLINE_WIDTHS = (3.0, 1.0)  # pixels
TRIANGLES = "abcacd"  # corners of the two counter-clockwise triangles of a tile (see _corners)
OUTLINE = "abbccdda"  # corners of its four edges
ASPECT_TOLERANCE = 0.01  # images within 1 % of the compared width/height ratio get the overlay (e.g. a 50 % render)

# Blender 3.x names its 2D builtin shaders 2D_*; 4.0 dropped those names (the plain ones take 2D positions).
FLAT_COLOR_SHADERS = ("2D_FLAT_COLOR", "FLAT_COLOR")
LINE_SHADERS = ("POLYLINE_UNIFORM_COLOR",)

_handle = None


@dataclass(frozen=True)
class Geometry:
    """What the overlay draws, in normalised image coordinates; float32 arrays ready for the GPU."""

    width: int  # the compared image's size in pixels, to match the images the overlay belongs over
    height: int
    positions: object  # (6 * tiles, 2): two triangles per tile
    colors: object  # (6 * tiles, 4): RGBA per vertex
    outline: object  # (2 * segments, 2): ends of the line segments around significant tiles


def tile_rects(tiles_y: int, tiles_x: int, tile: int, width: int, height: int):
    """(u0, v0, u1, v1) of every tile, rows first, in normalised image coordinates with v up.

    The tile grid starts at the top-left corner; the tiles at the right and bottom edges are partial where the
    tile does not divide the image (files of earlier versions have no such tiles: their edge is not covered).
    """
    import numpy as np

    rows, cols = np.meshgrid(np.arange(tiles_y), np.arange(tiles_x), indexing="ij")
    u0, u1 = cols * tile / width, np.minimum((cols + 1) * tile, width) / width
    v1 = 1.0 - rows * tile / height  # row 0 is the top of the image
    v0 = 1.0 - np.minimum((rows + 1) * tile, height) / height
    return np.stack([u0, v0, u1, v1], axis=-1).reshape(-1, 4).astype(np.float32)


def _corners(rects, order: str):
    """Points of every rect in ``order`` (corner names: a bottom-left, b bottom-right, c top-right, d top-left),
    flattened to (len(rects) * len(order), 2) float32."""
    import numpy as np

    u0, v0, u1, v1 = rects.T
    points = {"a": (u0, v0), "b": (u1, v0), "c": (u1, v1), "d": (u0, v1)}
    stacked = np.stack([np.stack(points[name], axis=-1) for name in order], axis=1)
    return np.ascontiguousarray(stacked.reshape(-1, 2), dtype=np.float32)


def significant_of(comparison):
    """The finest tiles the verdict found significant: for the stored comparison of a check, its look's (the
    verdict is the look's), else the comparison's own."""
    if comparison is current.comparison and current.significant is not None:
        return current.significant
    return comparison.significant


def tile_geometry(comparison, map_mode: str, channel: str, opacity: float) -> Geometry:
    """The overlay of `comparison` with the panel's display settings (``map_mode`` and ``channel`` as the
    settings' identifiers)."""
    import numpy as np

    tiles_y, tiles_x = comparison.tile_pvalues.shape
    rects = tile_rects(tiles_y, tiles_x, comparison.tile, comparison.width, comparison.height)
    rgb = welch_core.pvalue_rgb(comparison, mode=CORE_MAP_MODES[map_mode], channel=CHANNEL_INDEX.get(channel))
    significant = significant_of(comparison)
    shown = significant if map_mode == "SIGNIFICANT" else comparison.used
    alpha = np.where(shown, float(opacity), 0.0)[..., None]  # untrusted and untestable tiles stay clear
    rgba = np.concatenate([rgb, alpha], axis=-1).reshape(-1, 4).astype(np.float32)
    return Geometry(
        width=comparison.width,
        height=comparison.height,
        positions=_corners(rects, TRIANGLES),
        colors=np.ascontiguousarray(np.repeat(rgba, len(TRIANGLES), axis=0)),
        outline=_corners(rects[significant.ravel()], OUTLINE),
    )


def covers(image, geometry: Geometry, scene) -> bool:
    """Whether the overlay belongs over ``image``: one of the compared width/height ratio (the Render Result, a
    saved render, the mean image), except the map image, whose pixels carry the map already."""

    if image is None or image.get(IMAGE_TAG):
        return False
    if image.type == "RENDER_RESULT":
        width, height = rna.render_size(scene)  # its own size reads 0 x 0 from Python (3.4 and 5.0)
    else:
        width, height = image.size
    if width == 0 or height == 0:
        return False
    return abs(width * geometry.height - height * geometry.width) <= ASPECT_TOLERANCE * width * geometry.height


def shown_anywhere(context) -> bool:
    """Whether an Image Editor shows an image the overlay is drawn over (never in background mode)."""
    geometry, scene = current.overlay, context.scene
    if bpy.app.background or geometry is None or scene is None or not scene.welch_bias.show_overlay:
        return False
    return any(
        covers(area.spaces.active.image, geometry, scene)
        for window in context.window_manager.windows
        for area in window.screen.areas
        if area.type == "IMAGE_EDITOR"
    )


def update(settings) -> None:
    """Recompute the vertices from the cached comparison; the next draw uploads them."""
    current.overlay_batches, current.overlay_error = None, ""
    if current.comparison is None:
        current.overlay = None
        return
    shown = current.layers.get(settings.component, current.comparison)  # the image's map, or a layer's
    current.overlay = tile_geometry(shown, settings.map_mode, settings.channel, settings.opacity)


def tag_redraw(context) -> None:
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "IMAGE_EDITOR":
                area.tag_redraw()


def builtin_shader(names: tuple[str, ...]):
    """The first of ``names`` this Blender has."""
    import gpu

    for name in names:
        try:
            return gpu.shader.from_builtin(name)
        except ValueError:
            continue
    raise RuntimeError(f"this Blender has none of the shaders {', '.join(names)}")


def make_batches(geometry: Geometry):
    """GPU batches of the geometry: (shader, batch) for the tiles, and for the outline or None."""
    from gpu_extras.batch import batch_for_shader

    flat = builtin_shader(FLAT_COLOR_SHADERS)
    tiles = batch_for_shader(flat, "TRIS", {"pos": geometry.positions, "color": geometry.colors})
    outline = None
    if len(geometry.outline):
        line = builtin_shader(LINE_SHADERS)
        outline = (line, batch_for_shader(line, "LINES", {"pos": geometry.outline}))
    return (flat, tiles), outline


def _draw(geometry: Geometry, region) -> None:
    import gpu

    if current.overlay_batches is None:
        current.overlay_batches = make_batches(geometry)
    (flat, tiles), outline = current.overlay_batches
    # The image spans 0..1 in the view's coordinates; one transform places every vertex.
    x0, y0 = region.view2d.view_to_region(0.0, 0.0, clip=False)
    x1, y1 = region.view2d.view_to_region(1.0, 1.0, clip=False)
    gpu.state.blend_set("ALPHA")
    try:
        with gpu.matrix.push_pop():
            gpu.matrix.translate((x0, y0))
            gpu.matrix.scale((x1 - x0, y1 - y0))
            flat.bind()
            tiles.draw(flat)
            if outline is not None:
                line, lines = outline
                line.bind()
                line.uniform_float("viewportSize", (region.width, region.height))
                for color, width in zip(OUTLINE_COLORS, OUTLINE_WIDTHS, strict=True):
                    line.uniform_float("lineWidth", width)
                    line.uniform_float("color", color)
                    lines.draw(line)
    finally:
        gpu.state.blend_set("NONE")


def draw() -> None:
    """Draw handler of every Image Editor's main region."""
    geometry = current.overlay
    if geometry is None or current.overlay_error:
        return
    context = bpy.context
    scene = context.scene
    if scene is None or not scene.welch_bias.show_overlay:
        return
    if not covers(getattr(context.space_data, "image", None), geometry, scene):
        return
    try:
        _draw(geometry, context.region)
    except Exception as ex:  # a failing draw handler would raise again on every redraw of every editor
        current.overlay_error = fmt.one_line(f"{type(ex).__name__}: {ex}")
        print(f"Welch Bias Test: the overlay can't be drawn: {current.overlay_error}")


def register():
    global _handle
    _handle = bpy.types.SpaceImageEditor.draw_handler_add(draw, (), "WINDOW", "POST_PIXEL")


def unregister():
    global _handle
    if _handle is not None:
        bpy.types.SpaceImageEditor.draw_handler_remove(_handle, "WINDOW")
        _handle = None
