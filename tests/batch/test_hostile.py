"""Hostile inputs against the surfaces of check, suite, workers, layers, --tile and the report: each answered in
one line, or by a verdict that says what was tested, never by a wrong answer with exit 0."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch import cli
from batch.decide import suite as suites
from batch.errors import BatchError, Exit
from batch.jobs.lock import OutputLock
from batch.present.junit import junit_xml
from batch.present.pipeline import present

ROOT = Path(__file__).resolve().parents[2]


def save(path, sums, seeds, height, width, tile, info=None):
    stats = wc.TileStats.from_sums(sums, seeds, height, width, tile, info)
    wc.save_stats(path, stats)
    return str(path)


def strip_runs(tmp_path, brighter: float = 1.2):
    """A 64x48 image in 16-px tiles whose bottom 16 rows are `brighter` on the test side: the strip a 32-px
    tile does not reach whole."""
    rng = np.random.default_rng(7)
    mean = np.full((3, 4, 3), 100.0)
    shifted = mean.copy()
    shifted[2] *= brighter
    ref = save(tmp_path / "ref.npz", rng.normal(mean, 2.0, (32, 3, 4, 3)), range(32), 48, 64, 16)
    test = save(tmp_path / "test.npz", rng.normal(shifted, 2.0, (32, 3, 4, 3)), range(100, 132), 48, 64, 16)
    return ref, test


def test_a_tile_that_does_not_divide_the_image_leaves_no_strip_untested(tmp_path, capsys):
    ref, test = strip_runs(tmp_path)
    assert cli.main(["compare", ref, test, "--tile", "32", "--out", str(tmp_path / "r")]) == Exit.BIASED
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert report["grid"] == {"width": 64, "height": 48, "tile": 32, "tiles_x": 2, "tiles_y": 2}
    assert report["dropped_pixels"] == 0
    top = report["top_tiles"][0]
    assert (top["y"], top["height"]) == (32, 16)  # the partial row of tiles: 16 px high
    capsys.readouterr()
    code = cli.main(["compare", ref, test, "--tile", "32", "--tolerance", "5%", "--out", str(tmp_path / "e")])
    assert code == Exit.BIASED and capsys.readouterr().out.startswith("verdict: biased")


def test_a_file_of_an_earlier_version_says_which_pixels_it_leaves_untested(tmp_path):
    rng = np.random.default_rng(8)
    old = wc.TileStats.from_sums(rng.normal(100.0, 2.0, (8, 3, 4, 3)), range(8), 56, 64, 16, edges="dropped")
    new = wc.TileStats.from_sums(rng.normal(100.0, 2.0, (8, 3, 4, 3)), range(8, 16), 56, 64, 16, edges="dropped")
    summary = present(tmp_path, wc.compare(old, new), old, new)
    assert summary["dropped_pixels"] == 64 * 8
    assert any("512 pixels at the right and bottom edges are in no tile" in w for w in summary["warnings"])


def test_text_in_names_can_not_end_or_comment_out_the_reports_script(tmp_path):
    hostile = "<!--<script></script>&amp;"
    rng = np.random.default_rng(9)
    info = wc.RunInfo(scene=hostile, renderer=hostile, overrides=(f"objects['x'].name={hostile}",))
    ref = wc.TileStats.from_sums(rng.normal(100, 1, (8, 2, 2, 3)), range(8), 32, 32, 16, info)
    test = wc.TileStats.from_sums(rng.normal(100, 1, (8, 2, 2, 3)), range(8, 16), 32, 32, 16, info)
    present(tmp_path, wc.compare(ref, test), ref, test)
    page = (tmp_path / "report.html").read_text()
    opening = '<script type="application/json" id="report-data">'
    start = page.index(opening) + len(opening)
    block = page[start : page.index("</script>", start)]
    assert "<" not in block and ">" not in block and "&" not in block
    assert json.loads(block)["summary"]["reference"]["info"]["scene"] == hostile


def test_junit_is_well_formed_whatever_the_messages_hold():
    case = suites.Case(name="c", scene="corner")
    result = suites.CaseResult(case, "CPU", "failed", "biased", "Cycles said \x1b[31m\x00red\x07 and \ud800")
    root = ET.fromstring(junit_xml("suite \x0b name", [result]))
    failure = root.find("testsuite/testcase/failure")
    assert "\ufffd" in failure.attrib["message"] and "\x00" not in failure.attrib["message"]


def test_a_report_is_replaced_whole_or_not_at_all(tmp_path, monkeypatch):
    rng = np.random.default_rng(10)
    ref = wc.TileStats.from_sums(rng.normal(100, 1, (8, 2, 2, 3)), range(8), 32, 32, 16)
    test = wc.TileStats.from_sums(rng.normal(100, 1, (8, 2, 2, 3)), range(8, 16), 32, 32, 16)
    present(tmp_path, wc.compare(ref, test), ref, test)
    before = {name: (tmp_path / name).read_bytes() for name in ("report.json", "report.html", "pvalues.exr")}
    real_fsync, calls = os.fsync, []

    def full_at_the_third_file(fd):  # two files of the new report are written, then the disk is full
        calls.append(fd)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        return real_fsync(fd)

    monkeypatch.setattr(os, "fsync", full_at_the_third_file)
    with pytest.raises(OSError, match="No space left"):
        present(tmp_path, wc.compare(ref, test.subset(range(4))), ref, test.subset(range(4)))
    after = {name: (tmp_path / name).read_bytes() for name in before}
    assert after == before and not list(tmp_path.glob(".welch-*.tmp"))
    monkeypatch.undo()
    (tmp_path / "report.json").unlink()
    (tmp_path / "report.json").mkdir()
    with pytest.raises(wc.WelchInputError, match=re.escape(f"{tmp_path / 'report.json'} is a folder, not a file")):
        present(tmp_path, wc.compare(ref, test), ref, test)


def test_a_lock_file_that_can_not_be_written_is_named_and_not_left(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "write", lambda fd, data: 0)  # a full disk: nothing is written
    lock = OutputLock(tmp_path / "run.npz")
    with pytest.raises(BatchError, match=re.escape(f"can't write the lock file {lock.lock_path}")):
        with lock:
            pass
    assert not lock.lock_path.exists()


def test_suite_names_with_a_trailing_newline_or_control_characters_are_refused(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('[suite]\nname = "a\\u0007b"\n[[case]]\nname = "c\\n"\nscene = "corner"\n')
    with pytest.raises(BatchError) as caught:
        suites.load_suite(str(path))
    message = str(caught.value)
    assert "[suite] name must be a non-empty line of text" in message and "'name' must be letters" in message


def test_every_case_skipped_is_not_a_pass():
    case = suites.Case(name="c", scene="corner")
    skipped = [suites.CaseResult(case, "OPTIX", "skipped", message="Cycles found no GPU")]
    assert suites.exit_code(skipped) == Exit.USAGE
    mixed = [*skipped, suites.CaseResult(case, "CPU", "passed", "no_evidence")]
    assert suites.exit_code(mixed) == Exit.OK


def test_a_blender_that_is_not_blender_is_refused_in_one_line(tmp_path):
    fake = tmp_path / "blender"
    fake.write_text("#!/bin/sh\necho 'hello, I render nothing'\nexit 0\n")
    fake.chmod(0o755)
    done = subprocess.run([sys.executable, "-m", "batch", "render", "--scene", "corner", "--seeds", "0:2", "--spp",
                           "1", "--blender", str(fake), "--out", str(tmp_path / "x.npz")],
                          capture_output=True, text=True, cwd=ROOT)  # fmt: skip
    assert done.returncode == Exit.USAGE, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and f"--blender {fake} is not Blender" in done.stderr
    assert not (tmp_path / "x.npz").exists()


def test_a_blender_that_never_starts_rendering_is_stopped_with_what_it_started(tmp_path):
    """A Blender that answers --version and then hangs (a licence prompt, a stuck network mount) is given up on
    after WELCH_START_TIMEOUT seconds, in one line, and its whole process group is gone: nothing it started is
    left running or holding the tool's pipes."""
    marker = tmp_path / "child.pid"
    fake = tmp_path / "blender"
    fake.write_text("#!/bin/sh\n"
                    "if [ \"$1\" = --version ]; then echo 'Blender 4.5.4 LTS'; exit 0; fi\n"
                    f"sleep 600 & echo $! > {marker}\nwait\n")  # fmt: skip
    fake.chmod(0o755)
    env = {**os.environ, "WELCH_START_TIMEOUT": "2"}
    done = subprocess.run([sys.executable, "-m", "batch", "render", "--scene", "corner", "--seeds", "0:2", "--spp",
                           "1", "--blender", str(fake), "--out", str(tmp_path / "x.npz")],
                          capture_output=True, text=True, cwd=ROOT, env=env, timeout=60)  # fmt: skip
    assert done.returncode == Exit.USAGE, done.stderr
    assert done.stderr.strip() == (f"error: {fake} did not start rendering within 2 s "
                                   "(WELCH_START_TIMEOUT sets the limit)")  # fmt: skip
    stat = Path(f"/proc/{int(marker.read_text())}/stat")
    time.sleep(0.5)  # the kill is sent; let it land
    assert not stat.exists() or stat.read_text().rsplit(")", 1)[1].split()[0] == "Z"  # gone, or dead unreaped


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("key.light", "light group 'key.light': Blender takes it as 'key_light'"),
        ("g" * 80, "instead ('Object.lightgroup' holds at most 63 characters, or changes some)"),
    ],
)
def test_a_light_group_blender_would_rename_is_refused(tmp_path, name, message):
    done = subprocess.run([sys.executable, "-m", "batch", "render", "--scene", "corner", "--resolution", "16", "16",
                           "--tile", "8", "--seeds", "0:2", "--spp", "1", "--lobes", "lightgroups", "--set",
                           f'objects["Light"].lightgroup={name}', "--out", str(tmp_path / "x.npz")],
                          capture_output=True, text=True, cwd=ROOT)  # fmt: skip
    assert done.returncode == Exit.USAGE and message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def suite_with_two_references(tmp_path, swap: bool):
    """A suite of two cases on synthetic references (no rendering happens before the reference check)."""
    text = ('[[case]]\nname = "a"\nscene = "corner"\nresolution = [32, 32]\n'
            '[[case]]\nname = "b"\nscene = "glossy"\nresolution = [32, 32]\n')  # fmt: skip
    (tmp_path / "s.toml").write_text(text)
    refs = tmp_path / "refs"
    refs.mkdir()
    rng = np.random.default_rng(11)
    for case, scene in (("a", "corner"), ("b", "glossy")):
        info = wc.RunInfo(scene=scene, scene_id=f"builtin:{scene}:1")
        target = refs / f"{'b' if swap and case == 'a' else 'a' if swap else case}.npz"
        save(target, rng.normal(100, 1, (8, 2, 2, 3)), range(8), 32, 32, 16, info)
    return suites.load_suite(str(tmp_path / "s.toml")), refs


