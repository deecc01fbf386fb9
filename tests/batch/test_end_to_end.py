"""The batch tool end to end with real Cycles renders (bpy module) at 64 px: verdicts, the paired test, resume
after a killed run, bad inputs and exit codes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch.blender.run import RunError, render_passes
from batch.blender.scenes import WALL_COLOR_PATH
from batch.present.progress import Progress
from tests.helpers.renderers import NanEverySecondPass

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow


SMALL = ("--scene", "corner", "--resolution", 64, 64)


def command(*args) -> list[str]:
    return [sys.executable, "-m", "batch", *map(str, args)]


def batch(*args, check=None) -> subprocess.CompletedProcess:
    """Run ``python -m batch ARGS`` as a user would, from the repository root."""
    done = subprocess.run(command(*args), cwd=ROOT, capture_output=True, text=True)
    if check is not None:
        assert done.returncode == check, done.stderr[-3000:]
    return done


def render(out, seeds, *extra, spp=2) -> subprocess.CompletedProcess:
    return batch("render", *SMALL, "--tile", 16, "--seeds", seeds, "--spp", spp, "--out", out, *extra, check=0)


def grey(value: float) -> str:
    return f"{WALL_COLOR_PATH}={value},{value},{value},1"


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "ref.npz"
    render(out, "0:24")
    return out


def test_render_records_the_run(reference):
    run = wc.load_stats(reference)
    assert run.n == 24 and run.seeds == list(range(24))
    assert (run.width, run.height, run.tile, run.grid_shape) == (64, 64, 16, (4, 4, 3))
    info = run.info
    assert info.renderer == "Cycles" and info.renderer_version.startswith("5.0")
    assert info.spp == 2 and info.device == "CPU" and info.sampling_pattern == "TABULATED_SOBOL"
    assert info.settings["cycles.sample_clamp_indirect"] == 0 and info.settings["cycles.use_denoising"] is False
    assert len(info.settings_hash) == 64
    assert run.mean_image.shape == (64, 64, 3) and run.mean_image.mean() > 0


def test_unbiased_pair_gives_no_evidence(reference, tmp_path):
    other = tmp_path / "other.npz"
    render(other, "100:124")
    done = batch("compare", reference, other, "--out", tmp_path / "report", check=0)
    assert "verdict: no evidence of bias" in done.stdout
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert report["verdict"] == "no_evidence" and report["test"] == "welch"
    assert report["differences"] == []


def test_brighter_walls_are_biased(reference, tmp_path):
    test = tmp_path / "walls.npz"
    render(test, "200:224", "--set", grey(0.3))
    done = batch("compare", reference, test, "--out", tmp_path / "report", check=1)
    assert "verdict: biased" in done.stdout
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert report["top_tiles"][0]["rel_diff"] > 0.05  # brighter walls, brighter image
    assert any("overrides" in line for line in report["differences"])


def test_paired_run_with_a_changed_setting(reference, tmp_path):
    """Same seeds, indirect light clamped at 0.05: the paired test is chosen and finds the darkening."""
    test = tmp_path / "clamped.npz"
    render(test, "0:24", "--set", "cycles.sample_clamp_indirect=0.05")
    batch("compare", reference, test, "--out", tmp_path / "report", check=1)
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert report["test"] == "paired" and report["verdict"] == "biased"
    assert report["top_tiles"][0]["rel_diff"] < 0


def test_selftest_of_a_rendered_run(reference, tmp_path):
    batch("selftest", reference, "--out", tmp_path / "self", check=0)


def test_resume_after_kill(tmp_path):
    """Kill -9 a run mid-way: the checkpoint holds whole passes; --resume renders the rest, no seed twice."""
    out = tmp_path / "run.npz"
    args = command(
        "render",
        *SMALL,
        "--tile",
        16,
        "--seeds",
        "0:400",
        "--spp",
        1,
        "--checkpoint-every",
        4,
        "--json-progress",
        "--out",
        out,
    )
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        for line in proc.stdout:
            event = json.loads(line) if line.startswith("{") else {}
            if event.get("event") == "pass" and event["done"] >= 10:
                break
    finally:
        proc.kill()
        proc.wait()
    partial = wc.load_stats(out)
    # a checkpoint every 4 passes, or further apart where writing takes more than a tenth of the time
    assert 4 <= partial.n < 400 and partial.n % 4 == 0
    assert partial.seeds == list(range(partial.n))
    done = batch("render", *SMALL, "--tile", 16, "--seeds", "0:20", "--spp", 1, "--out", out, check=2)
    assert "already exists: pass --resume" in done.stderr
    target = max(20, partial.n)
    batch("render", *SMALL, "--tile", 16, "--seeds", f"0:{target}", "--spp", 1, "--resume", "--out", out, check=0)
    resumed = wc.load_stats(out)
    assert resumed.seeds == list(range(target))
    fresh = wc.TileStats.from_sums(resumed.sums, resumed.seeds, 64, 64, 16)
    np.testing.assert_allclose(resumed.mean, fresh.mean, rtol=1e-12)


def test_sigterm_keeps_the_checkpoint(tmp_path):
    out = tmp_path / "run.npz"
    args = command(
        "render", *SMALL, "--seeds", "0:400", "--spp", 1, "--checkpoint-every", 1000, "--json-progress", "--out", out
    )
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if line.startswith("{") and json.loads(line).get("done", 0) >= 3:
            break
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert wc.load_stats(out).n >= 3  # saved on the way out although no checkpoint was due


def test_resume_refuses_other_settings(reference, tmp_path):
    copy = tmp_path / "copy.npz"
    copy.write_bytes(reference.read_bytes())
    done = batch(
        "render",
        *SMALL,
        "--tile",
        16,
        "--seeds",
        "0:30",
        "--spp",
        2,
        "--set",
        "cycles.max_bounces=3",
        "--resume",
        "--out",
        copy,
        check=2,
    )
    assert (
        done.stderr == f"error: {copy}: can't resume runs that differ in the setting cycles.max_bounces: 1024 and 3\n"
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["missing.blend"], "error: missing.blend: no such file"),
        (["--scene", "nope"], "error: unknown built-in scene 'nope'"),
        (["--scene", "corner", "--set", "cycles.no_such_thing=1"], "no property 'no_such_thing'"),
        (
            ["--scene", "corner", "--set", "cycles.samples"],
            "error: argument --set: 'cycles.samples': malformed override at the end",
        ),
        ([], "error: no scene to render"),
    ],
)
def test_bad_render_inputs(tmp_path, args, message):
    done = batch("render", *args, "--seeds", "0:2", "--spp", 1, "--json-progress", "--out", tmp_path / "x.npz")
    assert done.returncode == 2, done.stderr
    assert message in done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1])["event"] == "error"
    assert not (tmp_path / "x.npz").exists()
    assert "Traceback" not in done.stderr


def test_corrupt_blend_file(tmp_path):
    bad = tmp_path / "bad.blend"
    bad.write_bytes(b"BLENDER-v500" + b"\0" * 64)
    done = batch("render", bad, "--seeds", "0:2", "--spp", 1, "--out", tmp_path / "x.npz")
    assert done.returncode == 2 and "cannot open as a .blend file" in done.stderr


def test_a_missing_output_folder_is_made_and_an_impossible_one_refused(tmp_path):
    out = tmp_path / "runs" / "x.npz"  # as check --out does, render --out makes its folder
    done = batch("render", "--scene", "corner", "--resolution", 16, 16, "--tile", 8, "--seeds", "0:2", "--spp", 1,
                 "--out", out)  # fmt: skip
    assert done.returncode == 0 and out.is_file(), done.stderr
    (tmp_path / "file").write_text("a file, not a folder")
    done = batch("render", "--scene", "corner", "--seeds", "0:2", "--spp", 1, "--out", tmp_path / "file" / "x.npz")
    assert done.returncode == 2 and f"can't create the folder {tmp_path / 'file'}" in done.stderr


def test_lint_of_a_factory_scene(tmp_path):
    """A scene saved with Cycles' defaults has indirect clamping and Filter Glossy on: lint exits 1."""
    blend = tmp_path / "defaults.blend"
    code = (
        "import bpy; bpy.ops.wm.read_factory_settings(); bpy.context.scene.render.engine = 'CYCLES';"
        f"bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
    done = batch("lint", blend)
    assert done.returncode == 1, done.stderr
    assert "sample_clamp_indirect" in done.stdout and "blur_glossy" in done.stdout


@pytest.mark.parametrize(("policy", "count"), [("skip", 2), ("keep", 4)])
def test_nan_passes_skip_or_keep(tmp_path, policy, count):
    stats = wc.TileStats(32, 32, 16)
    render_passes(NanEverySecondPass(), [0, 1, 2, 3], stats, Progress(4), policy, str(tmp_path / "x.npz"))
    assert stats.n == count and wc.load_stats(tmp_path / "x.npz").n == count


def test_nan_pass_stops_the_run_and_keeps_what_was_done(tmp_path):
    stats = wc.TileStats(32, 32, 16)
    out = tmp_path / "x.npz"
    with pytest.raises(RunError, match="pass with seed 1 has 1 non-finite pixel values"):
        render_passes(NanEverySecondPass(), [0, 1, 2], stats, Progress(3), "stop", str(out))
    assert wc.load_stats(out).seeds == [0]
    assert os.path.getsize(out) > 0


def test_demo_prints_the_verdict_and_the_report(tmp_path):
    """The README's first command, made smaller: the planted bias (walls 0.21) is found and reported."""
    done = batch("demo", "--out", tmp_path / "demo", "--passes", 8, "--resolution", 64, check=0)
    assert "verdict: biased" in done.stdout
    assert f"report: {tmp_path / 'demo' / 'report.html'}" in done.stdout
    report = json.loads((tmp_path / "demo" / "report.json").read_text())
    assert report["verdict"] == "biased" and report["n_ref"] == report["n_test"] == 8
    written = {p.name for p in (tmp_path / "demo").iterdir()}
    assert {"reference.npz", "walls_0.21.npz", "report.html", "pvalues.exr"} <= written
