"""Blender 5.2 LTS, the current release, as a user's own binary: Debian sid's 5.2.2 (on Python 3.14) in the root
./dev test makes (see tests/conftest.py), driven with ``--blender``. Its renders agree with the tool's bpy module
and with the bpy module of its own release."""

from __future__ import annotations

import subprocess
import sys

import pytest

import welch_core as wc
from batch.jobs import releases

pytestmark = pytest.mark.slow

SMALL = ("--scene", "corner", "--resolution", "32", "32", "--tile", "8", "--max-passes", "64", "--tolerance", "off")


def check(*args, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "batch", "check", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)  # fmt: skip


def test_a_blender_52_binary_renders_as_the_bpy_modules_do(tmp_path, blender52):
    """5.2.2 LTS against the tool's bpy 5.0.1, and against bpy 5.2.3 LTS (a binary on one side, a module on the
    other): no bias in either, each side recording the release that rendered it."""
    done = check(*SMALL, "--test-blender", blender52, "--out", tmp_path / "tool", cwd=tmp_path)
    assert done.returncode == 0 and done.stdout.startswith("verdict: no evidence of bias"), done.stderr[-2000:]
    test = wc.load_stats(tmp_path / "tool" / "test.npz", pixels=False)
    assert test.info.renderer_version.startswith("5.2.2") and test.info.sampling_pattern == "TABULATED_SOBOL"
    module = releases.python_of(releases.cache_folder() / "5.2.3")
    if not module.exists():
        pytest.skip(f"no bpy 5.2.3 environment in {releases.cache_folder()} (./dev test makes it)")
    done = check(*SMALL, "--blender", blender52, "--test-python", module, "--out", tmp_path / "own", cwd=tmp_path)
    assert done.returncode == 0 and done.stdout.startswith("verdict: no evidence of bias"), done.stderr[-2000:]
    ref = wc.load_stats(tmp_path / "own" / "reference.npz", pixels=False)
    test = wc.load_stats(tmp_path / "own" / "test.npz", pixels=False)
    assert ref.info.renderer_version.startswith("5.2.2") and test.info.renderer_version.startswith("5.2.3")
