"""The add-on inside the bpy module: registration, settings, checks, operators on statistics files, result image,
and every panel state drawn through a recording layout."""

import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import blender_addon  # noqa: E402
import welch_core  # noqa: E402
from batch.decide.check_job import UNPAIRED_SEEDS  # noqa: E402
from blender_addon import checks, results, runner, session, ui  # noqa: E402
from blender_addon.state import RunFolder  # noqa: E402
from blender_addon.state import current as state  # noqa: E402
from tests.helpers.synthetic import write_grey_stats  # noqa: E402

SIZE = 64
TILE = 16


pytestmark = pytest.mark.usefixtures("addon")  # registered for the module (tests/addon/conftest.py)


@pytest.fixture
def scene():
    """A fresh scene with a camera, made the window's scene; removed afterwards."""
    window = bpy.context.window
    previous = window.scene
    new = bpy.data.scenes.new("Welch Test Scene")
    camera = bpy.data.objects.new("Welch Camera", bpy.data.cameras.new("Welch Camera"))
    new.collection.objects.link(camera)
    new.camera = camera
    new.render.resolution_x = new.render.resolution_y = SIZE
    new.render.resolution_percentage = 100
    new.render.engine = "CYCLES"
    window.scene = new
    state.clear_result()
    state.reset()
    yield new
    window.scene = previous
    bpy.data.scenes.remove(new)
    bpy.data.objects.remove(camera)


def read_pixels(image):
    """The image's pixels as height x width x 4, bottom row first (Blender's order)."""
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    return pixels.reshape(image.size[1], image.size[0], 4)


# -- a recording stand-in for UILayout -----------------------------------------------------------------------

ICONS = set(bpy.types.UILayout.bl_rna.functions["label"].parameters["icon"].enum_items.keys())


def check_call(function, **kw):
    """The keywords must be parameters of UILayout's RNA function, so a call that works here works in Blender."""
    parameters = set(bpy.types.UILayout.bl_rna.functions[function].parameters.keys())
    assert set(kw) <= parameters, (function, set(kw) - parameters)


class FakeOperatorProperties:
    """Accepts only the properties the operator really has."""

    def __init__(self, idname):
        category, name = idname.split(".")
        self._names = set(getattr(getattr(bpy.ops, category), name).get_rna_type().properties.keys())

    def __setattr__(self, name, value):
        if not name.startswith("_") and name not in self._names:
            raise AttributeError(f"operator has no property {name!r}")
        object.__setattr__(self, name, value)


class FakeLayout:
    """Records every call; sub-layouts share the record. Checks property names, operators and icons."""

    def __init__(self, calls=None):
        self.calls = [] if calls is None else calls

    def _child(self, kind, **kw):
        check_call(kind, **kw)
        self.calls.append((kind, kw))
        return type(self)(self.calls)

    def row(self, **kw):
        return self._child("row", **kw)

    def column(self, **kw):
        return self._child("column", **kw)

    def box(self):
        return self._child("box")

    def split(self, **kw):
        return self._child("split", **kw)

    def panel(self, idname, default_closed=False):
        check_call("panel", idname=idname, default_closed=default_closed)
        self.calls.append(("panel", {"idname": idname}))
        return FakeLayout(self.calls), FakeLayout(self.calls)

    def label(self, text="", icon="NONE"):
        assert icon in ICONS, icon
        self.calls.append(("label", {"text": text, "icon": icon}))

    def prop(self, data, prop, **kw):
        check_call("prop", **kw)
        assert prop in data.bl_rna.properties.keys(), prop
        self.calls.append(("prop", {"prop": prop, **kw}))

    def operator(self, idname, text="", icon="NONE"):
        assert icon in ICONS, icon
        props = FakeOperatorProperties(idname)
        self.calls.append(("operator", {"idname": idname, "text": text, "props": props}))
        return props

    def menu(self, menu, text="", icon="NONE"):
        assert icon in ICONS and issubclass(getattr(bpy.types, menu), bpy.types.Menu), menu
        self.calls.append(("menu", {"menu": menu}))

    def progress(self, factor=0.0, type="BAR", text=""):
        assert 0.0 <= factor <= 1.0 and type in {"BAR", "RING"}
        self.calls.append(("progress", {"factor": factor, "text": text}))

    def texts(self):
        return [kw["text"] for kind, kw in self.calls if kind == "label"]

    def operators(self):
        return [kw for kind, kw in self.calls if kind == "operator"]


