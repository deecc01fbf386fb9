"""Scene settings: what the reference and test sides are, the budget and tolerance of the check, and how the
result is shown. The defaults and limits of the check's settings are the command line's (``python -m batch check``),
read from their declaration (`batch.jobs.options`); the soft limits (a slider's range) are the panel's own.

Only the setup lives here (it is saved with the file); the running job and the last result are module state in
``state.py`` so nothing transient ends up in the user's file.
"""

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from ._siblings import options

MODES = (
    (
        "CURRENT_WITH_OVERRIDES",
        "Overrides",
        "This scene against itself with the property overrides below applied to the test side",
    ),
    ("TWO_SCENES", "Two Scenes", "One scene of this file as reference, another as test"),
    ("STATS_FILES", "Statistics Files", "Compare two statistics files already on disk"),
)

MAP_MODES = (
    ("MIN", "Smallest P", "Smallest p-value of the three channels of each tile"),
    ("CHANNEL", "One Channel", "P-values of one colour channel"),
    ("SQRT", "Square Root", "Square root of the smallest p-value, more colours for small p"),
    ("LOG10", "Log Scale", "Minus log10 of the smallest p-value, saturating at 1e-8"),
    ("Q", "Q-Values", "Benjamini-Hochberg q-values of the tiles"),
    ("SIGNIFICANT", "Significant Only", "Colour only the tiles significant after multiple-testing correction"),
)

CHANNELS = (("R", "Red", "Red channel"), ("G", "Green", "Green channel"), ("B", "Blue", "Blue channel"))


def _declared(dest: str, percent: bool = False) -> dict:
    """The default and the limits `batch.jobs.options` declares for the option `dest` at ``addon``, as a
    property's keywords (`percent`: a fraction shown in percent). A limit the option excludes (alpha's 0 and 1) is
    left to the property, which can only include its limits; an option the panel takes as ``auto`` is 0 there,
    its default."""
    option = options.OPTIONS[dest]
    scale = 100.0 if percent else 1
    found = {"default": option.default_for("addon") * scale if percent else option.default_for("addon")}
    if option.use("addon").auto:
        found = {"default": 0, "min": 0}
    elif option.low is not None and not option.open_low:
        found["min"] = option.low * scale
    if option.high is not None and not option.open_high:
        found["max"] = option.high * scale
    return found


def _refresh_result(_self, context):
    # Display settings only re-colour the cached comparison; nothing is rendered again.
    from . import results  # imported when a result exists, not when the add-on registers

    results.refresh(context)


#: The Component menu's items; kept here because Blender does not keep a dynamic enum's strings alive.
_component_items: list[tuple[str, str, str]] = []


def _components(_self, _context):
    from .state import current

    _component_items[:] = [("COMBINED", "Image", "The rendered image (Combined)")] + [
        (name, name.replace("lightgroup:", "Light Group: ").title(), f"The {name} layer of both runs")
        for name in current.layers
    ]
    return _component_items


def _redraw_overlay(_self, context):
    from . import overlay

    overlay.tag_redraw(context)


class WELCH_BIAS_PG_override(bpy.types.PropertyGroup):
    text: StringProperty(
        name="Override",
        description="Property path relative to the scene or bpy.data and its value, e.g. "
        "cycles.sample_clamp_indirect=0",
        default="",
    )
    enabled: BoolProperty(name="Enabled", description="Apply this override to the test side", default=True)


