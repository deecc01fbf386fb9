"""Audits rendered for real with Cycles, small (32x32, at most 24 passes a side a check): a control found and
confirmed, the default against itself clean, a second run that reuses every decided cell, a planted difference of
a setting documented as noise-only confirmed, explained and reported with exit code 1 (through ``suite run`` of an
audit file, on a .blend with Blender's default clamp and Filter Glossy), and the audit page in headless Chromium."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
SCREENSHOT = ROOT / "docs" / "screenshots" / "audit.png"
pytestmark = pytest.mark.slow

#: A tight indirect clamp: biased by design (a control), found in the corner scene within 2 passes.
TIGHT = """
[[change]]
name = "tight_clamp"
setting = "cycles.sample_clamp_indirect"
reference = ["cycles.sample_clamp_indirect=0"]
test = ["cycles.sample_clamp_indirect=0.05"]
documented = "bias"
samples = 1
why = "a tight indirect clamp, a control"
"""
#: A tight direct clamp wrongly documented as noise-only: a finding the audit must report.
PLANTED = """
[[change]]
name = "planted"
setting = "cycles.sample_clamp_direct"
reference = ["cycles.sample_clamp_direct=0"]
test = ["cycles.sample_clamp_direct=0.05"]
documented = "noise"
samples = 1
why = "a direct clamp said to change only the noise"
"""
SMALL = ["--resolution", "32", "32", "--tile", "8", "--max-passes", "24"]


def batch(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "batch", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, timeout=900)  # fmt: skip


@pytest.fixture(scope="module")
def audited(tmp_path_factory):
    pytest.importorskip("bpy")
    folder = tmp_path_factory.mktemp("audit")
    (folder / "own.toml").write_text(TIGHT)
    start = time.perf_counter()
    done = batch("audit", "--scene", "corner", "--scene", "corner_mesh_light", "--changes", folder / "own.toml",
                 "--only", "light_tree", "tight_clamp", *SMALL, "--out", folder / "out")  # fmt: skip
    return folder / "out", done, time.perf_counter() - start


def test_a_control_is_found_and_confirmed_and_the_default_against_itself_is_clean(audited):
    out, done, _seconds = audited
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert lines[0] == "audit: asking current which of the 2 changes it can render"
    assert (
        "6 cells (0 not applicable), at most 24 passes a side and 20 s of rendering a cell (at least 8 passes a side "
        "whatever their seconds), 32x32, 8-px tiles" in lines[1]
    )
    assert "alpha / 6 = 0.00167" in lines[2] and lines[3].startswith("audit: 6 cells to run: about ")
    assert [line.split(":")[1].strip() for line in lines[4:10]] == [
        "1/6 default on corner",
        "2/6 default on corner_mesh_light",
        "3/6 light_tree on corner",
        "4/6 light_tree on corner_mesh_light",
        "5/6 tight_clamp on corner",
        "6/6 tight_clamp on corner_mesh_light",
    ]
    summary = json.loads((out / "summary.json").read_text())
    cells = {(c["change"], c["scene"]): c for c in summary["cells"]}
    found = cells[("tight_clamp", "corner")]
    assert found["status"] == "biased" and found["first"]["verdict"] == found["confirm"]["verdict"] == "biased"
    assert found["first"]["alpha"] == found["confirm"]["alpha"] == pytest.approx(0.01 / 6)
    assert found["first"]["seeds"][0] != found["confirm"]["seeds"][0]  # confirmed on fresh seeds
    confirm = json.loads((out / found["confirm"]["report"]).with_name("report.json").read_text())
    assert confirm["pixel_variance"]["mode"] == "off" and not confirm["pixel_variance"]["used"]  # tile sums alone
    assert found["confirm"]["layers"]["explained_by"]  # the light component that carries it
    assert found["message"].startswith("found (biased by design): whole image -")
    for scene in ("corner", "corner_mesh_light"):
        assert cells[("default", scene)]["status"] != "biased"
    assert summary["findings"] == [] and summary["unfound_controls"] == [] and summary["exit_code"] == 0
    found = len(summary["controls_found"]["tight_clamp"])
    assert f"{found} control{'s' if found > 1 else ''} found; findings: none" in done.stdout  # no finding in "biased"
    assert summary["cells_k"] == 6 and summary["level"] == pytest.approx(0.01 / 6)
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("6", "0", "0")
    assert (out / "index.html").read_text().startswith("<!doctype html>")


def test_a_second_run_reuses_every_decided_cell(audited):
    out, first, seconds = audited
    before = json.loads((out / "summary.json").read_text())["cells"]
    start = time.perf_counter()
    done = batch("audit", "--scene", "corner", "--scene", "corner_mesh_light", "--changes", out.parent / "own.toml",
                 "--only", "light_tree", "tight_clamp", *SMALL, "--resume", "--out", out)  # fmt: skip
    again = time.perf_counter() - start
    assert done.returncode == first.returncode
    cells = [line for line in done.stdout.splitlines() if "/6 " in line]
    assert len(cells) == 6 and all(": reused: " in line for line in cells)
    assert "asking" not in done.stdout  # what the release supports is read from the audit, not asked again
    assert "6 cells decided already; 0 cells to run" in done.stdout
    assert again < seconds / 2
    after = json.loads((out / "summary.json").read_text())["cells"]
    assert [(c["status"], c["first"]["passes"]) for c in after] == [(c["status"], c["first"]["passes"]) for c in before]
    other = batch("audit", "--scene", "corner", "--only", "light_tree", *SMALL, "--resume", "--out", out)
    assert other.returncode == 2 and "can't resume the audit in" in other.stderr and "other scenes, changes" in (
        other.stderr)  # fmt: skip


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    """``suite run`` of an audit file: a .blend of the corner scene with Blender's default clamp and Filter Glossy,
    and a planted change documented as noise-only."""
    pytest.importorskip("bpy")
    folder = tmp_path_factory.mktemp("planted")
    blend = folder / "room.blend"
    script = ("import sys, bpy; sys.path.insert(0, sys.argv[-2]); from batch.blender.scenes import build_scene;"
              "bpy.ops.wm.read_factory_settings(use_empty=True); s = build_scene('corner');"
              "s.cycles.sample_clamp_indirect = 10; s.cycles.blur_glossy = 1.0;"
              "bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1])")  # fmt: skip
    subprocess.run([sys.executable, "-c", script, str(ROOT), str(blend)], check=True, capture_output=True)
    (folder / "welch_audit.toml").write_text('[audit]\nname = "planted"\nblends = ["room.blend"]\nchanges = "none"\n'
                                             'resolution = [32, 32]\ntile = 8\npasses = 24\n' + PLANTED)  # fmt: skip
    done = batch("suite", "run", folder / "welch_audit.toml", "--out", folder / "out")
    return folder / "out", done


def test_a_planted_difference_is_confirmed_explained_and_fails_the_audit(planted):
    out, done = planted
    assert done.returncode == 1, done.stdout[-3000:] + done.stderr[-3000:]
    assert "findings: planted/room" in done.stdout
    summary = json.loads((out / "summary.json").read_text())
    (cell,) = [c for c in summary["cells"] if c["change"] == "planted"]
    assert cell["status"] == "biased" and summary["findings"] == ["planted/room"]
    explain = cell["explain"]
    assert explain["verdict"] == "biased" and explain["meaning"].startswith("the change itself moves the image")
    report = json.loads((out / explain["report"]).with_name("report.json").read_text())
    overrides = report["reference"]["info"]["overrides"]
    assert "cycles.sample_clamp_indirect=0" in overrides and "cycles.blur_glossy=0" in overrides
    command = cell["command"]
    assert command.startswith("welch-bias check ") and "--set cycles.sample_clamp_direct=0.05" in command
    assert command.endswith("(with cycles.sample_clamp_direct=0 in the scene file itself)")
    assert cell["confirm"]["layers"]["explanation"].startswith("the difference is in")
    failure = ET.parse(out / "junit.xml").getroot().find(".//testcase[@name='planted/room']/failure")
    assert failure is not None


def test_the_audit_page_in_a_browser(planted, tmp_path):
    playwright = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    if CHROMIUM is None:
        pytest.skip("no chromium on PATH (apt-get install chromium; ./dev test does it)")
    out, _done = planted
    args = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--no-first-run"]
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=args)
        page = browser.new_page(viewport={"width": 1200, "height": 900})
        errors = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto((out / "index.html").as_uri())
        assert page.locator("#title").inner_text().endswith("1 confirmed difference of noise-only settings")
        finding = page.locator("#findings li.finding")
        assert finding.count() == 1 and finding.first.get_attribute("data-key") == "planted/room"
        text = finding.first.inner_text()
        assert "biased-by-design settings off: the change itself moves the image" in text
        assert "light components: the difference is in" in text and "reproduce: welch-bias check" in text
        cells = page.locator("#cells td.cell")
        assert cells.count() == 2
        assert page.locator('#cells td.cell[data-key="planted/room"]').get_attribute("data-status") == "biased"
        assert "alpha 0.01 over the audit's 2 cells" in page.locator("#alpha").inner_text()
        page.screenshot(path=str(tmp_path / "audit.png"), full_page=True)
        page.locator('#cells td.cell[data-key="planted/room"] a').first.click()
        page.wait_for_load_state()
        assert page.url.endswith("/cells/planted/room/first/report.html")
        assert page.locator("#verdict").inner_text() == "Biased"
        browser.close()
    assert errors == []
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(tmp_path / "audit.png", SCREENSHOT)


def test_a_release_says_which_settings_it_has():
    """``render --probe`` with overrides, a pattern or a device sets the scene up as the passes would: what the
    release lacks is refused in one line, persistent data may be turned off."""
    pytest.importorskip("bpy")
    from batch.decide.audit import probe_release
    from batch.jobs.job import RenderJob

    def job(**kwargs) -> RenderJob:
        return RenderJob(out="probe.npz", seeds=(0,), scene="corner", python=sys.executable, **kwargs)

    plain, persistent, missing, pattern = probe_release([
        job(), job(overrides=("render.use_persistent_data=false",)), job(overrides=("cycles.no_such_setting=1",)),
        job(sampling_pattern="NO_SUCH_PATTERN")])  # fmt: skip
    assert plain is None and persistent is None
    assert missing == "--set cycles.no_such_setting=1: 'CyclesRenderSettings' has no property 'no_such_setting'"
    assert pattern.startswith("--sampling-pattern NO_SUCH_PATTERN is not a pattern of Blender 5.")