class FakeLayout34(FakeLayout):
    """UILayout of Blender 3.4: no ``panel`` (4.1+) and no ``progress`` (4.0+)."""

    def __getattribute__(self, name):
        if name in {"panel", "progress"}:
            raise AttributeError(f"'UILayout' object has no attribute {name!r}")
        return super().__getattribute__(name)


def draw_panel(layout_type=FakeLayout, setup=True):
    layout = layout_type()
    ui.draw_panel(layout, bpy.context, setup)
    return layout


# -- registration and settings -------------------------------------------------------------------------------


def test_register_and_unregister_twice():
    for _ in range(2):
        blender_addon.unregister()
        assert not hasattr(bpy.types.Scene, "welch_bias")
        assert not hasattr(bpy.types, "WELCH_BIAS_PT_render")
        blender_addon.register()
        assert hasattr(bpy.types.Scene, "welch_bias")
        assert bpy.ops.welch_bias.run.idname() == "WELCH_BIAS_OT_run"
        assert ui.draw_status in bpy.types.STATUSBAR_HT_header._dyn_ui_initialize()


def test_settings_defaults_and_limits(scene):
    settings = scene.welch_bias
    # The command line's defaults (python -m batch check).
    assert (settings.mode, settings.max_passes, settings.tile, settings.paired) == ("CURRENT_WITH_OVERRIDES", 512, 16,
                                                                                   True)  # fmt: skip
    assert settings.tolerance == pytest.approx(1.0) and settings.test_build == ""
    assert session.alpha_of(settings) == 0.01  # a single-precision property, rounded before use
    settings.max_passes = 1
    settings.alpha = 0.9
    settings.opacity = 2.0
    assert (settings.max_passes, settings.alpha, settings.opacity) == (2, 0.5, 1.0)
    with pytest.raises(TypeError):
        settings.mode = "current"  # identifiers are upper case
    bpy.ops.welch_bias.override_add(text=" cycles.blur_glossy=0 ")
    bpy.ops.welch_bias.override_add(text="")
    bpy.ops.welch_bias.override_add(text="cycles.caustics_reflective=False")
    settings.overrides[2].enabled = False
    assert settings.enabled_overrides() == ["cycles.blur_glossy=0"]
    bpy.ops.welch_bias.override_remove(index=1)
    assert [o.text for o in settings.overrides] == [" cycles.blur_glossy=0 ", "cycles.caustics_reflective=False"]
    with pytest.raises(RuntimeError, match="No override number 5"):
        bpy.ops.welch_bias.override_remove(index=4)


def test_the_panel_asks_for_the_check_the_command_line_describes(scene, tmp_path):
    """The panel's defaults are the check's (`CheckRequest`), and its request makes the very job that the command
    line's arguments for the same settings make."""
    from batch.cli.commands import build_parser
    from batch.decide.check_job import CheckRequest, check_job, check_job_from_args

    settings = scene.welch_bias
    declared = CheckRequest(out="")
    assert (settings.spp or None, settings.tile, settings.device) == (declared.spp, declared.tile, declared.device)
    assert settings.seed_offset == declared.seed_offset
    assert (session.alpha_of(settings), settings.tolerance / 100) == (declared.alpha, pytest.approx(declared.tolerance))
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER")  # the request checks that the file exists; nothing renders here
    bpy.ops.welch_bias.override_add(text="cycles.blur_glossy=0")
    settings.max_passes, settings.spp, settings.tolerance, settings.paired = 64, 2, 0.5, False
    settings.test_build, settings.seed_offset = "/opt/blender-5.2/blender", 7
    request = session.check_request(settings, scene, str(blend), tmp_path / "run", False, "/usr/bin/blender")
    argv = ["check", str(blend), "--blend-scene", scene.name, "--out", str(tmp_path / "run"), "--spp", "2",
            "--tile", str(settings.tile), "--device", "CPU", "--alpha", "0.01", "--max-passes", "64",
            "--tolerance", "0.5%", "--set", "cycles.blur_glossy=0", "--blender", "/usr/bin/blender",
            "--test-blender", "/opt/blender-5.2/blender", "--unpaired", "--seed-offset", "7"]  # fmt: skip
    job = check_job(request)
    assert job == check_job_from_args(build_parser().parse_args(argv))
    assert (job.seed_offset, job.reference.seeds[0], job.test.seeds[0]) == (7, 7, UNPAIRED_SEEDS + 7)