class WELCH_BIAS_PG_settings(bpy.types.PropertyGroup):
    mode: EnumProperty(name="Compare", description="What the reference and test sides are", items=MODES)
    overrides: CollectionProperty(type=WELCH_BIAS_PG_override)
    reference_scene: PointerProperty(
        name="Reference Scene", description="Scene rendered as the reference side", type=bpy.types.Scene
    )
    test_scene: PointerProperty(name="Test Scene", description="Scene rendered as the test side", type=bpy.types.Scene)
    reference_file: StringProperty(
        name="Reference Statistics", description="Statistics file of the reference side", subtype="FILE_PATH"
    )
    test_file: StringProperty(
        name="Test Statistics", description="Statistics file of the test side", subtype="FILE_PATH"
    )
    max_passes: IntProperty(
        name="Max Passes",
        description="The most independent renders a side (each with its own seed): the run stops as soon as the "
        "data decide, and says what it rules out when it reaches this",
        **_declared("max_passes"),
        soft_max=4096,
    )
    tolerance: FloatProperty(
        name="Tolerance %",
        description="Stop at Equivalent once every tile of the size the budget can bound is within this relative "
        "difference of the reference (0: stop only at Biased)",
        **_declared("tolerance", percent=True),
        min=0.0,  # off, as the command line's `--tolerance off`
        max=options.OPTIONS["tolerance"].high * 100.0,  # excluded: refused when a run starts
        soft_max=10.0,
        precision=2,
        step=10,
    )
    paired: BoolProperty(
        name="Paired",
        description="Render both sides with the same seeds and test per-pass differences (more sensitive; off: "
        "disjoint seeds, an A/A check)",
        default=True,
    )
    test_build: StringProperty(
        name="Test Build",
        description="Render the test side with another build: a Blender binary, or a Python whose environment has "
        "another release's bpy (python -m batch bpy VERSION makes one). Empty: this Blender",
        default="",
        subtype="FILE_PATH",
    )
    spp: IntProperty(
        name="Samples per Pass",
        description="Cycles samples of each pass. 0: Auto, 1 unless the sides differ in a setting that acts only "
        "above some samples per render (path guiding, a blue-noise pattern), then the scene's own samples",
        **_declared("spp"),
        soft_max=64,
    )
    seed_offset: IntProperty(
        name="Seed Offset",
        description="Shift both sides' seeds: the same check on other passes, an independent second answer",
        **_declared("seed_offset"),
        soft_max=1_000_000,
    )
    tile: IntProperty(
        name="Tile Size",
        description="Edge of the finest square pixel tiles tested (their 2x2, 4x4, ... blocks are tested too)",
        **_declared("tile"),
        soft_min=2,
        soft_max=256,
    )
    device: EnumProperty(
        name="Device",
        description="Cycles device of the background renders",
        items=(("CPU", "CPU", "Render on the CPU"), ("GPU", "GPU", "Render on the GPU set in the preferences")),
        **_declared("device"),
    )
    alpha: FloatProperty(
        name="Alpha",
        description="Significance level of the test (probability of a false alarm on an unbiased renderer)",
        **_declared("alpha"),
        min=1e-6,  # the panel's own limits, inside the declared (0, 1)
        max=0.5,
        precision=4,
        step=0.1,
    )
    map_mode: EnumProperty(
        name="Map", description="Which values colour the tiles", items=MAP_MODES, update=_refresh_result
    )
    channel: EnumProperty(
        name="Channel", description="Channel shown by the One Channel map", items=CHANNELS, update=_refresh_result
    )
    component: EnumProperty(
        name="Component",
        description="Which layer's p-values the map shows: the image, or a light component or light group "
        "(rendered with Light Components on)",
        items=_components,
        update=_refresh_result,
    )
    use_lobes: BoolProperty(
        name="Light Components",
        description="Also render the light components (diffuse, glossy, transmission, volume, emission, "
        "environment) and the scene's light groups, and test each; slower passes",
        default=False,
    )
    show_overlay: BoolProperty(
        name="Show Overlay",
        description="Draw the p-value map over the image in every Image Editor that shows a render of this size",
        default=True,
        update=_redraw_overlay,
    )
    opacity: FloatProperty(
        name="Opacity",
        description="Opacity of the p-value map, in the result image and in the overlay",
        default=0.4,
        min=0.0,
        max=1.0,
        subtype="FACTOR",
        update=_refresh_result,
    )

    last_result: StringProperty(
        name="Last Result",
        description="The summary of the last finished run, kept with the file",
        default="",
        options={"HIDDEN"},
    )
    last_result_key: StringProperty(
        name="Last Result Settings",
        description="The settings the last result was made with (a changed one makes it stale)",
        default="",
        options={"HIDDEN"},
    )

    def enabled_overrides(self) -> list[str]:
        return [o.text.strip() for o in self.overrides if o.enabled and o.text.strip()]


classes = (WELCH_BIAS_PG_override, WELCH_BIAS_PG_settings)

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(classes)


def register():
    _register_classes()
    bpy.types.Scene.welch_bias = PointerProperty(type=WELCH_BIAS_PG_settings)


def unregister():
    del bpy.types.Scene.welch_bias
    _unregister_classes()
