"""Installed the way users install tools: the wheel holds only the tool's packages and the `welch-bias` command, a
venv without bpy compares and says in one line what a Cycles render needs, and under Python 3.13 (which Blender
5.1+ runs) with bpy 5.2 and numpy 2 the tool installs with its `cycles` extra, runs the demo and passes the quick
tests. The Python 3.13 environment is made by ``./dev test`` (cached by pyproject.toml); without one, those tests
are skipped with the reason."""

import hashlib
import json
import os
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch.jobs import launch, releases

ROOT = Path(__file__).resolve().parents[1]
#: The environment ./dev test makes for another Python (the function other_python there).
OTHER = (
    Path.home()
    / ".cache"
    / "welch-bias"
    / ("python3.13-" + hashlib.sha1((ROOT / "pyproject.toml").read_bytes()).hexdigest()[:12])
)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--disable-pip-version-check",
                    "-w", str(out), str(ROOT)], check=True, capture_output=True, text=True, timeout=600)  # fmt: skip
    (found,) = out.glob("welch_bias-*.whl")
    return found


@pytest.mark.slow
def test_the_wheel_holds_the_tools_packages_and_the_command_and_nothing_else(wheel):
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
        points = archive.read(entry_points).decode()
        metadata = archive.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    tops = {name.split("/")[0] for name in names}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"welch_core", "batch", "blender_addon"}, tops
    assert "welch-bias = batch.__main__:run" in points and "welch = batch.cli.pytest_plugin" in points
    assert "batch/present/report_template.html" in names and "batch/decide/suites/builtin.toml" in names
    requires = [line for line in metadata.splitlines() if line.startswith("Requires-Dist:")]
    core = [r for r in requires if "extra ==" not in r]
    assert not any("bpy" in r for r in core), core  # bpy is the extra `cycles`
    assert any("bpy==5.0.1" in r and "3.11" in r for r in requires) and any("bpy==5.2.3" in r for r in requires)
    for (major, minor), release in launch.BPY_RELEASES.items():  # what a render without bpy advises installing
        assert any(f"bpy=={release}" in r and f'"{major}.{minor}"' in r for r in requires), (release, requires)


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    """A fresh venv of this Python (3.11) with the wheel and its core dependencies only (numpy 2 where pip picks
    it, no bpy): its `welch-bias` command."""
    env_dir = tmp_path_factory.mktemp("installed") / "venv"
    venv.create(env_dir, with_pip=True)
    python = env_dir / "bin" / "python"
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", str(wheel)],
                   check=True, capture_output=True, text=True, timeout=900)  # fmt: skip
    return env_dir / "bin" / "welch-bias"


@pytest.mark.slow
def test_without_bpy_compare_works_and_a_cycles_render_says_what_to_install(installed, tmp_path):
    """A fresh venv, the wheel and its core dependencies only: `welch-bias compare` decides, and a render or a
    check with Cycles ends in one line naming the extra and --blender."""
    command = installed
    rng = np.random.default_rng(1)
    for name, first, shift in (("a", 0, 0.0), ("b", 100, 30.0)):
        sums = rng.normal(1000.0 + shift, 10.0, (8, 2, 2, 3))
        wc.save_stats(tmp_path / f"{name}.npz", wc.TileStats.from_sums(sums, range(first, first + 8), 64, 64, 32))
    done = subprocess.run([str(command), "compare", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--out",
                           str(tmp_path / "report")], capture_output=True, text=True, cwd=tmp_path)  # fmt: skip
    assert done.returncode == 1 and done.stdout.startswith("verdict: biased"), done.stdout + done.stderr
    assert json.loads((tmp_path / "report" / "report.json").read_text())["outcome"]["verdict"] == "biased"
    help_text = subprocess.run([str(command), "--help"], capture_output=True, text=True).stdout
    assert help_text.startswith("usage: welch-bias ")
    for args in (["render", "--scene", "corner", "--seeds", "0:2", "--spp", "1", "--out", "r.npz"],
                 ["check", "--scene", "corner", "--unpaired", "--out", "c"],
                 ["suite", "run", "builtin", "--out", "s"]):  # fmt: skip
        done = subprocess.run([str(command), *args], capture_output=True, text=True, cwd=tmp_path)
        assert done.returncode == 2, done.stdout + done.stderr
        assert done.stderr.strip().splitlines() == [
            "error: rendering with Cycles needs the bpy module, which this Python 3.11 lacks: install bpy 5.0.1 with "
            f"{command.parent / 'python'} -m pip install bpy==5.0.1 (from a checkout of welch-bias: pip install "
            "'.[cycles]'), or render with --blender PATH (a Blender binary) or --python PATH (a Python with bpy)"
        ]


def installed_check(command: Path, blender: str, cwd: Path) -> subprocess.CompletedProcess:
    """A tiny unpaired `welch-bias check` of the corner scene, both sides rendered by `blender`, run in `cwd`."""
    return subprocess.run([str(command), "check", "--scene", "corner", "--resolution", "32", "32", "--unpaired",
                           "--max-passes", "4", "--blender", blender, "--out", "check"], capture_output=True, text=True,
                          cwd=cwd, timeout=600)  # fmt: skip


