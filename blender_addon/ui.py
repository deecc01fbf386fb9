"""Panels in Properties > Render (Cycles) and the Image Editor sidebar, and a progress bar in the status bar.

``draw()`` only reads the scene settings and the cached state (``state.py``); every number shown was computed
when the run ended. Layout calls that Blender 3.4 lacks (``panel``, ``progress``) fall back to boxes and labels
(a bar of block characters).
"""

import textwrap

import bpy

from . import runner
from ._siblings import fmt
from .results import SIDEBAR_TAB
from .session import settings_key
from .state import current

BAR_BLOCK = "\u2588"  # a full block: Blender before 4.0 has no progress bar widget, its UI font has this glyph
BAR_BLOCKS = 12  # blocks of a full bar, which fit half of a narrow sidebar

# Cycles settings that bias the image by design (clamping, Filter Glossy, caustics off, Fast GI), as overrides.
OVERRIDE_PRESETS = (
    ("cycles.sample_clamp_indirect=0", "Indirect Light Clamp Off"),
    ("cycles.sample_clamp_direct=0", "Direct Light Clamp Off"),
    ("cycles.blur_glossy=0", "Filter Glossy Off"),
    ("cycles.caustics_reflective=True", "Reflective Caustics On"),
    ("cycles.caustics_refractive=True", "Refractive Caustics On"),
    ("cycles.use_fast_gi=False", "Fast GI Off"),
)


def subpanel(layout, idname: str, title: str, default_closed: bool = False):
    """A collapsible sub-panel (Blender 4.1+), else a box with a heading; returns its body or None if closed."""
    if hasattr(layout, "panel"):
        header, body = layout.panel(idname, default_closed=default_closed)
        header.label(text=title)
        return body
    box = layout.box()
    box.label(text=title)
    return box


def progress_bar(layout, factor: float, text: str, header: bool = False) -> None:
    """A progress bar (Blender 4.0+); before, the text next to a bar of block characters, or in a header (which
    gives items the width of their text) the text and the percentage."""
    if hasattr(layout, "progress"):
        layout.progress(factor=factor, type="BAR", text=text)
    elif header:
        layout.label(text=f"{text} ({factor:.0%})", icon="TIME")
    else:
        split = layout.split(factor=0.55)
        split.label(text=text)
        split.label(text=BAR_BLOCK * round(min(max(factor, 0.0), 1.0) * BAR_BLOCKS))


def draw_overrides(layout, settings) -> None:
    col = layout.column(align=True)
    for index, item in enumerate(settings.overrides):
        row = col.row(align=True)
        row.prop(item, "enabled", text="")
        row.prop(item, "text", text="")
        row.operator("welch_bias.override_remove", text="", icon="X").index = index
    row = col.row(align=True)
    row.operator("welch_bias.override_add", text="Add Override", icon="ADD")
    row.menu("WELCH_BIAS_MT_override_presets", text="", icon="PRESET")


def draw_setup(layout, settings) -> None:
    layout.prop(settings, "mode")
    if settings.mode == "STATS_FILES":
        layout.prop(settings, "reference_file")
        layout.prop(settings, "test_file")
        layout.prop(settings, "alpha")
        return
    if settings.mode == "TWO_SCENES":
        layout.prop(settings, "reference_scene")
        layout.prop(settings, "test_scene")
    body = subpanel(layout, "welch_bias_overrides", f"Test Side Overrides ({len(settings.overrides)})")
    if body is not None:
        draw_overrides(body, settings)
    col = layout.column()
    col.prop(settings, "max_passes")
    col.prop(settings, "tolerance")
    col.prop(settings, "spp")
    col.prop(settings, "paired")
    col.prop(settings, "seed_offset")
    col.prop(settings, "tile")
    col.prop(settings, "device")
    col.prop(settings, "use_lobes")
    col.prop(settings, "alpha")
    col.prop(settings, "test_build")