def test_a_reference_of_another_case_is_named_and_not_used(tmp_path):
    suite, refs = suite_with_two_references(tmp_path, swap=True)
    outcomes = suites.run_suite(suite, list(suite.cases), refs, tmp_path / "out", lambda n: None, say=lambda _: None)
    assert [o.status for o in outcomes] == ["error", "error"]
    assert "not this case's reference: it should be of the built-in scene 'corner', it holds 'glossy'" in (
        outcomes[0].message
    )
    # A command that renders it anew, with the folder the references are in (a suite file's own is not found).
    advice = f"(to render it anew: welch-bias suite bless {tmp_path / 's.toml'} --refs {refs} --filter a --force)"
    assert outcomes[0].message.endswith(advice), outcomes[0].message
    args = cli.build_parser().parse_args(shlex.split(advice.split(": ", 1)[1].rstrip(")"))[1:])
    assert (args.suite_command, args.suite_file, args.refs, args.filter, args.force) == (
        "bless", str(tmp_path / "s.toml"), str(refs), ["a"], True
    )  # fmt: skip
    assert not (tmp_path / "out" / "a").exists()  # nothing rendered
    (refs / "a.npz").write_bytes((refs / "a.npz").read_bytes()[:100])  # truncated: that case alone fails, named
    outcomes = suites.run_suite(suite, list(suite.cases), refs, tmp_path / "out2", lambda n: None, say=lambda _: 0)
    assert outcomes[0].status == "error" and str(refs / "a.npz") in outcomes[0].message


