"""The overlay inside the bpy module: its vertices (tile positions, colours, outlines), which images it covers,
the draw handler's registration, and how a draw that fails degrades. Drawing itself needs a GPU context, which
the bpy module never has: tests/addon/test_gui.py looks at it in a real Blender window."""

import dataclasses
import sys
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import blender_addon  # noqa: E402
import welch_core  # noqa: E402
from batch.present.pipeline import assess  # noqa: E402
from blender_addon import overlay, results, ui  # noqa: E402
from blender_addon.state import current as state  # noqa: E402
from tests.helpers.synthetic import grey_stats  # noqa: E402

SIZE = 64
TILE = 16


pytestmark = pytest.mark.usefixtures("addon")  # registered for the module (tests/addon/conftest.py)


@pytest.fixture
def settings():
    scene = bpy.context.scene
    saved = {name: getattr(scene.welch_bias, name) for name in ("map_mode", "channel", "opacity", "show_overlay")}
    state.reset()
    yield scene.welch_bias
    for name, value in saved.items():
        setattr(scene.welch_bias, name, value)
    state.reset()


def biased_comparison(width=SIZE, height=SIZE):
    reference = grey_stats(range(0, 16), width=width, height=height, seed=1)
    test = grey_stats(range(16, 32), bias=0.3, width=width, height=height, seed=2)
    return welch_core.compare(reference, test, alpha=0.01), reference, test


def tile_colors(geometry):
    """One RGBA per tile (every vertex of a tile has the same colour)."""
    colors = geometry.colors.reshape(-1, len(overlay.TRIANGLES), 4)
    assert (colors == colors[:, :1]).all()
    return colors[:, 0]


def test_tile_rects_put_row_0_at_the_top():
    rects = overlay.tile_rects(2, 3, 16, 50, 40)  # a file without partial tiles: the edge is not covered
    assert rects.shape == (6, 4) and rects.dtype == np.float32
    np.testing.assert_allclose(rects[0], [0.0, 1.0 - 16 / 40, 16 / 50, 1.0])  # top-left tile
    np.testing.assert_allclose(rects[5], [32 / 50, 1.0 - 32 / 40, 48 / 50, 1.0 - 16 / 40])  # bottom-right
    partial = overlay.tile_rects(3, 4, 16, 50, 40)  # the partial tiles end at the image's edges
    np.testing.assert_allclose(partial[-1], [48 / 50, 0.0, 1.0, 1.0 - 32 / 40])