def draw_run(layout, context, settings) -> None:
    session = current.session
    if current.running():
        row = layout.row(align=True)
        progress_bar(row, session.fraction, session.status_text())
        row.operator("welch_bias.cancel", text="", icon="CANCEL")
        return
    row = layout.row(align=True)
    row.scale_y = 1.4
    text = "Compare Files" if settings.mode == "STATS_FILES" else "Run"
    row.operator("welch_bias.run", text=text, icon="PLAY")
    resumable = current.resumable
    if resumable is not None and settings.mode != "STATS_FILES":
        if resumable.key == settings_key(settings, context.scene):
            row.operator("welch_bias.run", text="Resume", icon="FILE_REFRESH").resume = True
    if session is not None and session.state == runner.CANCELLED:
        layout.label(text=session.status_text(), icon="INFO")
    if current.last_error:
        box = layout.box()
        box.alert = True
        box.label(text=current.last_error, icon="ERROR")


#: Characters of the verdict's sentence on one line of a panel in the default layout.
SENTENCE_WIDTH = 44


def draw_verdict(layout, result) -> None:
    """The verdict's title, its sentence (the one every presenter shows: batch.present.words) and the design."""
    box = layout.box()
    row = box.row()
    row.alert = result["verdict"] == "biased"
    row.label(text=result["verdict_title"], icon=result["verdict_icon"])
    for line in textwrap.wrap(result["sentence"], SENTENCE_WIDTH):
        box.label(text=line)
    for line in textwrap.wrap(result["design"], SENTENCE_WIDTH):
        box.label(text=line)
    tiles = result["tiles"]
    box.label(text=f"Tiles: {tiles['valid']} of {tiles['total']} valid, {tiles['used']} used")
    box.label(text=f"Outlined (the verdict's test found them or a tile around them): {tiles['significant']}")
    box.label(text=f"Passes: {result['n_ref']} reference, {result['n_test']} test")
    for reason, count in result["excluded"].items():
        box.label(text=f"Excluded tile-channels, {reason}: {count}")
    for note in result["notes"]:
        box.label(text=note, icon="INFO")
    for warning in result["warnings"]:
        box.label(text=warning, icon="ERROR")
    for layer in result.get("layers", []):
        box.label(text=f"{layer['name']}: {layer['title']}", icon="ERROR" if layer["verdict"] == "biased" else "DOT")


def draw_display(layout, settings) -> None:
    col = layout.column()
    if current.layers:
        col.prop(settings, "component")
    col.prop(settings, "map_mode")
    if settings.map_mode == "CHANNEL":
        col.prop(settings, "channel")
    col.prop(settings, "show_overlay")
    col.prop(settings, "opacity", slider=True)
    if current.overlay_error:
        col.label(text=f"Overlay unavailable: {current.overlay_error}", icon="ERROR")
    col.operator("welch_bias.show_result", icon="IMAGE_DATA")


def draw_histogram(layout, result) -> None:
    col = layout.column(align=True)
    for bar in result["histogram"]:
        progress_bar(col, bar["fill"], f"p {bar['label']}: {bar['count']}")
    layout.label(text=f"Flat at {result['histogram_expected']:.1f} tiles per bin if unbiased")


def draw_top_tiles(layout, result) -> None:
    if not result["top_tiles"]:
        layout.label(text="No testable tiles")
        return
    for tile in result["top_tiles"]:
        row = layout.row(align=True)
        size = (
            f"{tile['size']}x{tile['size']} " if tile.get("decided") else ""
        )  # saved results of earlier versions lack it
        text = f"{size}({tile['x']}, {tile['y']}) {tile['channel']} p {fmt.p_value(tile['pvalue'])}"
        op = row.operator("welch_bias.frame_tile", text=text, icon="ZOOM_SELECTED")
        op.row, op.col = tile["row"], tile["col"]
        interval = f"[{fmt.percent(tile['ci_low'], 1)}, {fmt.percent(tile['ci_high'], 1)}]"
        row.label(text=f"{fmt.percent(tile['rel_diff'], 1)} {interval}")


