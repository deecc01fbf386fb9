"""Other Cycles releases through their bpy module: `--python PATH` (checked in one line when it is not a Python,
has no bpy or an old one), the cached environments of `python -m batch bpy VERSION`, and a real render and check
through bpy 4.5.4 LTS when its environment is there (``./dev test`` makes it; skipped otherwise, with the reason)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import welch_core as wc
from batch.errors import BatchError, Exit
from batch.jobs import releases
from batch.jobs.job import RenderJob
from batch.jobs.launch import bpy_version, job_command

ROOT = Path(__file__).resolve().parents[2]
#: The second release the tests render with (an LTS with the same Python as the tool's bpy).
RELEASE = os.environ.get("WELCH_TEST_BPY", "4.5.4")


def fake(tmp_path, name: str, body: str) -> str:
    path = tmp_path / name
    path.write_text("#!/bin/sh\n" + body)
    path.chmod(0o755)
    return str(path)


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("echo hello; exit 0\n", "is not a Python interpreter: it answered 'hello'"),
        ("exit 3\n", "is not a Python interpreter: it answered 'nothing, exit code 3'"),
        ('echo "python 3.11.2"; echo "bpy 3.6.5 0123abcd"\n', "has bpy 3.6.5: the tool drives bpy 4.2 and later"),
    ],
)
def test_a_python_that_cannot_render_is_refused_in_one_line(tmp_path, body, message):
    path = fake(tmp_path, "python", body)
    with pytest.raises(BatchError) as info:
        bpy_version(path)
    assert str(info.value) == f"--python {path} {message}"


def test_a_python_without_bpy_says_how_to_get_one():
    python = shutil.which("python3.11") or "/usr/bin/python3"
    if not os.path.exists(python) or subprocess.run([python, "-c", "import bpy"], capture_output=True).returncode == 0:
        pytest.skip(f"no Python without bpy at {python}")
    with pytest.raises(BatchError, match=r"has no bpy module \(ModuleNotFoundError.*python -m batch bpy VERSION$"):
        bpy_version(python)
    with pytest.raises(BatchError, match="no such program"):
        bpy_version("/nonexistent/python")


def test_a_job_runs_in_the_other_python_with_only_the_tools_code_on_its_path():
    job = RenderJob(out="x.npz", seeds=range(4), scene="corner", python="/opt/bpy-4.5/bin/python")
    command = job_command(job, base_env={"PYTHONPATH": "/this/venv/site-packages", "PYTHONHOME": "/x", "A": "1"})
    assert command.argv[:4] == ["/opt/bpy-4.5/bin/python", str(ROOT / "batch" / "blender_entry.py"), "--", "render"]
    assert "--python" not in command.argv  # the child renders with its own bpy
    # The entry script imports the tool's packages from their folder, and nothing else of it (a venv's numpy).
    assert "PYTHONPATH" not in command.env and "PYTHONHOME" not in command.env and command.env["A"] == "1"
    with pytest.raises(BatchError, match="give --blender or --python, not both"):
        job.replace(blender="/opt/blender")


def batch(*args, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "batch", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, env=env)  # fmt: skip


def test_check_takes_a_binary_or_a_python_for_each_side(tmp_path):
    """A binary on one side and another release's bpy module on the other (a user's Blender against the module of
    its release) is one check; both for one side is refused."""
    from batch.cli.commands import build_parser
    from batch.decide.check_job import check_job_from_args

    args = build_parser().parse_args(["check", "--scene", "corner", "--blender", "/opt/b", "--test-python", "/opt/p",
                                      "--out", str(tmp_path / "c")])  # fmt: skip
    job = check_job_from_args(args)
    assert (job.reference.blender, job.reference.python) == ("/opt/b", None)
    assert (job.test.blender, job.test.python) == (None, "/opt/p") and not job.paired
    done = batch("check", "--scene", "corner", "--blender", "/opt/b", "--python", "/opt/p", "--out", tmp_path)
    assert done.returncode == Exit.USAGE
    assert done.stderr.startswith("error: give a side's build as a Blender binary or as a Python with bpy, not both")


def test_the_release_cache(tmp_path):
    env = {**os.environ, "WELCH_BPY_CACHE": str(tmp_path / "cache")}
    done = batch("bpy", "4.5", env=env)
    assert done.returncode == Exit.USAGE
    assert (
        done.stderr.strip() == "error: a bpy release is a full version such as 4.5.4 (4.5 would mean 4.5.0), got '4.5'"
    )
    done = batch("bpy", "--list", env=env)
    assert done.returncode == 0 and "no bpy release in" in done.stderr
    # A broken cached environment is listed as broken, not taken for a release.
    broken = tmp_path / "cache" / "4.9.9" / "bin"
    broken.mkdir(parents=True)
    fake(broken.parent, "bin/python", "exit 1\n")
    done = batch("bpy", "--list", env=env)
    assert done.stdout.startswith("4.9.9\t") and "broken: --python" in done.stdout


def test_each_release_line_names_its_python_and_one_that_is_missing_is_said_in_one_line(tmp_path):
    assert [releases.python_needed(v) for v in ("4.1.1", "4.2.23", "5.0.1", "5.1.0", "5.2.3")] == [
        "3.10", "3.11", "3.11", "3.13", "3.13"
    ]  # fmt: skip
    here = f"{sys.version_info[0]}.{sys.version_info[1]}"  # these tests run under 3.11 and, the quick ones, under 3.13
    own, other = ("5.2.3", "4.1.1") if here == "3.13" else ("5.0.1", "5.2.3")
    need = releases.python_needed(other)
    assert releases.base_python(own) == sys.executable
    env = {**os.environ, "WELCH_BPY_CACHE": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin",
           "PYENV_ROOT": str(tmp_path / "no-pyenv")}  # fmt: skip
    done = batch("bpy", other, env=env)
    assert done.returncode == Exit.USAGE and done.stderr.splitlines() == [
        f"error: bpy {other} needs Python {need} (its Blender runs it) and there is no python{need} on PATH: install "
        "one, or name it with --base-python PATH"
    ]
    done = batch("bpy", other, "--base-python", sys.executable, env=env)
    assert done.stderr.splitlines() == [
        f"error: --base-python {sys.executable}: bpy {other} needs Python {need}, this is {here}"
    ]
    assert not (tmp_path / "cache").exists()  # nothing made


def release_python() -> str:
    folder = releases.cache_folder() / RELEASE
    python = releases.python_of(folder)
    if not python.exists():
        pytest.skip(f"no bpy {RELEASE} environment in {releases.cache_folder()} (./dev test makes it: "
                    f"python -m batch bpy {RELEASE})")  # fmt: skip
    return str(python)


@pytest.mark.slow
def test_render_and_check_through_another_release(tmp_path):
    python = release_python()
    out = tmp_path / "old.npz"
    done = batch("render", "--scene", "corner", "--resolution", 32, 32, "--tile", 16, "--seeds", "0:6", "--spp", 1,
                 "--python", python, "--out", out)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    stats = wc.load_stats(out)
    assert stats.n == 6 and stats.info.renderer_version.startswith(RELEASE) and stats.info.build_hash
    done = batch("check", "--scene", "corner", "--resolution", 32, 32, "--test-python", python, "--max-passes", 8,
                 "--out", tmp_path / "check")  # fmt: skip
    assert done.returncode in (Exit.OK, Exit.INCONCLUSIVE), done.stderr[-2000:]
    assert f"renderer_version: {wc.load_stats(tmp_path / 'check' / 'reference.npz').info.renderer_version}" in (
        (tmp_path / "check" / "report.json").read_text()
    )


@pytest.mark.slow
def test_a_release_matrix_and_the_fog_bisect(tmp_path):
    """The matrix of bpy 4.5.4 and this bpy on the corner scene (no difference there), and the bisect that pins
    the blue-noise fog difference (docs/findings/blue_noise_volume.md) to the newer of the two: Tabulated Sobol
    against blue noise in the built-in volume scene at 2 spp a pass, within each release."""
    release_python()
    done = batch("matrix", "--scene", "corner", "--resolution", 32, 32, "--builds", RELEASE, "current", "--passes",
                 16, "--out", tmp_path / "m")  # fmt: skip
    assert done.returncode == Exit.OK, done.stdout[-2000:] + done.stderr[-2000:]
    assert f"{RELEASE} vs current: no evidence of bias" in done.stdout
    assert (tmp_path / "m" / "index.html").is_file() and (tmp_path / "m" / "junit.xml").is_file()
    done = batch("bisect", "--scene", "volume", "--resolution", 64, 64, "--spp", 2, "--sampling-pattern",
                 "TABULATED_SOBOL", "--test-sampling-pattern", "BLUE_NOISE", "--builds", RELEASE, "current",
                 "--passes", 48, "--out", tmp_path / "b")  # fmt: skip
    assert done.returncode == Exit.OK, done.stdout[-2000:] + done.stderr[-2000:]
    found = json.loads((tmp_path / "b" / "bisect.json").read_text())
    assert found["first"] == "current" and [s["pair"]["verdict"] for s in found["steps"]] == ["biased", "no_evidence"]


@pytest.mark.slow
def test_the_current_lts_against_this_bpy(tmp_path):
    """Blender 5.2 LTS (bpy 5.2.3 on Python 3.13, made by ./dev test) against the tool's 5.0.1: the corner scene
    converges to the same image, and the run records the release that rendered it."""
    python = releases.python_of(releases.cache_folder() / "5.2.3")
    if not python.exists():
        pytest.skip(f"no bpy 5.2.3 environment in {releases.cache_folder()} (./dev test makes it where a Python "
                    "3.13 can be had: python -m batch bpy 5.2.3)")  # fmt: skip
    done = batch("check", "--scene", "corner", "--resolution", 32, 32, "--tile", 8, "--test-python", python,
                 "--max-passes", 64, "--tolerance", "off", "--out", tmp_path / "c")  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("verdict: no evidence of bias")
    test = wc.load_stats(tmp_path / "c" / "test.npz", pixels=False)
    assert test.info.renderer_version.startswith("5.2.3") and test.info.sampling_pattern == "TABULATED_SOBOL"