def test_pixel_moments_that_contradict_their_tile_sums_are_refused_by_compare(tmp_path, capsys):
    """8 v 8 unbiased passes whose files' pixel M2s are all zeros: `compare --pixel-variance on` said `biased`
    ('a difference spread over many tiles'), exit 1; now the file is refused in one line naming it and the array."""
    rng = np.random.default_rng(41)
    paths = []
    for side, first in (("ref", 0), ("test", 100)):
        run = wc.TileStats(32, 32, 16, 3, keep_pixel_moments=True)
        for seed in range(first, first + 8):
            run.add_pass(rng.gamma(2.0, 0.5, (32, 32, 3)).astype(np.float32), seed)
        run.pixels.m2[:] = 0.0
        paths.append(str(tmp_path / f"{side}.npz"))
        wc.save_stats(paths[-1], run)
    code = cli.main(["compare", *paths, "--pixel-variance", "on", "--out", str(tmp_path / "r")])
    assert code == Exit.USAGE
    assert capsys.readouterr().err == (
        f"error: {paths[0]!r} is damaged: 'pixel_m2' contradicts its tile sums: in 12 of 12 tile-channels the tile "
        "sums vary more than their pixels can\n"
    )


def test_a_blender_that_never_answers_is_said_to_be_waited_for_and_stopped_whole(tmp_path, monkeypatch):
    """A --blender that only sleeps kept `check --scene corner --unpaired --blender ./hang.sh` silent for 45 s:
    the 15 s line ("waiting for ...") covered a render process slow to start, not the binary's --version that
    comes first. The same line now comes from there (seconds shortened here), then the one-line error, and
    nothing the script started is left running."""
    from batch.jobs import launch
    from batch.jobs.job import RenderJob
    from batch.jobs.side import Side

    marker = tmp_path / "child.pid"
    hang = tmp_path / "hang.sh"
    hang.write_text(f"#!/bin/sh\nsleep 600 & echo $! > {marker}\nwait\n")
    hang.chmod(0o755)
    monkeypatch.setattr(launch, "START_NOTICE", 1.0)
    monkeypatch.setattr(launch, "VERSION_TIMEOUT", 3.0)
    said = []
    side = Side("reference", RenderJob(str(tmp_path / "r.npz"), (0,), scene="corner", blender=str(hang)),
                warn=said.append)  # fmt: skip
    start = time.monotonic()
    with pytest.raises(BatchError) as info:
        side.start()
    assert 3.0 <= time.monotonic() - start < 10
    assert said == [f"reference: waiting for {hang} to answer --version (1 s so far; stopped at 3 s; Ctrl-C stops "
                    "it now)"]  # fmt: skip
    assert str(info.value) == f"--blender {hang} did not answer --version within 3 s"
    stat = Path(f"/proc/{int(marker.read_text())}/stat")
    time.sleep(0.5)  # the kill is sent; let it land
    assert not stat.exists() or stat.read_text().rsplit(")", 1)[1].split()[0] == "Z"  # gone, or dead unreaped
