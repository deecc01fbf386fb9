"""The pytest plugin (batch/cli/pytest_plugin.py) the way a renderer project uses it: a folder holding only a suite
file, pytest run there with the installed package's plugin. Renders with Cycles (32x32, 16 passes)."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from tests.helpers.audits import PLANTED, TIGHT
from tests.helpers.pytest_runs import pytest_in, skip_unless_plugin_installed

pytestmark = pytest.mark.slow

SUITE = """
[suite]
name = "smoke"
tolerance = "10%"

[[case]]
name = "corner"
scene = "corner"
resolution = [32, 32]
tile = 16
passes = 16
devices = ["CPU", "OPTIX"]
why = "the smallest scene with direct and indirect light"
"""


@pytest.fixture
def project(tmp_path):
    skip_unless_plugin_installed()
    pytest.importorskip("bpy")
    (tmp_path / "welch_smoke.toml").write_text(SUITE)
    return tmp_path


def test_cases_are_tests_blessed_once_and_a_planted_change_fails(project):
    listed = pytest_in(project, "--collect-only", "-q")
    assert "welch_smoke.toml::corner[CPU]" in listed.stdout and "welch_smoke.toml::corner[OPTIX]" in listed.stdout

    missing = pytest_in(project, "-k", "CPU")
    assert missing.returncode == 1
    refs = project / "welch_smoke-refs"
    assert f"no reference for corner in {refs}: run pytest with --welch-bless" in missing.stdout

    blessed = pytest_in(project, "--welch-bless")
    assert blessed.returncode == 0, blessed.stdout[-3000:]
    assert "PASSED welch_smoke.toml::corner[CPU]" in blessed.stdout
    assert "SKIPPED" in blessed.stdout and "OPTIX" in blessed.stdout  # no such device here: skipped with the reason
    stored = (refs / "corner.npz").read_bytes()

    again = pytest_in(project, "-k", "CPU")
    assert again.returncode == 0 and (refs / "corner.npz").read_bytes() == stored  # the reference is kept

    # A reference that is not the case's (its provenance names another case): the failure names a command that
    # renders it anew in the plugin's folder of references, and after it the case passes.
    provenance = refs / "corner.json"
    provenance.write_text(json.dumps({**json.loads(provenance.read_text()), "case": "other"}))
    wrong = pytest_in(project, "-k", "CPU")
    assert wrong.returncode == 1 and "not this case's reference" in wrong.stdout
    command = re.search(r"\(to render it anew: (welch-bias suite bless .*? --force)\)", wrong.stdout).group(1)
    assert shlex.split(command)[3:] == [str(project / "welch_smoke.toml"), "--refs", str(refs), "--filter", "corner",
                                        "--force"]  # fmt: skip
    done = subprocess.run([sys.executable, "-m", "batch", *shlex.split(command)[1:]], cwd=project,
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert pytest_in(project, "-k", "CPU").returncode == 0

    planted = pytest_in(project, "-k", "CPU", "--welch-set", "cycles.max_bounces=0", "--junitxml", "j.xml")
    assert planted.returncode == 1
    line = next(x for x in planted.stdout.splitlines() if x.startswith("failed: biased: whole image"))
    assert "; differences: max_bounces: 1024 → 0; overrides of the test side: cycles.max_bounces=0 (report: " in line
    assert re.search(r"; \d+ passes; differences", line)
    report = line.rsplit("(report: ", 1)[1].rstrip(")")
    assert report == str(project / "tmp" / "welch" / "smoke" / "corner" / "CPU" / "report.html")
    assert open(report).read(15).lower() == "<!doctype html>"
    failure = ET.parse(project / "j.xml").getroot().find(".//testcase[@name='corner[CPU]']/failure")
    assert failure is not None and "biased" in failure.get("message")


def test_a_bad_suite_file_is_one_collection_error(project):
    (project / "welch_bad.toml").write_text('[[case]]\nname = "x"\nscene = "no_such_scene"\n')
    done = pytest_in(project, "--collect-only")
    assert done.returncode == 2  # pytest: errors during collection
    assert "welch_bad.toml" in done.stdout and "no_such_scene" in done.stdout
    assert "Traceback" not in done.stdout


AUDIT = (
    """
[audit]
name = "smoke"
scenes = ["corner"]
changes = "none"
resolution = [32, 32]
tile = 8
passes = 24
"""
    + TIGHT
    + PLANTED
)


def test_an_audit_file_is_a_test_per_cell_and_per_control(tmp_path):
    skip_unless_plugin_installed()
    pytest.importorskip("bpy")
    (tmp_path / "welch_audit.toml").write_text(AUDIT)
    listed = pytest_in(tmp_path, "--collect-only", "-q")
    assert [line for line in listed.stdout.splitlines() if "::" in line] == [
        "welch_audit.toml::default[corner]",
        "welch_audit.toml::tight_clamp[corner]",
        "welch_audit.toml::tight_clamp[found]",
        "welch_audit.toml::planted[corner]",
    ]
    done = pytest_in(tmp_path, "--welch-out", tmp_path / "out", "--junitxml", "j.xml", timeout=900)
    assert done.returncode == 1, done.stdout[-3000:]
    for passed in ("default[corner]", "tight_clamp[corner]", "tight_clamp[found]"):
        assert f"PASSED welch_audit.toml::{passed}" in done.stdout
    line = next(x for x in done.stdout.splitlines() if x.startswith("planted documented to change only the noise"))
    assert ": biased: whole image -" in line and "(report: " in line
    summary = tmp_path / "out" / "audit-smoke" / "summary.json"
    assert summary.is_file() and (summary.parent / "index.html").is_file()
    again = pytest_in(tmp_path, "--welch-out", tmp_path / "out", "-k", "tight_clamp")  # decided cells reused
    assert again.returncode == 0 and "2 passed" in again.stdout
