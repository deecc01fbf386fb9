"""Each side renders what it was given: a scene file keeps its own sampling pattern, the settings the passes fix
are said in the notes, a difference between the files that the passes erase is never "Nothing to do", and
``check`` compares two sampling patterns (or samples, or devices) directly. Real Cycles through the bpy module."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import welch_core as wc
from batch.jobs.job import RenderJob

MAKE_FILE = """
import sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=False)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.samples = int(sys.argv[-2])
scene.cycles.sampling_pattern = sys.argv[-1]
scene.render.resolution_x = scene.render.resolution_y = 16
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-3])
"""


def scene_file(folder: Path, name: str, samples: int, pattern: str) -> Path:
    """A user's file as Blender 5.0 saves it (denoiser and adaptive sampling on), with its own samples and
    pattern."""
    path = folder / name
    script = folder / "make_file.py"
    script.write_text(MAKE_FILE)
    subprocess.run([sys.executable, str(script), str(path), str(samples), pattern], check=True, capture_output=True)
    return path


def check(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "batch", "check", *map(str, args)], capture_output=True, text=True)


def test_a_scene_file_renders_with_its_own_pattern_and_records_what_the_passes_fix(tmp_path):
    from batch.blender.run import prepare_scene

    blue = scene_file(tmp_path, "blue.blend", 4096, "BLUE_NOISE")
    _scene, info = prepare_scene(RenderJob(out=str(tmp_path / "x.npz"), seeds=(0,), blend=str(blue)))
    assert info.sampling_pattern == "BLUE_NOISE" and info.settings["cycles.sampling_pattern"] == "BLUE_NOISE"
    assert info.fixed["cycles.samples"] == [4096, 1]
    assert info.fixed["cycles.use_denoising"] == [True, False]
    assert info.fixed["cycles.use_adaptive_sampling"] == [True, False]
    assert "cycles.sampling_pattern" not in info.fixed  # the file's own, not fixed
    job = RenderJob(out=str(tmp_path / "y.npz"), seeds=(0,), blend=str(blue), sampling_pattern="TABULATED_SOBOL")
    _scene, given = prepare_scene(job)
    assert given.sampling_pattern == "TABULATED_SOBOL"
    assert given.fixed["cycles.sampling_pattern"] == ["BLUE_NOISE", "TABULATED_SOBOL"]
    assert wc.RunInfo.from_json(json.loads(json.dumps(given.to_json()))) == given


def test_a_built_in_scene_has_the_default_pattern_and_no_notes_of_its_own(tmp_path):
    from batch.blender.run import prepare_scene
    from batch.present.summary import fixed_notes

    _scene, info = prepare_scene(RenderJob(out=str(tmp_path / "x.npz"), seeds=(0,), scene="corner"))
    assert info.sampling_pattern == "TABULATED_SOBOL"
    assert fixed_notes(info, info) == ([], [])


def test_fixed_notes_name_what_the_passes_replace_and_what_they_hide():
    from batch.present.summary import fixed_notes

    def info(samples, denoise):
        fixed = {"cycles.samples": [samples, 1], "cycles.use_denoising": [denoise, False],
                 "cycles.use_layer_samples": ["USE", "IGNORE"], "cycles.time_limit": [0.0, 0.0]}  # fmt: skip
        return wc.RunInfo(scene="f.blend/Scene", scene_id="sha256:0", fixed=fixed)

    same, _ = fixed_notes(info(4096, True), info(4096, True))
    assert same == ["the passes replace settings of both scenes: samples 4096 → 1, use_denoising on → off"]
    notes, hidden = fixed_notes(info(4096, True), info(2, True))
    assert notes == [
        "the passes replace settings of the reference scene: samples 4096 → 1, use_denoising on → off",
        "the passes replace settings of the test scene: samples 2 → 1, use_denoising on → off",
        "the scene files differ in settings the passes replace on both sides, so the test cannot see them: "
        "samples: 4096 → 2 in the files, 1 in the passes",
    ]
    assert hidden == ["samples: 4096 → 2 in the files, 1 in the passes"]


@pytest.mark.slow
def test_files_that_differ_only_in_what_the_passes_replace_are_never_nothing_to_do(tmp_path):
    """Bit-identical passes from two files of other samples: `equivalent`, but the next step names the hidden
    difference and how to test it."""
    many = scene_file(tmp_path, "many.blend", 4096, "TABULATED_SOBOL")
    few = scene_file(tmp_path, "few.blend", 2, "TABULATED_SOBOL")
    done = check(many, "--test-blend", few, "--tile", 8, "--max-passes", 64, "--out", tmp_path / "chk")
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    report = json.loads((tmp_path / "chk" / "report.json").read_text())
    assert report["outcome"]["reason"] == "identical"
    assert report["hidden_differences"] == ["samples: 4096 → 2 in the files, 1 in the passes"]
    assert "Nothing to do" not in report["next_step"] and "--test-spp" in report["next_step"]
    assert "samples 4096 → 1" in " ".join(report["notes"])
    assert "next: The passes agree, but the scene files differ in what the passes replace (samples)" in done.stdout


@pytest.mark.slow
def test_check_compares_two_sampling_patterns_directly(tmp_path):
    """--test-sampling-pattern renders the test side with its own pattern: recorded, and named as a difference of
    the noise only."""
    done = check("--scene", "corner", "--resolution", 16, 16, "--tile", 8, "--test-sampling-pattern", "BLUE_NOISE",
                 "--max-passes", 8, "--tolerance", "off", "--out", tmp_path / "chk")  # fmt: skip
    assert done.returncode in (0, 3), done.stdout[-2000:] + done.stderr[-2000:]
    ref = wc.load_stats(tmp_path / "chk" / "reference.npz", pixels=False)
    test = wc.load_stats(tmp_path / "chk" / "test.npz", pixels=False)
    assert (ref.info.sampling_pattern, test.info.sampling_pattern) == ("TABULATED_SOBOL", "BLUE_NOISE")
    report = json.loads((tmp_path / "chk" / "report.json").read_text())
    assert report["noise_differences"] == ["sampling_pattern: TABULATED_SOBOL → BLUE_NOISE"]
    assert report["test"] == "paired" and report["hidden_differences"] == []


def test_a_test_side_setting_goes_to_the_test_side_only(tmp_path):
    from batch.cli.commands import build_parser
    from batch.decide.check_job import check_job_from_args

    argv = ["check", "--scene", "corner", "--spp", "1", "--test-spp", "4", "--test-sampling-pattern", "BLUE_NOISE",
            "--out", str(tmp_path / "c")]  # fmt: skip
    args = build_parser().parse_args(argv)
    job = check_job_from_args(args)
    assert (job.reference.spp, job.reference.sampling_pattern) == (1, None)
    assert (job.test.spp, job.test.sampling_pattern) == (4, "BLUE_NOISE") and job.paired


@pytest.mark.slow
def test_guiding_asked_for_at_the_default_samples_renders_the_files_own(tmp_path):
    """--set cycles.use_guiding=True without --spp: the file is read once and the passes render its 16 samples, at
    which guiding acts (at 32x32 from 6), not 1, at which it never does."""
    room = scene_file(tmp_path, "room.blend", 16, "TABULATED_SOBOL")
    done = check(room, "--resolution", 32, 32, "--tile", 8, "--set", "cycles.use_guiding=True", "--max-passes", 8,
                 "--tolerance", "off", "--out", tmp_path / "chk")  # fmt: skip
    assert done.returncode in (0, 1, 3), done.stdout[-2000:] + done.stderr[-2000:]
    for side in ("reference", "test"):
        assert wc.load_stats(tmp_path / "chk" / f"{side}.npz", pixels=False).info.spp == 16
    report = json.loads((tmp_path / "chk" / "report.json").read_text())
    assert report["outcome"]["reason"] not in ("identical", "identical_too_few") and report["hidden_differences"] == []
    assert "note: --spp auto: 16 samples per pass, the scene files' own, since the sides differ in what acts only " \
           "from some samples per render: use_guiding (off → on, from 2)" in done.stdout  # fmt: skip


@pytest.mark.slow
def test_guiding_that_left_every_pass_as_it_was_is_never_nothing_to_do(tmp_path):
    """A built-in scene at 32x32: --spp auto gives guiding the 2 samples it needs at best, but at this size it acts
    only from 6, so every pass is as it was; the verdict holds at 2 samples per pass only and says so."""
    done = check("--scene", "corner", "--resolution", 32, 32, "--tile", 8, "--set", "cycles.use_guiding=True",
                 "--max-passes", 8, "--out", tmp_path / "chk")  # fmt: skip
    assert done.returncode == 3, done.stdout[-2000:] + done.stderr[-2000:]
    report = json.loads((tmp_path / "chk" / "report.json").read_text())
    assert report["outcome"]["reason"] == "identical_too_few"
    assert report["hidden_differences"] == ["use_guiding: off → on, acting from 2 samples per render, 2 in the passes"]
    assert "Nothing to do" not in report["next_step"] and "--spp" in report["next_step"]
    assert "note: the verdict holds at 2 samples per pass only: the sides differ in use_guiding (off → on), which " \
           "left every pass as it was at these samples" in done.stdout  # fmt: skip
    assert "next: The passes agree, but they have too few samples to show use_guiding" in done.stdout