def test_geometry_colours_tiles_by_p_value_and_outlines_the_significant_ones():
    comparison, _, _ = biased_comparison()
    geometry = overlay.tile_geometry(comparison, "MIN", "R", 0.6)
    tiles = (SIZE // TILE) ** 2
    assert geometry.positions.shape == (6 * tiles, 2) and geometry.colors.shape == (6 * tiles, 4)
    assert geometry.positions.dtype == geometry.colors.dtype == geometry.outline.dtype == np.float32
    assert geometry.positions.flags.c_contiguous and geometry.colors.flags.c_contiguous
    colors = tile_colors(geometry)
    np.testing.assert_allclose(colors[:, :3], welch_core.pvalue_rgb(comparison).reshape(-1, 3))
    np.testing.assert_allclose(colors[:, 3], np.where(comparison.used.ravel(), 0.6, 0.0))
    # Two triangles per tile cover its rect exactly: the first tile is the top-left one.
    first = geometry.positions[:6]
    assert (first.min(axis=0).tolist(), first.max(axis=0).tolist()) == ([0.0, 0.75], [0.25, 1.0])
    # Outlines: four segments around each significant tile, all in the biased top-left quarter.
    significant = int(comparison.significant.sum())
    assert significant > 0 and geometry.outline.shape == (8 * significant, 2)
    assert (geometry.outline[:, 0] <= 0.5).all() and (geometry.outline[:, 1] >= 0.5).all()
    top_left = colors.reshape(SIZE // TILE, SIZE // TILE, 4)[0, 0]
    bottom_right = colors.reshape(SIZE // TILE, SIZE // TILE, 4)[-1, -1]
    assert top_left[0] > 0.9 and top_left[2] < 0.2  # viridis yellow: small p
    assert bottom_right[0] < top_left[0] - 0.3  # towards violet: no bias there


def test_geometry_leaves_unused_tiles_clear():
    comparison, _, _ = biased_comparison()
    trusted = np.ones_like(comparison.trusted)
    trusted[0, 1] = False  # as when a tile's passes are far from normal (fireflies)
    untrusted = dataclasses.replace(comparison, trusted=trusted)
    alpha = tile_colors(overlay.tile_geometry(untrusted, "MIN", "R", 1.0))[:, 3].reshape(trusted.shape)
    assert alpha[0, 1] == 0.0 and (alpha[trusted] == 1.0).all()
    significant_only = tile_colors(overlay.tile_geometry(comparison, "SIGNIFICANT", "R", 1.0))[:, 3]
    np.testing.assert_array_equal(significant_only, comparison.significant.ravel().astype(np.float32))


def test_geometry_of_one_channel_and_of_an_incomplete_edge():
    comparison, _, _ = biased_comparison(width=70, height=50)  # 4 x 3 whole tiles and partial ones: 5 x 4
    geometry = overlay.tile_geometry(comparison, "CHANNEL", "G", 0.5)
    assert geometry.positions.shape == (6 * 20, 2) and (geometry.width, geometry.height) == (70, 50)
    assert geometry.positions[:, 0].max() == pytest.approx(1.0)  # the partial tiles reach the edges
    assert geometry.positions[:, 1].min() == pytest.approx(0.0)
    np.testing.assert_allclose(
        tile_colors(geometry)[:, :3], welch_core.pvalue_rgb(comparison, "channel", 1).reshape(-1, 3)
    )


def test_the_overlay_covers_renders_of_the_compared_shape_only():
    comparison, _, _ = biased_comparison(width=64, height=32)
    geometry = overlay.tile_geometry(comparison, "MIN", "R", 0.6)
    scene = bpy.context.scene

    def image(width, height, kind="IMAGE", ours=False):
        return SimpleNamespace(size=(width, height), type=kind, get={results.IMAGE_TAG: True}.get if ours else {}.get)

    assert overlay.covers(image(64, 32), geometry, scene)
    assert overlay.covers(image(128, 64), geometry, scene)  # a render at another resolution percentage
    assert not overlay.covers(image(64, 64), geometry, scene)
    assert not overlay.covers(image(64, 32, ours=True), geometry, scene)  # the map image has the map already
    assert not overlay.covers(image(0, 0), geometry, scene)
    assert not overlay.covers(None, geometry, scene)
    # The Render Result reads 0 x 0 from Python: the scene's render size decides.
    saved = scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage
    try:
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 640, 320, 50
        assert overlay.covers(image(0, 0, "RENDER_RESULT"), geometry, scene)
        scene.render.resolution_y = 480
        assert not overlay.covers(image(0, 0, "RENDER_RESULT"), geometry, scene)
    finally:
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = saved


def test_display_settings_rebuild_the_vertices_at_once(settings, tmp_path):
    comparison, reference, test = biased_comparison()
    results.store(assess(comparison, reference, test), reference, test, {"reference": "r.npz", "test": "t.npz"})
    results.refresh(bpy.context)
    geometry = state.overlay
    assert isinstance(geometry, overlay.Geometry) and state.overlay_batches is None
    state.overlay_batches = "uploaded"  # what the first draw leaves
    settings.opacity = 0.25
    assert state.overlay is not geometry and state.overlay_batches is None  # re-faded; uploaded again on draw
    assert set(tile_colors(state.overlay)[:, 3]) <= {0.0, 0.25}
    settings.map_mode = "SIGNIFICANT"
    assert tile_colors(state.overlay)[:, 3].sum() == pytest.approx(0.25 * comparison.significant.sum())
    kept = state.overlay
    settings.show_overlay = False  # only a redraw: the vertices stay
    assert state.overlay is kept
    state.clear_result()
    assert state.overlay is None and state.overlay_batches is None


def test_the_draw_handler_lives_while_the_addon_is_registered():
    assert overlay._handle is not None
    blender_addon.unregister()
    try:
        assert overlay._handle is None
    finally:
        blender_addon.register()
    assert overlay._handle is not None


def test_a_failing_draw_is_reported_once_and_shown_in_the_panel(settings, capsys):
    comparison, reference, test = biased_comparison()
    results.store(assess(comparison, reference, test), reference, test, {"reference": "r.npz", "test": "t.npz"})
    results.refresh(bpy.context)
    overlay.draw()  # no Image Editor in the context: nothing to do
    assert state.overlay_error == ""
    area = next(a for a in bpy.context.screen.areas if a.type == "VIEW_3D")
    area.type = "IMAGE_EDITOR"
    try:
        other = bpy.data.images.new("Welch Overlay Test", SIZE, SIZE)
        area.spaces.active.image = other
        region = next(r for r in area.regions if r.type == "WINDOW")
        with bpy.context.temp_override(area=area, region=region, space_data=area.spaces.active):
            overlay.draw()  # the bpy module has no GPU: the draw fails like a missing shader would
            assert state.overlay_error.startswith("SystemError: ") and "\n" not in state.overlay_error
            overlay.draw()
        printed = capsys.readouterr().out
        assert printed.count("the overlay can't be drawn") == 1
        assert display_texts(settings) == [f"Overlay unavailable: {state.overlay_error}"]
        settings.opacity = 0.5  # a new geometry tries again
        assert state.overlay_error == ""
    finally:
        area.type = "VIEW_3D"
        bpy.data.images.remove(other)


def display_texts(settings):
    """Labels of the panel's display section, drawn through a stand-in that records them."""
    texts = []

    class Layout:
        def column(self):
            return self

        def prop(self, *_args, **_kw):
            pass

        def operator(self, *_args, **_kw):
            pass

        def label(self, text="", icon="NONE"):
            texts.append(text)

    ui.draw_display(Layout(), settings)
    return texts


def test_shaders_are_found_by_their_name_in_this_blender(monkeypatch):
    calls = []

    def from_builtin(name):
        calls.append(name)
        if name.startswith("2D_"):  # Blender 4.0 and later
            raise ValueError(f"expected a string in ('FLAT_COLOR', ...), got {name!r}")
        return f"shader {name}"

    monkeypatch.setitem(sys.modules, "gpu", SimpleNamespace(shader=SimpleNamespace(from_builtin=from_builtin)))
    assert overlay.builtin_shader(overlay.FLAT_COLOR_SHADERS) == "shader FLAT_COLOR"
    assert calls == ["2D_FLAT_COLOR", "FLAT_COLOR"]
    with pytest.raises(RuntimeError, match="none of the shaders 2D_NOPE"):
        overlay.builtin_shader(("2D_NOPE",))


def test_a_run_keeps_a_render_under_the_overlay_on_screen(settings, tmp_path, monkeypatch):
    from blender_addon import operators

    reference, test = tmp_path / "ref.npz", tmp_path / "test.npz"
    welch_core.save_stats(reference, grey_stats(range(0, 16), seed=3))
    welch_core.save_stats(test, grey_stats(range(16, 32), bias=0.3, seed=4))
    area = next(a for a in bpy.context.screen.areas if a.type == "VIEW_3D")
    area.type = "IMAGE_EDITOR"
    render = bpy.data.images.new("Welch Overlay Render", SIZE, SIZE)
    try:
        area.spaces.active.image = render
        operators.compare_and_show(bpy.context, str(reference), str(test), 0.01)
        assert area.spaces.active.image.name == state.result["image"]  # background: no overlay is ever drawn
        assert not overlay.shown_anywhere(bpy.context)

        monkeypatch.setattr(overlay, "bpy", SimpleNamespace(app=SimpleNamespace(background=False)))
        area.spaces.active.image = render
        assert overlay.shown_anywhere(bpy.context)
        operators.compare_and_show(bpy.context, str(reference), str(test), 0.01)
        assert area.spaces.active.image == render  # the map is drawn over it: it stays
        settings.show_overlay = False
        assert not overlay.shown_anywhere(bpy.context)
        settings.show_overlay = True
        render.scale(SIZE, SIZE // 2)
        assert not overlay.shown_anywhere(bpy.context)
    finally:
        area.type = "VIEW_3D"
        bpy.data.images.remove(render)
