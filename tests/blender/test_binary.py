"""The batch tool in a real Blender binary (Debian's Blender 3.4, installed by the test command as root):
``blender -b ... --python batch/blender_entry.py -- render``, ``python -m batch render --blender PATH``, and a
comparison of Cycles 3.4 against the bpy module's Cycles 5.0."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import welch_core as wc
from batch.jobs import protocol

ROOT = Path(__file__).resolve().parents[2]
BLENDER = shutil.which("blender")


def _blender_problem() -> str | None:
    if BLENDER is None:
        return "no blender on PATH (apt-get install blender python3-numpy; ./dev test does it as root)"
    done = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-expr", "import numpy"], capture_output=True)
    if done.returncode != 0 or b"Error" in done.stderr:
        return f"{BLENDER} has no numpy in its Python (apt-get install python3-numpy)"
    return None


PROBLEM = _blender_problem()
pytestmark = [pytest.mark.slow, pytest.mark.skipif(PROBLEM is not None, reason=PROBLEM or "")]

SMALL = ["--resolution", "32", "32", "--tile", "16", "--spp", "1"]


def batch(*args, check=None) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", "batch", *map(str, args)], capture_output=True, text=True)
    if check is not None:
        assert done.returncode == check, done.stderr[-3000:]
    return done


def test_blender_b_renders_a_builtin_scene(tmp_path):
    out = tmp_path / "glossy.npz"
    entry = ROOT / "batch" / "blender_entry.py"
    argv = [BLENDER, "-b", "--factory-startup", "--python-exit-code", "4", "--python", str(entry), "--", "render",
            "--scene", "glossy", *SMALL, "--seeds", "0:4", "--out", str(out)]  # fmt: skip
    done = subprocess.run(argv, capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    run = wc.load_stats(out)
    assert run.n == 4 and run.grid_shape == (2, 2, 3)
    info = run.info
    assert info.renderer == "Cycles" and info.renderer_version == "3.4.1"
    assert info.sampling_pattern == "SOBOL"  # 3.4 has no TABULATED_SOBOL: the closest default, recorded
    assert info.scene == "glossy" and info.scene_id.startswith("builtin:glossy:")
    assert "cycles.use_light_tree" not in info.settings  # a 5.0 setting 3.4 lacks is left out, not invented


def test_render_with_the_blender_option_streams_progress_and_passes_errors_through(tmp_path):
    blend = tmp_path / "corner34.blend"
    script = (
        "import sys, bpy; sys.path.insert(0, sys.argv[-2]); from batch.blender.scenes import build_scene;"
        "bpy.ops.wm.read_factory_settings(use_empty=True); build_scene('corner');"
        "bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1])"
    )
    subprocess.run([BLENDER, "-b", "--factory-startup", "--python-expr", script, "--", str(ROOT), str(blend)],
                   check=True, capture_output=True)  # fmt: skip
    out = tmp_path / "run.npz"
    done = batch("render", blend, *SMALL, "--seeds", "0:3", "--blender", BLENDER, "--json-progress", "--out", out,
                 check=0)  # fmt: skip
    seen = [protocol.parse(line) for line in done.stdout.splitlines()]
    assert [type(e).__name__ for e in seen if e is not None] == ["Started", "PassDone", "PassDone", "PassDone",
                                                                "Finished"]  # fmt: skip
    run = wc.load_stats(out)
    assert run.info.renderer_version == "3.4.1" and run.info.scene_id.startswith("sha256:")
    assert run.info.scene == "corner34.blend/corner"

    done = batch("render", blend, *SMALL, "--seeds", "0:3", "--blender", BLENDER, "--set", "cycles.nope=1",
                 "--out", tmp_path / "x.npz", check=2)  # fmt: skip
    assert done.stderr == "error: --set cycles.nope=1: 'CyclesRenderSettings' has no property 'nope'\n"
    done = batch("render", blend, *SMALL, "--seeds", "0:3", "--blender", BLENDER, "--sampling-pattern",
                 "TABULATED_SOBOL", "--out", tmp_path / "x.npz", check=2)  # fmt: skip
    assert done.stderr == (
        "error: --sampling-pattern TABULATED_SOBOL is not a pattern of Blender 3.4.1 (it has SOBOL, "
        "PROGRESSIVE_MULTI_JITTER)\n"
    )
    done = batch("render", "--scene", "corner", *SMALL, "--seeds", "0:3", "--blender", tmp_path / "no-blender",
                 "--out", tmp_path / "x.npz", check=2)  # fmt: skip
    assert done.stderr == f"error: --blender {tmp_path / 'no-blender'}: no such program\n"
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.parametrize(
    ("scene", "verdict"),
    [
        # Blender 4.0 fixed the power-to-radiance conversion of area lights (a factor 4 where pi belongs,
        # blender/blender#109404): 5.0 renders them 4/pi = 1.2732 times brighter than 3.4.
        ("corner", "biased"),
        ("corner_mesh_light", "no_evidence"),  # an emissive mesh instead of the area light: the versions agree
    ],
)
def test_cycles_34_against_cycles_50(tmp_path, scene, verdict):
    common = ["--scene", scene, "--resolution", "64", "64", "--tile", "32", "--spp", "4"]
    batch("render", *common, "--seeds", "0:24", "--blender", BLENDER, "--out", tmp_path / "b34.npz", check=0)
    batch("render", *common, "--seeds", "24:48", "--out", tmp_path / "b50.npz", check=0)
    done = batch("compare", tmp_path / "b34.npz", tmp_path / "b50.npz", "--out", tmp_path / "report")
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert report["verdict"] == verdict, done.stdout
    assert "renderer_version: 3.4.1 → 5.0.1" in report["differences"]
    assert report["reference"]["name"].startswith("Cycles 3.4.1") and report["test_run"]["name"].startswith(
        "Cycles 5.0"
    )
    if verdict == "biased":
        assert done.returncode == 1
        for tile in report["top_tiles"]:
            assert tile["rel_diff"] == pytest.approx(4 / math.pi - 1, abs=0.005)
    else:
        assert done.returncode == 0


def test_a_renderer_failure_is_one_line_quoting_blenders_reason(tmp_path):
    """A file Blender 3.4 cannot read (saved by the bpy module's 5.0), and a Blender whose Python has no numpy:
    one line each, exit 2, Blender's or Python's own reason quoted."""
    pytest.importorskip("bpy")
    newer = tmp_path / "newer.blend"
    subprocess.run([sys.executable, "-c", f"import bpy; bpy.ops.wm.save_as_mainfile(filepath={str(newer)!r})"],
                   check=True, capture_output=True)  # fmt: skip
    done = batch("render", newer, "--blender", BLENDER, *SMALL, "--seeds", "0:2", "--out", tmp_path / "a.npz", check=2)
    assert done.stderr.splitlines() == [
        f"error: the render failed: {BLENDER} exited with code 1: Failed to read blend file '{newer}', not a blend file"
    ]
    lacking = tmp_path / "blender-without-numpy"
    hide = "import sys; sys.modules['numpy'] = None"
    lacking.write_text(f'#!/bin/sh\nif [ "$1" = "--version" ]; then exec {BLENDER} "$@"; fi\n'
                       f'exec {BLENDER} --python-expr "{hide}" "$@"\n')  # fmt: skip
    lacking.chmod(0o755)
    done = batch("render", "--scene", "corner", "--blender", lacking, *SMALL, "--seeds", "0:2", "--out",
                 tmp_path / "b.npz", check=2)  # fmt: skip
    assert len(done.stderr.splitlines()) == 1 and done.stderr.startswith(
        f"error: Blender 3.4.1 ({BLENDER}) runs Python 3.11"
    ) and done.stderr.rstrip().endswith("which can't import numpy (import of numpy halted; None in sys.modules): "
                                        "install numpy for that Python (Debian's blender package: apt-get install "
                                        "python3-numpy)")  # fmt: skip


def test_a_renderer_hung_in_a_pass_is_stopped_by_the_pass_limit(tmp_path):
    """A Blender whose third pass never ends: stopped once no pass has ended for the limit (WELCH_PASS_TIMEOUT
    here), one line, exit 2, nothing left running."""
    hang = "\n".join(["import bpy, time", "count = [0]", "@bpy.app.handlers.persistent",
                      "def hang(*_args):", "    count[0] += 1", "    if count[0] > 2:", "        time.sleep(1000)",
                      "bpy.app.handlers.render_pre.append(hang)"])  # fmt: skip
    (tmp_path / "hang.py").write_text(hang)
    hung = tmp_path / "blender-that-hangs"
    hung.write_text(f'#!/bin/sh\nif [ "$1" = "--version" ]; then exec {BLENDER} "$@"; fi\n'
                    f'exec {BLENDER} --python "{tmp_path / "hang.py"}" "$@"\n')  # fmt: skip
    hung.chmod(0o755)
    line = [sys.executable, "-m", "batch", "render", "--scene", "corner", "--blender", str(hung), *SMALL, "--seeds",
            "0:6", "--out", str(tmp_path / "h.npz")]  # fmt: skip
    env = {**os.environ, "WELCH_PASS_TIMEOUT": "4"}
    done = subprocess.run(line, capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 2 and done.stderr.splitlines()[-1] == (
        f"error: {hung} finished no pass in 4 s and was stopped (WELCH_PASS_TIMEOUT)"
    )
    assert subprocess.run(["pgrep", "-f", str(tmp_path)], capture_output=True).returncode == 1