def test_the_panels_auto_samples_read_its_own_scenes(scene, tmp_path):
    """Samples per Pass 0 is --spp auto: the sides' scenes are read from this file, not by a render process; an
    override of path guiding renders the scene's own samples."""
    from batch.decide.check_job import check_job

    settings = scene.welch_bias
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER")
    scene.cycles.samples = 24
    bpy.ops.welch_bias.override_add(text="cycles.use_guiding=True")
    assert settings.spp == 0
    request = session.check_request(settings, scene, str(blend), tmp_path / "run", False)
    assert request.spp is None
    job = check_job(request, probe=session.scene_samples)
    assert (job.reference.spp, job.test.spp) == (24, 24)
    assert job.auto_samples["differing"] == [{"name": "use_guiding", "values": [False, True], "fewest": 2}]


def test_checks_of_the_setup(scene, tmp_path):
    settings = scene.welch_bias
    settings.tile = TILE
    assert checks.setup_problems(settings, scene) == [
        "No overrides: both sides would be the same renders; add an override, or turn Paired off to check the "
        "scene against itself on other seeds"
    ]
    settings.paired = False
    assert checks.setup_problems(settings, scene) == []
    scene.render.engine = "BLENDER_EEVEE"
    assert checks.setup_warnings(settings, scene) == [
        "Scene 'Welch Test Scene' uses BLENDER_EEVEE: the passes are rendered with Cycles",
        "No overrides: the scene against itself on other seeds (a check of the test itself)",
    ]
    settings.tile = 128
    assert checks.setup_problems(settings, scene) == [
        "Tile size 128 exceeds the render size 64x64 of scene 'Welch Test Scene'"
    ]
    settings.tile = TILE
    settings.mode = "TWO_SCENES"
    assert checks.setup_problems(settings, scene) == ["Choose the reference scene", "Choose the test scene"]
    other = bpy.data.scenes.new("Welch Other")
    try:
        other.render.resolution_x, other.render.resolution_y = 32, 64
        settings.reference_scene, settings.test_scene = scene, other
        assert checks.setup_problems(settings, scene) == [
            "Scene 'Welch Other' has no camera",
            "The reference and test scenes render at different sizes: 64x64 and 32x64",
        ]
    finally:
        settings.test_scene = None
        bpy.data.scenes.remove(other)
    settings.mode = "STATS_FILES"
    settings.reference_file = str(tmp_path / "missing.npz")
    assert checks.setup_problems(settings, scene) == [
        f"Reference statistics file not found: {tmp_path / 'missing.npz'}",
        "Choose the test statistics file",
    ]


def test_override_syntax_is_checked_before_a_run(scene):
    pytest.importorskip("batch.jobs.overrides")
    assert checks.override_problems(['lights["Light"].energy=5', *(text for text, _ in ui.OVERRIDE_PRESETS)]) == []
    problems = checks.override_problems(["no equals sign"])
    assert len(problems) == 1 and problems[0].startswith("Override 'no equals sign': ")
    scene.welch_bias.overrides.add().text = "no equals sign"
    with pytest.raises(RuntimeError, match="Override 'no equals sign'"):
        bpy.ops.welch_bias.run()


def test_run_refuses_a_scene_without_camera(scene):
    scene.camera = None
    with pytest.raises(RuntimeError, match="Scene 'Welch Test Scene' has no camera"):
        bpy.ops.welch_bias.run()
    assert state.last_error == "Scene 'Welch Test Scene' has no camera"
    assert state.session is None


# -- statistics files, result image --------------------------------------------------------------------------


