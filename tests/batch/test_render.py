"""batch.blender.render and batch.blender.scenes with real Cycles (bpy module): opening scenes, unbiased settings,
passes, records."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from batch.blender import render  # noqa: E402
from batch.blender.scenes import SCENES, WALL_COLOR_PATH, build_scene  # noqa: E402
from batch.errors import BatchError  # noqa: E402
from batch.jobs.overrides import apply_overrides, parse_override  # noqa: E402
from batch.jobs.rna import render_size  # noqa: E402

SIZE = 64


@pytest.fixture
def factory():
    """bpy is one global state per process: every test that builds a scene starts from an empty file."""
    bpy.ops.wm.read_factory_settings(use_empty=True)


def corner(spp: int = 1):
    scene = render.open_scene(None, "corner")
    render.configure_unbiased(scene, spp=spp, resolution=(SIZE, SIZE))
    return scene


# -- scenes ---------------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_builtin_scene_renders(factory, name):
    scene = render.open_scene(None, name)
    assert scene.name == name and bpy.context.scene == scene and scene.camera is not None
    render.configure_unbiased(scene, spp=2)
    with render.PassRenderer(scene) as renderer:
        image = renderer.render(0)
    assert image.shape == (SIZE, SIZE, 3) and image.dtype == np.float32
    assert np.isfinite(image).all() and 0.02 < image.mean() < 2.0


def test_build_scene_rejects_unknown_names(factory):
    with pytest.raises(BatchError, match=f"unknown built-in scene 'box'; choose from {', '.join(SCENES)}$"):
        build_scene("box")


# -- opening scenes -------------------------------------------------------------------------------------------


def test_open_scene_errors(factory, tmp_path):
    missing = tmp_path / "missing.blend"
    corrupt = tmp_path / "corrupt.blend"
    corrupt.write_bytes(b"not a blend file" * 64)
    cases = [
        ((str(missing),), f"{missing}: no such file"),
        ((None, "box"), f"unknown built-in scene 'box'; choose from {', '.join(SCENES)}"),
        ((str(missing), "corner"), f"give a .blend file or a built-in scene, not both ({missing}, 'corner')"),
        ((None, "corner", "Other"), "a built-in scene has no scene 'Other' to choose"),
        ((None,), f"no scene to render: give a .blend file or a built-in scene ({', '.join(SCENES)})"),
    ]
    for args, message in cases:
        with pytest.raises(render.RenderSetupError) as info:
            render.open_scene(*args)
        assert str(info.value) == message
    with pytest.raises(render.RenderSetupError, match=rf"^{corrupt}: cannot open as a \.blend file \(.+\)$"):
        render.open_scene(str(corrupt))


def test_open_scene_from_file_chooses_scenes_and_needs_a_camera(factory, tmp_path):
    build_scene("corner")
    bpy.data.scenes.new("NoCamera")
    path = str(tmp_path / "two.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    assert render.open_scene(path, None, "corner").name == "corner"
    assert render.open_scene(None, None, "corner").name == "corner"  # the file Blender has open
    with pytest.raises(render.RenderSetupError) as info:
        render.open_scene(path, None, "NoCamera")
    assert str(info.value) == "scene 'NoCamera' has no camera"
    with pytest.raises(render.RenderSetupError) as info:
        render.open_scene(path, None, "Nope")
    assert str(info.value) == f"{path}: no scene 'Nope'; the file has 'corner', 'NoCamera', 'Scene'"


def test_configure_unbiased_records_changes_and_keeps_biased_settings(factory):
    scene = bpy.context.scene  # the factory scene: EEVEE, denoising and adaptive sampling on, clamp 10
    own_pattern = scene.cycles.sampling_pattern  # the startup file's (5.0: Tabulated Sobol; 5.2: automatic)
    changes = render.configure_unbiased(scene, spp=3, resolution=(40, 30))
    assert {"path": "render.engine", "old": "BLENDER_EEVEE", "new": "CYCLES"} in changes
    assert {"path": "cycles.use_denoising", "old": True, "new": False} in changes
    cycles, settings = scene.cycles, scene.render.image_settings
    assert scene.render.engine == "CYCLES" and cycles.samples == 3 and cycles.device == "CPU"
    assert not cycles.use_denoising and not scene.view_layers[0].cycles.use_denoising
    assert not cycles.use_adaptive_sampling and cycles.time_limit == 0
    assert cycles.sampling_pattern == own_pattern  # the scene's own: the job gave none
    assert not scene.render.use_compositing and not scene.render.use_sequencer and scene.render.use_persistent_data
    assert (settings.file_format, settings.color_depth, settings.exr_codec) == ("OPEN_EXR", "32", "NONE")
    assert render_size(scene) == (40, 30)
    # What the user tests stays as it is: lint reports it.
    assert cycles.sample_clamp_indirect == 10.0 and cycles.blur_glossy == 1.0
    assert render.configure_unbiased(scene, spp=3, resolution=(40, 30)) == []
    with pytest.raises(ValueError, match="`spp` must be a positive integer, got 0"):
        render.configure_unbiased(scene, spp=0)
    with pytest.raises(render.RenderSetupError, match="^unknown device 'TPU'; use CPU, GPU or one of "):
        render.configure_unbiased(scene, device="TPU")
    with pytest.raises(render.RenderSetupError) as info:
        render.configure_unbiased(scene, sampling_pattern="SOBOL")
    assert str(info.value) == (
        f"--sampling-pattern SOBOL is not a pattern of Blender {bpy.app.version_string} (it has AUTOMATIC, "
        "TABULATED_SOBOL, BLUE_NOISE)"
    )


def test_an_override_of_a_setting_the_job_fixes_is_refused(factory):
    """What is rendered is what is recorded: --set cycles.samples=64 with --spp 1 would render 64 spp."""
    scene = render.open_scene(None, "corner")
    render.configure_unbiased(scene, spp=1, resolution=(64, 64))
    for text, message in (
        (
            "cycles.samples=64",
            "--set cycles.samples=64 changes cycles.samples (1 -> 64), which the job fixes: use --spp instead",
        ),
        (
            "render.resolution_x=200",
            "--set render.resolution_x=200 changes render.resolution_x (64 -> 200), which the job fixes: use "
            "--resolution instead",
        ),
        (
            "cycles.use_adaptive_sampling=true",
            "--set cycles.use_adaptive_sampling=true changes cycles.use_adaptive_sampling (False -> True), which the "
            "job fixes: every pass needs it as the batch tool sets it",
        ),
    ):
        applied = apply_overrides(scene, [text])
        with pytest.raises(render.RenderSetupError) as info:
            render.check_fixed_settings(scene, 1, (64, 64), applied)
        assert str(info.value) == message
        apply_overrides(scene, [f"{applied[0]['path']}={str(applied[0]['old']).lower()}"])
    render.check_fixed_settings(scene, 1, (64, 64), apply_overrides(scene, ["cycles.samples=1"]))  # unchanged: fine
    # Without --resolution the size is the scene's to set: it is read back after the overrides and recorded.
    render.check_fixed_settings(scene, 1, None, apply_overrides(scene, ["render.resolution_x=32"]))


def test_a_sample_subset_past_the_passes_samples_is_refused_before_rendering(factory, tmp_path):
    """use_sample_subset with a sample_offset at or past the pass's samples renders black passes (Cycles renders no
    sample; `compare` then said `inconclusive`, constant images, without a word): refused in one line when the
    scene is prepared, whether an override or the .blend sets it."""
    from batch.blender.run import prepare_scene
    from batch.jobs.job import RenderJob

    out = str(tmp_path / "run.npz")
    job = RenderJob(out, (0,), spp=2, scene="corner", resolution=(32, 32), tile=16)
    subset = ("cycles.use_sample_subset=True", "cycles.sample_offset=4")
    with pytest.raises(render.RenderSetupError) as info:
        prepare_scene(job.replace(overrides=subset))
    assert str(info.value) == (
        "cycles.use_sample_subset is on with cycles.sample_offset 4, at or past the 2 samples of a pass: every "
        "pass would render black (turn it off: --set cycles.use_sample_subset=False)"
    )
    scene, _ = prepare_scene(job.replace(overrides=("cycles.use_sample_subset=True", "cycles.sample_offset=1")))
    with render.PassRenderer(scene) as renderer:
        assert renderer.render(0).mean() > 0.02  # within the samples: rendered (lint says what a subset does)
    scene = render.open_scene(None, "corner")
    scene.cycles.use_sample_subset, scene.cycles.sample_offset = True, 2
    blend = str(tmp_path / "subset.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    with pytest.raises(render.RenderSetupError, match=r"^cycles.use_sample_subset is on with cycles.sample_offset 2,"):
        prepare_scene(RenderJob(out, (0,), spp=2, blend=blend, resolution=(32, 32), tile=16))
    prepare_scene(RenderJob(out, (0,), spp=3, blend=blend, resolution=(32, 32), tile=16))


# -- passes ---------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_seeds_differ_and_repeat_bit_identically_with_persistent_data(factory):
    scene = corner()
    assert scene.render.use_persistent_data
    with render.PassRenderer(scene) as renderer:
        first, other, again = renderer.render(0), renderer.render(1), renderer.render(0)
        path = renderer.path
        assert os.path.isfile(path) and path.startswith("/dev/shm/" if os.path.isdir("/dev/shm") else "")
    assert not os.path.exists(path)  # removed on close
    assert (first != other).mean() > 0.5  # the re-seed took effect
    assert np.array_equal(first, again)


@pytest.mark.slow
def test_a_pass_equals_a_fresh_non_persistent_render_of_the_same_seed(factory):
    scene = corner()
    with render.PassRenderer(scene) as renderer:
        for seed in (3, 4):
            persistent = renderer.render(seed)  # seed 4 re-uses the synced scene of seed 3
    bpy.ops.wm.read_factory_settings(use_empty=True)
    fresh = corner()
    fresh.render.use_persistent_data = False
    with render.PassRenderer(fresh) as renderer:
        assert np.array_equal(renderer.render(4), persistent)


@pytest.mark.slow
def test_pass_is_top_row_first_rgb_scene_linear(factory):
    """An emitter in the top-left quarter of an orthographic view, colour (1, 0.5, 0.25); black elsewhere."""
    scene = bpy.data.scenes.new("orientation")
    bpy.context.window.scene = scene
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.type, camera.data.ortho_scale = "ORTHO", 2.0
    camera.location = (0.0, 0.0, 5.0)  # looks down -Z with +Y up in the image
    scene.collection.objects.link(camera)
    scene.camera = camera
    mesh = bpy.data.meshes.new("Quad")
    mesh.from_pydata([(-1, 0, 0), (0, 0, 0), (0, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    material = bpy.data.materials.new("Emit")
    nodes = material.node_tree.nodes
    nodes.clear()
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (1.0, 0.5, 0.25, 1.0)
    material.node_tree.links.new(emission.outputs[0], nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    mesh.materials.append(material)
    scene.collection.objects.link(bpy.data.objects.new("Quad", mesh))
    scene.view_settings.view_transform = "AgX"  # a display transform must not reach the saved pass
    render.configure_unbiased(scene, resolution=(SIZE, SIZE))
    with render.PassRenderer(scene) as renderer:
        image = renderer.render(0)
    half, margin = SIZE // 2, 3  # the pixel filter blurs about a pixel across the edges
    np.testing.assert_allclose(image[: half - margin, : half - margin], np.broadcast_to([1.0, 0.5, 0.25], (29, 29, 3)))
    assert np.all(image[half + margin :] == 0) and np.all(image[:, half + margin :] == 0)


@pytest.mark.slow
def test_an_override_changes_the_render(factory):
    means = []
    for grey in (0.2, 0.3):
        scene = corner(spp=4)
        apply_overrides(scene, [f"{WALL_COLOR_PATH}={grey},{grey},{grey},1"])
        with render.PassRenderer(scene) as renderer:
            means.append(float(np.mean([renderer.render(seed).mean() for seed in range(4)])))
    # Direct light scales with the albedo: 1.5x the grey gives at least 1.4x the mean.
    assert means[1] > 1.4 * means[0]


# -- what a run records ---------------------------------------------------------------------------------------


def test_scene_settings_are_json_override_paths_and_hash_changes(factory):
    scene = corner()
    settings = render.scene_settings(scene)
    assert json.loads(json.dumps(settings)) == settings
    for key in settings:
        parse_override(f"{key}=0")  # every key is a valid override path
    assert settings["cycles.sample_clamp_indirect"] == 0.0 and settings["cycles.pixel_filter_type"] == "BLACKMAN_HARRIS"
    assert (
        settings["render.resolution_x"] == SIZE and settings['view_layers["ViewLayer"].cycles.use_denoising'] is False
    )
    assert settings["camera"] == "Camera" and "cycles.seed" not in settings and "cycles.samples" not in settings
    digest = render.settings_hash(settings)
    assert len(digest) == 64 and digest == render.settings_hash(dict(reversed(settings.items())))
    scene.cycles.blur_glossy = 0.5
    assert render.settings_hash(render.scene_settings(scene)) != digest
    scene.cycles.seed = 7  # seeds and samples are recorded elsewhere
    scene.cycles.blur_glossy = 0.0
    assert render.settings_hash(render.scene_settings(scene)) == digest


def test_renderer_info(factory):
    info = render.renderer_info(corner(), "CPU")
    assert info == {
        "renderer": "Cycles",
        "version": bpy.app.version_string,
        "build_hash": info["build_hash"],
        "device": "CPU",
        "sampling_pattern": "TABULATED_SOBOL",
    }
    assert json.dumps(info)


def test_a_full_temporary_folder_is_named_as_such(factory, tmp_path, monkeypatch):
    """Blender only prints a failed save: the pass then does not read back, and the reason must be the full
    folder, not an unreadable EXR."""
    scene = render.open_scene(None, "corner")
    render.configure_unbiased(scene, resolution=(16, 16))
    with render.PassRenderer(scene, temp_dir=str(tmp_path)) as renderer:
        monkeypatch.setattr(render, "_free_bytes", lambda _folder: 100)
        Path(renderer.path).unlink()
        Path(renderer.path).mkdir()  # Blender can't save over a folder: its save fails as on a full disk
        with pytest.raises(BatchError) as info:
            renderer.render(0)
        Path(renderer.path).rmdir()
    assert str(info.value) == f"no space left in {tmp_path} to save a pass (0.0 MiB free, a pass needs 0.0 MiB)"


def test_temporary_passes_of_killed_renders_are_removed(factory, tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f"welch-pass-{dead.pid}-abc.exr"
    alive = tmp_path / f"welch-pass-{os.getppid()}-abc.exr"  # a running process's pass stays
    other = tmp_path / "unrelated.exr"
    for path in (stale, alive, other):
        path.write_bytes(b"x")
    scene = render.open_scene(None, "corner")
    render.configure_unbiased(scene, resolution=(16, 16))
    with render.PassRenderer(scene, temp_dir=str(tmp_path)) as renderer:
        assert not stale.exists() and alive.exists() and other.exists()
        assert os.path.basename(renderer.path).startswith(f"welch-pass-{os.getpid()}-")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([alive.name, other.name])


def test_the_tools_seeds_map_one_to_one_onto_scattered_cycles_seeds():
    seeds = list(range(100_000)) + [render.SEED_MASK - k for k in range(1000)]
    mapped = [render.cycles_seed(s) for s in seeds]
    assert len(set(mapped)) == len(seeds) and all(0 <= m <= render.SEED_MASK for m in mapped)
    assert render.cycles_seed(0) == 0 and abs(render.cycles_seed(2) - render.cycles_seed(0)) > 1_000_000


@pytest.mark.slow
def test_passes_of_consecutive_seeds_are_uncorrelated(factory, tmp_path):
    """Cycles' own seeds s and s + 2 gave correlated passes with Tabulated Sobol on the diffuse corner (rho 0.11
    between their tile sums over 300 seeds, in 4.5 to 5.3); the tool's seeds 0, 1, 2, ... render unrelated
    Cycles seeds: no lag has a correlation beyond what 240 independent passes show."""
    import welch_core as wc
    from batch.blender.run import prepare_scene
    from batch.jobs.job import RenderJob

    job = RenderJob(out=str(tmp_path / "x.npz"), seeds=range(240), scene="corner", resolution=(SIZE, SIZE),
                    sampling_pattern="TABULATED_SOBOL")  # fmt: skip
    scene, _ = prepare_scene(job)
    with render.PassRenderer(scene) as renderer:
        sums = np.stack([wc.tile_sums(renderer.render(seed), 16) for seed in job.seeds])
    z = sums.reshape(len(sums), -1)
    z = (z - z.mean(axis=0)) / z.std(axis=0)
    lags = [float(np.mean(z[:-k] * z[k:])) for k in (1, 2, 3, 4)]
    assert max(abs(c) for c in lags) < 0.05, lags  # 0.11 at lag 2 with Cycles' seeds 0, 1, 2, ...
