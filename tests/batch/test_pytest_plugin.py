"""The pytest plugin (batch/cli/pytest_plugin.py) the way a renderer project uses it: a folder holding only a suite
file, pytest run there with the installed package's plugin. Renders with Cycles (32x32, 16 passes)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import pytest

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
