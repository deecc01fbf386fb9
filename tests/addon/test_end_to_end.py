"""The whole flow through the operator on the bpy module: set up the corner scene, run the command line's check
engine on it (both sides rendered by the batch tool as subprocesses, looked at until decided), and check the
verdict, the report it writes, the result image and that the user's file is untouched."""

import hashlib
import json
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
scenes = pytest.importorskip("batch.blender.scenes")
pytest.importorskip("batch.blender.render")
pytest.importorskip("batch.jobs.overrides")

import blender_addon  # noqa: E402
from blender_addon import runner, session  # noqa: E402
from blender_addon.state import current as state  # noqa: E402

SIZE = 64  # the corner scene's default resolution
TILE = 16
MAX_PASSES = 64


@pytest.fixture(scope="module")
def corner(tmp_path_factory):
    saved_tempdir = tempfile.tempdir
    tempfile.tempdir = str(tmp_path_factory.mktemp("addon_runs"))
    blender_addon.register()
    window = bpy.context.window
    previous = window.scene
    scene = scenes.build_scene("corner")  # becomes the window's scene
    user_file = tmp_path_factory.mktemp("user") / "user.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(user_file))
    yield scene, user_file
    window.scene = previous
    bpy.data.scenes.remove(scene)
    blender_addon.unregister()
    tempfile.tempdir = saved_tempdir


class RecordingLayout:
    """Just enough of a UILayout to collect the labels a draw function writes."""

    def __init__(self):
        self.labels: list[str] = []
        self.alert = False

    def label(self, text="", **_):
        self.labels.append(text)

    def panel(self, *_args, **_kwargs):
        return self, self

    def operator(self, *_args, **_kwargs):
        return SimpleNamespace()

    def __getattr__(self, _name):
        return lambda *args, **kwargs: self


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _settings(scene, overrides):
    settings = scene.welch_bias
    settings.mode = "CURRENT_WITH_OVERRIDES"
    settings.overrides.clear()
    for text in overrides:
        settings.overrides.add().text = text
    settings.max_passes, settings.spp, settings.tile, settings.paired = MAX_PASSES, 1, TILE, True
    return settings


@pytest.mark.slow
def test_run_renders_both_sides_and_shows_a_biased_map(corner, capsys):
    scene, user_file = corner
    # Brighter walls on the test side: a plain bias the test must find with a few passes.
    _settings(scene, [f"{scenes.WALL_COLOR_PATH}=0.3,0.3,0.3,1"])
    before = _digest(user_file)
    assert bpy.ops.welch_bias.run() == {"FINISHED"}

    assert state.session.state == runner.FINISHED
    assert state.result["verdict"] == "biased", state.result
    passes = state.session.result[0].passes
    assert state.result["n_ref"] == state.result["n_test"] == passes < MAX_PASSES  # stopped when decided
    assert state.result["tiles"]["total"] == (SIZE // TILE) ** 2
    run_dir = Path(state.run.dir)
    report = (run_dir / "report.json").read_text()  # what `python -m batch check` writes, the panel's numbers
    assert f'"sentence": "{state.result["sentence"]}"' in report and state.result["check"]["passes"] == passes
    image = bpy.data.images[state.result["image"]]
    assert tuple(image.size) == (SIZE, SIZE)
    pixels = np.empty(SIZE * SIZE * 4, np.float32)
    image.pixels.foreach_get(pixels)
    rgb = pixels.reshape(SIZE, SIZE, 4)[..., :3]
    assert np.isfinite(rgb).all() and rgb.std() > 0.01 and 0.0 <= rgb.min() and rgb.max() <= 1.0

    assert (run_dir / "reference.npz").is_file() and (run_dir / "test.npz").is_file()

    # The result is kept with the file: after a reload the panel shows it again, and says so when the settings
    # changed since.
    from blender_addon import results, ui

    saved = json.loads(scene.welch_bias.last_result)
    assert saved["sentence"] == state.result["sentence"]
    state.reset()
    assert results.restore_from_file(scene) and state.result["sentence"] == saved["sentence"]
    layout = RecordingLayout()
    ui.draw_result(layout, scene.welch_bias, scene)
    assert "Saved with the file (run again for the map)" in layout.labels
    assert not any(t.startswith("Stale") for t in layout.labels)
    scene.welch_bias.spp = 2
    layout = RecordingLayout()
    ui.draw_result(layout, scene.welch_bias, scene)
    assert "Stale: the settings changed since this result" in layout.labels
    scene.welch_bias.spp = 1
    # A saved result that is empty, of an older version or of the wrong type is left out with one console line,
    # and the panel draws.
    good = scene.welch_bias.last_result
    for bad in ("{}", "[1, 2]", '{"verdict": 3}', json.dumps({**saved, "tiles": []}), "not json"):
        state.reset()
        scene.welch_bias.last_result = bad
        capsys.readouterr()
        assert not results.restore_from_file(scene) and state.result is None
        said = capsys.readouterr().out.splitlines()
        assert len(said) == 1 and said[0].startswith("Welch bias: the result saved in this file is from another"), said
        ui.draw_result(RecordingLayout(), scene.welch_bias, scene)
    scene.welch_bias.last_result = good
    assert results.restore_from_file(scene)
    assert not (run_dir / "scene.blend").exists()  # the temporary copy is gone
    assert bpy.data.filepath == str(user_file) and _digest(user_file) == before


@pytest.mark.slow
def test_an_unpaired_run_detects_a_brighter_light(corner):
    scene, _ = corner
    # The startup file has a light named "Light" too, so the corner's light data may be "Light.001".
    light = next(o.data for o in scene.objects if o.type == "LIGHT")
    settings = _settings(scene, [f'lights["{light.name}"].energy={light.energy * 1.3}'])
    settings.paired = False
    assert bpy.ops.welch_bias.run() == {"FINISHED"}
    assert state.result["test"] == "welch" and state.result["verdict"] == "biased"


@pytest.mark.slow
def test_an_override_that_does_not_resolve_fails_in_one_line(corner):
    scene, _ = corner
    _settings(scene, ["cycles.no_such_setting=1"])
    with pytest.raises(RuntimeError, match=r"test side: .*no_such_setting"):
        bpy.ops.welch_bias.run()
    assert "\n" not in state.last_error
    assert state.resumable is not None and Path(state.resumable.dir, "check.json").is_file()
    assert state.result is None


@pytest.mark.slow
def test_cancel_then_resume_completes_the_run(corner):
    scene, _ = corner
    settings = _settings(scene, [f"{scenes.WALL_COLOR_PATH}=0.3,0.3,0.3,1"])
    started = session.start(bpy.context, settings, resume=False)
    deadline = time.monotonic() + 60
    while started.poll() == runner.RUNNING and started.passes < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert started.state == runner.RUNNING
    assert bpy.ops.welch_bias.cancel() == {"FINISHED"}
    run_dir = state.run.dir
    assert started.state == runner.CANCELLED and state.resumable.dir == run_dir
    assert (Path(run_dir) / "scene.blend").exists()  # kept: the resumed run renders the same scene

    assert bpy.ops.welch_bias.run(resume=True) == {"FINISHED"}
    assert state.run.dir == run_dir  # the same statistics files, continued
    assert state.result["verdict"] == "biased"
    assert json.loads((Path(run_dir) / "check.json").read_text())["looks"][-1]["verdict"] == "biased"