def draw_result(layout, settings, scene=None) -> None:
    result = current.result
    if result is None:
        layout.label(text="No result yet")
        return
    if result.get("saved"):
        layout.label(text="Saved with the file (run again for the map)", icon="FILE_TICK")
    key = current.run.key if current.run is not None and not result.get("saved") else settings.last_result_key
    if scene is not None and key and str(key) != str(settings_key(settings, scene)) and not current.running():
        box = layout.box()
        box.alert = True
        box.label(text="Stale: the settings changed since this result", icon="ERROR")
    draw_verdict(layout, result)
    draw_display(layout, settings)
    for idname, title, draw in (
        ("welch_bias_histogram", "P-Value Histogram", draw_histogram),
        ("welch_bias_top_tiles", "Most Significant Tiles", draw_top_tiles),
    ):
        body = subpanel(layout, idname, title)
        if body is not None:
            draw(body, result)
    if result["differences"]:
        body = subpanel(layout, "welch_bias_differences", "Recorded Differences", default_closed=True)
        if body is not None:
            for line in result["differences"]:
                body.label(text=line)


class WELCH_BIAS_MT_override_presets(bpy.types.Menu):
    bl_label = "Override Presets"

    def draw(self, _context):
        for text, label in OVERRIDE_PRESETS:
            self.layout.operator("welch_bias.override_add", text=label).text = text


def draw_panel(layout, context, setup: bool) -> None:
    """The add-on's panel: the setup (in the Properties editor), the run and its result."""
    layout.use_property_split = True
    layout.use_property_decorate = False
    settings = context.scene.welch_bias
    if setup:
        draw_setup(layout, settings)
    draw_run(layout, context, settings)
    draw_result(layout, settings, context.scene)


class WELCH_BIAS_PT_render(bpy.types.Panel):
    """The setup, the run and its result, in Properties > Render."""

    bl_label = "Welch Bias Test"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {"CYCLES"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        draw_panel(self.layout, context, setup=True)


class WELCH_BIAS_PT_image_editor(bpy.types.Panel):
    """The run and its result beside the image, in the Image Editor's sidebar."""

    bl_label = "Welch Bias Test"
    bl_space_type = "IMAGE_EDITOR"
    bl_region_type = "UI"
    bl_category = SIDEBAR_TAB

    def draw(self, context):
        draw_panel(self.layout, context, setup=False)


def draw_status(self, _context):
    """Progress in the status bar while a run goes on, so it is visible from any editor."""
    if current.running():
        row = self.layout.row(align=True)
        progress_bar(row, current.session.fraction, current.session.status_text(), header=True)
        row.operator("welch_bias.cancel", text="", icon="CANCEL")


def draw_image_header(self, context):
    """The verdict in the header of an Image Editor showing the map, so it is read without opening the sidebar
    (Blender 3.4 opens the sidebar on the tab it last showed)."""
    result, space = current.result, context.space_data
    image = getattr(space, "image", None)
    if result is None or image is None or image.name != result["image"]:
        return
    row = self.layout.row()
    row.alert = result["verdict"] == "biased"
    row.label(text=headline(result), icon=result["verdict_icon"])


def headline(result) -> str:
    """The verdict's title and the first clause of its sentence (what it claims, with its numbers)."""
    sentence = result["sentence"]
    claim = sentence.split(": ", 1)[1] if ": " in sentence else ""
    return f"{result['verdict_title']}: {claim.split('; ', 1)[0]}" if claim else result["verdict_title"]


classes = (WELCH_BIAS_MT_override_presets, WELCH_BIAS_PT_render, WELCH_BIAS_PT_image_editor)

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(classes)


def register():
    _register_classes()
    bpy.types.STATUSBAR_HT_header.append(draw_status)
    bpy.types.IMAGE_HT_header.append(draw_image_header)


def unregister():
    bpy.types.IMAGE_HT_header.remove(draw_image_header)
    bpy.types.STATUSBAR_HT_header.remove(draw_status)
    _unregister_classes()