def assert_rendered_by(folder: Path, version: str) -> None:
    for side in ("reference", "test"):
        run = wc.load_stats(folder / f"{side}.npz", pixels=False)
        assert run.n >= 2 and run.info.renderer_version.startswith(version), (side, run.n, run.info.renderer_version)


@pytest.mark.slow
def test_an_installed_tool_drives_a_blender_of_another_python(installed, blender52, tmp_path):
    """The tool installed into a venv of Python 3.11 drives Blender 5.2.2, which runs Python 3.14 with its own
    numpy: only the tool's packages reach that Python (the venv's numpy, built for 3.11, would not import)."""
    done = installed_check(installed, blender52, tmp_path)
    assert done.returncode in (0, 3), done.stdout[-2000:] + done.stderr[-2000:]
    assert_rendered_by(tmp_path / "check", "5.2.2")


@pytest.mark.slow
def test_an_installed_tool_renders_with_the_bpy_module_of_another_python(installed, tmp_path):
    """`--python` with the bpy 5.2.3 environment (Python 3.13, its own numpy) from the tool in a Python 3.11 venv:
    the other Python imports the tool's packages and nothing else of the venv."""
    module = releases.python_of(releases.cache_folder() / "5.2.3")
    if not module.exists():
        pytest.skip(f"no bpy 5.2.3 environment in {releases.cache_folder()} (./dev test makes it)")
    done = subprocess.run([str(installed), "render", "--scene", "corner", "--resolution", "32", "32", "--seeds", "0:2",
                           "--spp", "1", "--python", str(module), "--out", "r.npz"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    run = wc.load_stats(tmp_path / "r.npz", pixels=False)
    assert run.n == 2 and run.info.renderer_version.startswith("5.2.3"), run.info.renderer_version


@pytest.fixture(scope="module")
def other_python(wheel) -> Path:
    """Python 3.13's environment with this tree's wheel installed into it (its dependencies are there already)."""
    python = OTHER / "bin" / "python"
    if not (OTHER / ".ready").exists():
        pytest.skip(f"no Python 3.13 environment at {OTHER}: ./dev test makes it where a Python 3.13 can be had")
    subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "--force-reinstall",
                    "--no-deps", str(wheel)], check=True, capture_output=True, text=True, timeout=600)  # fmt: skip
    return python


@pytest.mark.slow
def test_under_python_313_the_cycles_extra_installs_and_the_demo_runs(other_python, wheel, tmp_path):
    """The wheel with its `cycles` extra into Python 3.13's environment (bpy 5.2.3, numpy 2; the dependencies are
    there already, so the install is the wheel's own), then `welch-bias demo`: exit 0, the planted bias found."""
    python = other_python
    check = subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "--dry-run",
                            f"{wheel}[cycles]"], capture_output=True, text=True, timeout=600)  # fmt: skip
    assert check.returncode == 0, check.stderr  # the extra resolves under 3.13 (to what is installed)
    done = subprocess.run([str(OTHER / "bin" / "welch-bias"), "demo", "--out", str(tmp_path / "demo")],
                          capture_output=True, text=True, cwd=tmp_path, timeout=600)  # fmt: skip
    assert done.returncode == 0 and "verdict: biased" in done.stdout, done.stdout[-2000:] + done.stderr[-2000:]
    versions = subprocess.run(
        [
            str(python),
            "-c",
            "import bpy, numpy, sys; print(sys.version_info[:2], bpy.app.version[:2], numpy.__version__)",
        ],
        capture_output=True,
        text=True,
    ).stdout
    assert versions.startswith("(3, 13) (5, 2) 2."), versions


@pytest.mark.slow
def test_an_installed_tool_of_python_313_drives_blender_34(other_python, blender34, tmp_path):
    """The tool installed into Python 3.13's environment (numpy 2) drives Debian's Blender 3.4, which runs the
    system Python 3.11 with its numpy 1.24."""
    done = installed_check(other_python.parent / "welch-bias", blender34, tmp_path)
    assert done.returncode in (0, 3), done.stdout[-2000:] + done.stderr[-2000:]
    assert_rendered_by(tmp_path / "check", "3.4.1")


@pytest.mark.slow
def test_the_quick_tests_pass_under_python_313(other_python):
    """`pytest -m "not slow"` under Python 3.13 with bpy 5.2.3 and numpy 2 (this file's own tests left out)."""
    python = other_python
    env = {k: v for k, v in os.environ.items() if k != "PYTEST_ADDOPTS"}
    done = subprocess.run([str(python), "-m", "pytest", "-q", "-m", "not slow", "-p", "no:cacheprovider", "-x",
                           "--deselect", "tests/test_packaging.py"], capture_output=True, text=True, cwd=ROOT,
                          env=env, timeout=1200)  # fmt: skip
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    print(done.stdout.strip().splitlines()[-1])