def test_compare_files_builds_the_result_image_and_summary(scene, tmp_path):
    settings = scene.welch_bias
    settings.mode = "STATS_FILES"
    settings.reference_file = write_grey_stats(tmp_path / "ref.npz", range(0, 16), seed=1)
    settings.test_file = write_grey_stats(tmp_path / "test.npz", range(16, 32), bias=0.3, seed=2)
    assert bpy.ops.welch_bias.run() == {"FINISHED"}
    result = state.result
    assert result["verdict"] == "biased" and result["verdict_title"] == "Biased" and result["verdict_icon"] == "ERROR"
    assert result["test"] == "welch" and result["tiles"]["total"] == 16
    assert result["top_tiles"][0]["row"] < 2 and result["top_tiles"][0]["col"] < 2  # the biased quarter
    assert len(result["histogram"]) == results.HISTOGRAM_BINS
    assert sum(bar["count"] for bar in result["histogram"]) == result["tiles"]["used"]

    image = bpy.data.images[result["image"]]
    assert tuple(image.size) == (SIZE, SIZE) and image.is_float
    assert image.colorspace_settings.name == "Non-Color"
    pixels = read_pixels(image)
    assert np.all(pixels[..., 3] == 1.0) and pixels[..., :3].std() > 0.01
    # Rows are bottom-up: the biased top-left quarter (yellow, small p) is in the last rows of the buffer.
    biased = pixels[SIZE // 2 :, : SIZE // 2, :3].mean(axis=(0, 1))
    unbiased = pixels[SIZE // 2 :, SIZE // 2 :, :3].mean(axis=(0, 1))
    assert biased[0] > unbiased[0] + 0.1  # viridis yellow has far more red than violet

    settings.opacity = 0.0  # the update callback re-colours the cached comparison
    plain = read_pixels(image)
    assert not np.allclose(plain, pixels)
    settings.map_mode = "SIGNIFICANT"
    settings.opacity = 1.0
    changed = ~np.isclose(plain, read_pixels(image)).all(axis=-1)
    assert changed[SIZE // 2 :, : SIZE // 2].any() and not changed[: SIZE // 2].any()  # only significant tiles

    settings.map_mode = "CHANNEL"
    settings.channel = "G"
    assert bpy.ops.welch_bias.show_result() == {"FINISHED"}
    assert bpy.ops.welch_bias.frame_tile(row=0, col=1) == {"FINISHED"}
    framed = read_pixels(image)[::-1]  # top row first
    assert np.all(framed[0, TILE : 2 * TILE, :3] == 1.0)  # the white outline of tile (0, 1)
    with pytest.raises(RuntimeError, match="No tile at row 9"):
        bpy.ops.welch_bias.frame_tile(row=9, col=0)


def test_compare_files_without_bias_and_paired(scene, tmp_path):
    settings = scene.welch_bias
    settings.mode = "STATS_FILES"
    settings.reference_file = write_grey_stats(tmp_path / "ref.npz", range(0, 16), seed=3)
    settings.test_file = write_grey_stats(tmp_path / "test.npz", range(16, 32), seed=4)
    bpy.ops.welch_bias.run()
    assert state.result["verdict"] == "no_evidence"
    settings.test_file = write_grey_stats(tmp_path / "paired.npz", range(0, 16), seed=5)
    bpy.ops.welch_bias.run()
    assert state.result["test"] == "paired"


def test_result_image_shows_in_an_image_editor(scene, tmp_path):
    settings = scene.welch_bias
    settings.mode = "STATS_FILES"
    settings.reference_file = write_grey_stats(tmp_path / "ref.npz", range(0, 8))
    settings.test_file = write_grey_stats(tmp_path / "test.npz", range(8, 16))
    area = next(a for a in bpy.context.screen.areas if a.type != "PROPERTIES")
    old_type = area.type
    area.type = "IMAGE_EDITOR"
    try:
        bpy.ops.welch_bias.run()
        assert area.spaces.active.image.name == state.result["image"]
    finally:
        area.type = old_type


@pytest.mark.parametrize(
    "make_test, message",
    [
        (lambda p: write_grey_stats(p, range(16, 24), size=32), "statistics have different grids"),
        (lambda p: write_grey_stats(p, range(4, 12)), "the runs share 4 seeds but not all"),
        (lambda p: (p.write_text("not a statistics file"), str(p))[1], "is not a readable statistics file"),
    ],
)
def test_compare_files_reports_bad_input_in_one_line(scene, tmp_path, make_test, message):
    settings = scene.welch_bias
    settings.mode = "STATS_FILES"
    settings.reference_file = write_grey_stats(tmp_path / "ref.npz", range(0, 8))
    settings.test_file = make_test(tmp_path / "test.npz")
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.welch_bias.run()
    assert message in state.last_error and "\n" not in state.last_error
    assert state.result is None


def test_result_rgba_is_bottom_up_with_alpha(tmp_path):
    reference = welch_core.load_stats(write_grey_stats(tmp_path / "r.npz", range(0, 8)))
    test = welch_core.load_stats(write_grey_stats(tmp_path / "t.npz", range(8, 16), bias=0.5))
    comparison = welch_core.compare(reference, test, alpha=0.01)
    rgba = results.result_rgba(comparison, test, "MIN", "R", 1.0)
    assert rgba.shape == (SIZE, SIZE, 4) and rgba.dtype == np.float32 and rgba.flags.c_contiguous
    expected = welch_core.upscale_tiles(welch_core.pvalue_rgb(comparison), TILE, SIZE, SIZE)
    used = welch_core.upscale_tiles(comparison.used, TILE, SIZE, SIZE)
    np.testing.assert_allclose(rgba[::-1, :, :3][used], expected[used], atol=1e-6)


def test_histogram_bars_scale_to_the_highest_bin():
    bars, expected = results.histogram_bars(np.r_[np.zeros(10), np.linspace(0.15, 0.95, 9)], bins=10)
    assert expected == pytest.approx(1.9)
    assert bars[0] == {"label": "0.0-0.1", "count": 10, "fill": 1.0}  # the spike at p = 0 fills its bar
    assert [bar["count"] for bar in bars[1:]] == [1] * 9 and bars[1]["fill"] == pytest.approx(0.1)


# -- panels --------------------------------------------------------------------------------------------------


def test_panel_without_result(scene):
    texts = draw_panel().texts()
    assert "No result yet" in texts
    for mode in ("TWO_SCENES", "STATS_FILES"):
        scene.welch_bias.mode = mode
        layout = draw_panel()
        assert layout.operators()[-1]["idname"] == "welch_bias.run"
    assert [op["text"] for op in layout.operators()] == ["Compare Files"]


def test_panel_with_overrides_and_an_error(scene):
    bpy.ops.welch_bias.override_add(text="cycles.blur_glossy=0")
    state.last_error = "Test run failed (exit code 2): override cycles.nope does not resolve"
    layout = draw_panel()
    ops = layout.operators()
    assert ops[0]["idname"] == "welch_bias.override_remove" and ops[0]["props"].index == 0
    assert state.last_error in layout.texts()


def hanging_run(tmp_path) -> runner.CheckRun:
    """A check whose render processes start and never render (a Blender that answers --version and waits)."""
    from batch.cli.commands import build_parser
    from batch.decide.check_job import check_job_from_args

    fake = tmp_path / "blender"
    fake.write_text("#!/bin/sh\nif [ \"$1\" = --version ]; then echo 'Blender 4.5.4 LTS'; exit 0; fi\nsleep 60\n")
    fake.chmod(0o755)
    argv = ["check", "--scene", "corner", "--unpaired", "--blender", str(fake), "--out", str(tmp_path / "run")]
    return runner.CheckRun(check_job_from_args(build_parser().parse_args(argv)))


def test_panel_and_status_bar_while_running(scene, tmp_path):
    state.session = hanging_run(tmp_path)
    state.run = RunFolder(dir=str(tmp_path), reference="", test="", alpha=0.01, key=())
    try:
        state.session.poll()
        layout = draw_panel()
        progress = [kw for kind, kw in layout.calls if kind == "progress"]
        assert progress == [{"factor": 0.0, "text": "Starting the renders"}]
        assert [op["idname"] for op in layout.operators()][-1] == "welch_bias.cancel"
        status = FakeLayout()
        ui.draw_status(SimpleNamespace(layout=status), bpy.context)
        assert [kind for kind, _ in status.calls] == ["row", "progress", "operator"]
        assert bpy.ops.welch_bias.run.poll() is False
        started = time.monotonic()
        assert bpy.ops.welch_bias.cancel() == {"FINISHED"}
        assert time.monotonic() - started < 5
    finally:
        if state.running():
            state.session.cancel()
    assert state.session.state == runner.CANCELLED and state.resumable == state.run
    layout = draw_panel()
    assert "Stopped" in layout.texts()
    assert [op["text"] for op in layout.operators()][-1] == "Run"  # other settings: nothing to resume
    state.resumable = RunFolder(**{**vars(state.run), "key": session.settings_key(scene.welch_bias, scene)})
    resume = draw_panel().operators()[-1]
    assert resume["text"] == "Resume" and resume["props"].resume is True


def test_disabling_the_addon_stops_a_running_render(scene, tmp_path):
    running = state.session = hanging_run(tmp_path)
    running.poll()
    processes = [side.process.popen for side in running.check.rendered]
    assert all(p.poll() is None for p in processes)
    blender_addon.unregister()
    try:
        assert running.state == runner.CANCELLED and all(p.poll() is not None for p in processes)
        assert state.session is None
    finally:
        blender_addon.register()


@pytest.mark.parametrize("bias, verdict", [(0.3, "Biased"), (0.0, "No Evidence of Bias")])
def test_panel_with_a_result(scene, tmp_path, bias, verdict):
    settings = scene.welch_bias
    settings.mode = "STATS_FILES"
    settings.reference_file = write_grey_stats(tmp_path / "ref.npz", range(0, 16), seed=6)
    settings.test_file = write_grey_stats(tmp_path / "test.npz", range(16, 32), bias=bias, seed=7)
    bpy.ops.welch_bias.run()
    layout = draw_panel()
    texts = layout.texts()
    assert verdict in texts
    assert " ".join(texts).startswith(f"{verdict} {state.result['sentence']}")  # the sentence every presenter shows
    assert any(t.startswith("alpha 0.01, global p ") for t in texts)
    assert "Tiles: 16 of 16 valid, 16 used" in texts
    bars = [kw["text"] for kind, kw in layout.calls if kind == "progress"]
    assert bars == [f"p {bar['label']}: {bar['count']}" for bar in state.result["histogram"]]
    frames = [op for op in layout.operators() if op["idname"] == "welch_bias.frame_tile"]
    assert len(frames) == results.TOP_TILES_SHOWN
    assert (frames[0]["props"].row, frames[0]["props"].col) == (
        state.result["top_tiles"][0]["row"],
        state.result["top_tiles"][0]["col"],
    )
    image_editor = FakeLayout()
    ui.WELCH_BIAS_PT_image_editor.draw(SimpleNamespace(layout=image_editor), bpy.context)
    assert image_editor.texts() == texts  # the result beside the image, as in the Properties editor...
    props = {kw["prop"] for kind, kw in image_editor.calls if kind == "prop"}
    assert "mode" not in props and "map_mode" in props  # ...without the setup, with the map's controls


def test_panel_in_blender_34_uses_boxes_and_block_bars(scene, tmp_path):
    settings = scene.welch_bias
    settings.mode = "STATS_FILES"
    settings.reference_file = write_grey_stats(tmp_path / "ref.npz", range(0, 16), seed=8)
    settings.test_file = write_grey_stats(tmp_path / "test.npz", range(16, 32), bias=0.3, seed=9)
    bpy.ops.welch_bias.run()
    layout = draw_panel(FakeLayout34)
    kinds = {kind for kind, _ in layout.calls}
    assert "panel" not in kinds and "progress" not in kinds
    texts = layout.texts()
    assert "Biased" in texts and "P-Value Histogram" in texts and "Most Significant Tiles" in texts
    histogram = state.result["histogram"]
    for bar in histogram:
        position = texts.index(f"p {bar['label']}: {bar['count']}")
        assert texts[position + 1] == ui.BAR_BLOCK * round(bar["fill"] * ui.BAR_BLOCKS)
    assert ui.BAR_BLOCK * ui.BAR_BLOCKS in texts  # the highest bin fills its bar


def test_status_bar_in_blender_34_shows_the_progress_as_text(scene, tmp_path):
    state.session = hanging_run(tmp_path)
    try:
        state.session.poll()
        status = FakeLayout34()
        ui.draw_status(SimpleNamespace(layout=status), bpy.context)
        assert status.texts() == ["Starting the renders (0%)"]
        assert [op["idname"] for op in status.operators()] == ["welch_bias.cancel"]
    finally:
        state.session.cancel()


def test_override_presets_add_overrides(scene):
    layout = FakeLayout()
    ui.WELCH_BIAS_MT_override_presets.draw(SimpleNamespace(layout=layout), bpy.context)
    presets = [op["props"].text for op in layout.operators()]
    assert presets == [text for text, _label in ui.OVERRIDE_PRESETS]
    bpy.ops.welch_bias.override_add(text=presets[0])
    assert scene.welch_bias.enabled_overrides() == ["cycles.sample_clamp_indirect=0"]


def test_render_panel_is_for_cycles_only(scene):
    assert ui.WELCH_BIAS_PT_render.poll(SimpleNamespace(engine="CYCLES"))
    assert not ui.WELCH_BIAS_PT_render.poll(SimpleNamespace(engine="BLENDER_EEVEE"))


def test_user_dir_falls_back_to_a_temporary_folder():
    path = session.user_dir()
    assert path.is_dir() and Path(tempfile.gettempdir()) in path.parents


def test_registering_imports_nothing_heavy():
    """Registering must stay instant: no scipy, no statistics, no report code until a result is made.
    The time is printed (measured here at about 0.03 s after `import bpy`), not asserted: the machine is shared."""
    code = (
        "import sys, time, json\n"
        "import bpy\n"
        "before = set(sys.modules)\n"
        "start = time.perf_counter()\n"
        "import blender_addon\n"
        "blender_addon.register()\n"
        "seconds = time.perf_counter() - start\n"
        "print(json.dumps({'seconds': seconds, 'new': sorted(set(sys.modules) - before)}))\n"
    )
    import json
    import subprocess

    root = Path(__file__).resolve().parents[2]
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.strip().splitlines()[-1])
    print(f"add-on registration: {report['seconds'] * 1000:.0f} ms")
    heavy = [m for m in report["new"] if m.split(".")[0] in {"scipy", "matplotlib", "OpenEXR"}]
    statistics = [
        m
        for m in report["new"]
        if m.startswith("welch_core.") or m in {"batch.present.summary", "batch.present.report"}
    ]
    assert heavy == [] and statistics == []


def test_the_map_shows_a_chosen_light_component(scene, tmp_path):
    """Statistics files with layers (render --lobes): each layer is compared, the panel lists their verdicts and
    the Component menu switches the map to a layer's p-values."""
    settings = scene.welch_bias
    settings.mode = "STATS_FILES"
    paths = []
    for name, seeds, bias in (("ref", range(0, 16), 0.0), ("test", range(16, 32), 0.3)):
        rng = np.random.default_rng(len(paths))
        info = welch_core.RunInfo(spp=1, renderer="synthetic")
        image, glossy = (welch_core.TileStats(SIZE, SIZE, TILE, 3, info) for _ in range(2))
        for s in seeds:
            shiny = 0.1 + rng.normal(0.0, 0.02, (SIZE, SIZE, 3))
            shiny[: SIZE // 2, : SIZE // 2] *= 1.0 + bias  # the bias is all in the glossy layer
            base = 0.2 + rng.normal(0.0, 0.05, (SIZE, SIZE, 3))
            image.add_pass((base + shiny).astype(np.float32), s)
            glossy.add_pass(shiny.astype(np.float32), s)
        welch_core.save_stats(tmp_path / f"{name}.npz", image, {"glossy": glossy})
        paths.append(str(tmp_path / f"{name}.npz"))
    settings.reference_file, settings.test_file = paths
    assert bpy.ops.welch_bias.run() == {"FINISHED"}
    assert state.result["layers"] == [{"name": "glossy", "verdict": "biased", "title": "Biased"}]
    image = bpy.data.images[state.result["image"]]
    settings.component = "COMBINED"
    combined = read_pixels(image)
    settings.component = "glossy"
    assert results.shown_comparison(settings) is state.layers["glossy"]
    assert not np.allclose(read_pixels(image), combined)  # the glossy layer's p-values colour the map now
    texts = draw_panel().texts()
    assert any("glossy: Biased" in text for text in texts)


def test_the_image_editor_header_states_the_verdict_and_its_first_claim():
    """What the header of an Image Editor showing the map says (read without opening the sidebar)."""
    result = {"verdict_title": "Biased", "sentence": "biased: whole image +10.93 % [+8.52 %, +12.61 %]; most "
              "significant +11.04 % [+2.83 %, +18.40 %] in R of the 32x32 tile at x 32, y 32 (p 2.24e-06)"}  # fmt: skip
    assert ui.headline(result) == "Biased: whole image +10.93 % [+8.52 %, +12.61 %]"
    result = {
        "verdict_title": "No Verdict Yet (3 Passes)",
        "sentence": "so far: whole image +1.00 % [-2.00 %, +4.00 %]",
    }
    assert ui.headline(result) == "No Verdict Yet (3 Passes): whole image +1.00 % [-2.00 %, +4.00 %]"
    assert ui.headline({"verdict_title": "Equivalent", "sentence": "equivalent"}) == "Equivalent"
