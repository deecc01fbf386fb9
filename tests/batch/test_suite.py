"""Regression suites (batch.decide.suite, ``python -m batch suite``): the suite file and its one-line errors, verdicts
to statuses and exit codes, JUnit XML, and real runs: bless, a refused re-bless, a passing run, a planted change named
as failed, a missing device skipped, and the dashboard in a real browser."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from batch.decide import suite as suites
from batch.errors import BatchError
from batch.present.junit import junit_xml
from welch_core import Verdict

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def write_suite(tmp_path, text: str) -> Path:
    path = tmp_path / "suite.toml"
    path.write_text(text)
    return path


CASE = '[[case]]\nname = "a"\nscene = "corner"\n'


#: The start of a case whose passes a command renders ("r", completed by each row).
COMMAND = '[[case]]\nname = "a"\ncommand = "r'


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "no [[case]] in the suite"),
        ("[suite]\nalpha = 2.0\n" + CASE, "[suite] alpha must be a number in (0, 1), got 2.0"),
        ('[suite]\nalpha = "0.01"\n' + CASE, "[suite] alpha must be a number, not text: '0.01'"),
        ("[sweet]\n" + CASE, "unknown table [sweet] (a suite has [suite], [defaults] and [[case]])"),
        (CASE + "colour = 1\n", "case 'a': unknown key 'colour'"),
        ('[[case]]\nname = "a b"\nscene = "corner"\n', "case 'a b': 'name' must be letters, digits, '-', '_' or '.'"),
        (
            '[[case]]\nname = "a"\n',
            "case 'a': give 'scene' (a built-in scene), 'blend' (a .blend file) or 'command' (another renderer), "
            "one of them",
        ),
        (CASE + 'blend = "x.blend"\n', "case 'a': give 'scene' (a built-in scene), 'blend'"),
        ('[[case]]\nname = "a"\nblend = "missing.blend"\n', "case 'a': blend file "),
        (CASE + "resolution = [32]\n", "case 'a': 'resolution' must be a width and a height in pixels, got [32]"),
        (CASE + "passes = 1\n", "case 'a': 'passes' must be an integer in 2..1000000, got 1"),
        (CASE + "passes = 1e11\n", "case 'a': 'passes' must be an integer in 2..1000000, got 100000000000.0"),
        (CASE + "seconds = inf\n", "case 'a': 'seconds' must be a number of seconds in (0, 604800], got inf"),
        (CASE + "seconds = nan\n", "case 'a': 'seconds' must be a number of seconds in (0, 604800], got nan"),
        (CASE + 'spp = "4"\n', "case 'a': 'spp' must be a number, not text: '4'"),
        (
            CASE + 'tolerance = "1%"\nequivalence_tile = 24\n',
            "case 'a': 'equivalence_tile' must be a multiple of the case's tile 16, got 24",
        ),  # fmt: skip
        (CASE + "equivalence_tile = 64\n", "case 'a': 'equivalence_tile' needs a 'tolerance'"),
        (
            CASE + "devices = []\n",
            "case 'a': 'devices' must name at least one of CPU, GPU, OPTIX, CUDA, HIP, METAL, ONEAPI",
        ),
        (CASE + 'devices = ["TPU"]\n', "case 'a': 'devices' must be one of CPU, GPU, OPTIX, CUDA, HIP, METAL, ONEAPI"),
        (CASE + 'devices = ["CPU", "CPU"]\n', "case 'a': 'devices' repeats an item: ['CPU', 'CPU']"),
        ('[[case]]\nname = "abc\\n"\nscene = "corner"\n', "'name' must be letters, digits, '-', '_' or '.'"),
        ('[[case]]\nname = "a"\nscene = "cornr"\n', "case 'a': 'scene' 'cornr' is not a built-in scene"),
        (CASE + 'tolerance = "1"\n', "case 'a': 'tolerance' must be a percentage such as 0.5%, got '1'"),
        (CASE + 'expect = "different"\n', "case 'a': 'expect' must be 'same' or 'biased', got 'different'"),
        (CASE + 'set = ["cycles.samples"]\n', "case 'a': 'set' 'cycles.samples': "),
        (CASE + CASE, "case 'a': the name is used twice"),
        (COMMAND + ' --out {out}"\n', "case 'a': --command 'r --out {out}' has no {seed}: each pass needs its own"),
        (COMMAND + ' {seed} {out} {sed}"\n', "case 'a': --command 'r {seed} {out} {sed}': unknown placeholder {sed}"),
        (
            COMMAND + ' {seed} {out}"\nset = ["k=1"]\n',
            "case 'a': --command 'r {seed} {out}' has no {set} for the overrides ['k=1']",
        ),  # fmt: skip
        (
            COMMAND + ' {seed} {out}"\ndevices = ["OPTIX"]\n',
            "case 'a': --command renders the passes itself: --device does not apply to it",
        ),  # fmt: skip
        (COMMAND + ' {seed} {out}"\nresolution = [32, 32]\n', "--resolution does not apply to it"),
        (COMMAND + ' {seed} {out}"\nscene = "corner"\n', "case 'a': give 'scene' (a built-in scene), 'blend'"),
        ("[[case]\n", "not readable TOML"),
    ],
)
def test_bad_suite_files_are_refused_in_one_line(tmp_path, text, message):
    path = write_suite(tmp_path, text)
    with pytest.raises(BatchError, match=re.escape(message)) as caught:
        suites.load_suite(str(path))
    assert "\n" not in str(caught.value) and str(caught.value).startswith(str(path))


def test_every_problem_of_a_suite_file_is_named_before_anything_renders(tmp_path):
    text = (CASE + 'spp = 0\n[[case]]\nname = "b"\nscene = "nowhere"\nset = ["cycles.max_bounces"]\n'
            + CASE)  # fmt: skip
    with pytest.raises(BatchError) as caught:
        suites.load_suite(str(write_suite(tmp_path, text)))
    message = str(caught.value)
    assert message.startswith(f"{tmp_path / 'suite.toml'}: 4 problems, nothing rendered: ")
    for part in ("case 'a': 'spp' must be an integer in 1..16777216, got 0", "case 'b': 'scene' 'nowhere' is not",
                 "case 'b': 'set' 'cycles.max_bounces'", "case 'a': the name is used twice"):  # fmt: skip
        assert part in message, part


def test_a_suite_file_with_defaults(tmp_path):
    (tmp_path / "s.blend").write_bytes(b"BLENDER")
    path = write_suite(tmp_path, '[suite]\nname = "mine"\nalpha = 0.05\n[defaults]\nresolution = [16, 8]\n'
                                 'tile = 4\n' + CASE + 'tolerance = "0.5%"\nexpect = "biased"\n'
                                 'sampling_pattern = "TABULATED_SOBOL"\ntest_sampling_pattern = "BLUE_NOISE"\n'
                                 '[[case]]\nname = "b"\nblend = "s.blend"\ntile = 8\ndevices = ["CPU", "OPTIX"]\n'
                                 'set = ["cycles.max_bounces=4"]\nseconds = 30\n')  # fmt: skip
    suite = suites.load_suite(str(path))
    assert suite.name == "mine" and suite.alpha == 0.05
    a, b = suite.cases
    assert (a.resolution, a.tile, a.tolerance, a.expect, a.passes) == ((16, 8), 4, 0.005, "biased", 64)
    assert a.job("r.npz", [1], "CPU", None).sampling_pattern == "TABULATED_SOBOL"
    assert a.job("t.npz", [2], "CPU", None, test=True).sampling_pattern == "BLUE_NOISE"
    assert b.job("t.npz", [2], "CPU", None, test=True).sampling_pattern is None
    assert b.blend == str(tmp_path / "s.blend") and b.tile == 8 and b.devices == ("CPU", "OPTIX")
    assert b.overrides == ("cycles.max_bounces=4",) and b.seconds == 30.0
    assert suite.select(["b*"]) == [b]
    with pytest.raises(BatchError, match=re.escape("--filter z matches no case of")):
        suite.select(["z"])


def test_the_builtin_suite_names_real_scenes_and_valid_planted_changes():
    from batch.blender.scenes import SCENES
    from batch.jobs.overrides import parse_override

    suite = suites.load_suite("builtin")
    assert len(suite.cases) >= 14
    for case in suite.cases:
        assert case.scene in SCENES and case.why
        assert case.expect == "biased" or case.planted, case.name
        if case.planted:
            parse_override(case.planted)
        assert suites.reference_path(suites.BUILTIN_REFS, case).is_file(), case.name


def test_a_case_is_checked_as_the_check_its_request_describes(tmp_path):
    """A case's check is made as every other front end's (`CheckRequest` -> `check_job`): the blessed reference is
    not rendered, the test side renders on the seeds after its seeds (and --seed-offset's), the case's overrides
    are both sides', ``suite run --set`` and the run's build are the test side's."""
    from batch.decide.check_job import check_job

    suite = suites.load_suite("builtin")
    case = dataclasses.replace(suite.cases[0], overrides=("cycles.sample_clamp_direct=0",))
    stored = suites.reference_path(suites.BUILTIN_REFS, case)
    request = suites.case_request(suite, case, "CPU", stored, tmp_path / "c", (None, "/py"), ("cycles.seed=1",), 5)
    job = check_job(request)
    seeds = suites.wc.load_stats(stored, pixels=False).seeds
    assert job.fixed_reference and not job.paired and job.reference.out == str(stored)
    assert job.reference.seeds == tuple(seeds) and job.test.seeds == tuple(
        range(max(seeds) + 6, max(seeds) + 6 + case.passes)
    )
    assert job.reference.overrides == case.overrides and job.test.overrides == (*case.overrides, "cycles.seed=1")
    assert (job.reference.python, job.test.python, job.max_passes, job.alpha) == (None, "/py", case.passes, suite.alpha)


def outcome(status, expect="same", verdict=None):
    case = suites.Case(name="c", scene="corner", expect=expect)
    return suites.CaseResult(case, "CPU", status, verdict, "message")


def test_statuses_and_exit_codes():
    same, different = suites.Case("c", "corner"), suites.Case("c", "corner", expect="biased")
    assert suites.status_of(same, Verdict.NO_EVIDENCE) == suites.status_of(same, Verdict.EQUIVALENT) == "passed"
    assert suites.status_of(same, Verdict.BIASED) == "failed"
    assert suites.status_of(different, Verdict.BIASED) == "passed"
    assert suites.status_of(different, Verdict.NO_EVIDENCE) == "failed"  # a known difference that went away
    assert suites.status_of(same, Verdict.INCONCLUSIVE) == "inconclusive"
    # A case that could not have found a bias of its tolerance does not pass on finding none.
    assert suites.status_of(same, Verdict.NO_EVIDENCE, 0.132, 0.01) == "underpowered"
    assert suites.status_of(same, Verdict.NO_EVIDENCE, None, 0.01) == "underpowered"
    assert suites.status_of(same, Verdict.NO_EVIDENCE, 0.009, 0.01) == "passed"
    assert suites.status_of(same, Verdict.EQUIVALENT, None, 0.01) == "passed"
    assert suites.status_of(different, Verdict.BIASED, None, 0.01) == "passed"
    assert suites.underpowered_text(0.132, 0.01, 8) == (
        "not enough passes to rule out 1 %: 13.2 % could hide in a 8x8 tile"
    )
    assert suites.exit_code([outcome("underpowered"), outcome("passed")]) == 3
    assert suites.exit_code([outcome("passed"), outcome("skipped")]) == 0
    biased = outcome("failed", verdict="biased")
    assert suites.exit_code([outcome("inconclusive"), outcome("error"), biased]) == 1
    assert suites.exit_code([outcome("inconclusive"), outcome("error")]) == 2
    assert suites.exit_code([outcome("inconclusive"), outcome("passed")]) == 3
    # An expected difference that went away: not `biased` (exit 1 means biased), but the suite can't pass.
    assert suites.exit_code([outcome("failed", expect="biased", verdict="no_evidence")]) == 3


def test_the_dashboard_shows_failing_cases_first(tmp_path):
    statuses = ["passed", "skipped", "inconclusive", "failed", "error", "passed"]
    results = []
    for number, status in enumerate(statuses):
        result = outcome(status, verdict="biased" if status == "failed" else None)
        result.case = suites.Case(name=f"c{number}", scene="corner")
        results.append(result)
    suite = suites.Suite(tmp_path / "s.toml", "s", 0.01, tuple(r.case for r in results))
    suites.write_outputs(suite, results, tmp_path / "out", tmp_path / "refs")
    page = (tmp_path / "out" / "index.html").read_text()
    shown = re.findall(r'<tr class="case" data-status="(\w+)"><td><b>(\w+)</b>', page)
    assert shown == [("failed", "c3"), ("error", "c4"), ("inconclusive", "c2"), ("passed", "c0"), ("passed", "c5"),
                     ("skipped", "c1")]  # fmt: skip
    # JUnit and summary.json keep the suite's order.
    assert [c["case"] for c in json.loads((tmp_path / "out" / "summary.json").read_text())["cases"]] == [
        f"c{n}" for n in range(6)
    ]


def test_junit_xml_counts_each_kind():
    results = [outcome("passed", verdict="no_evidence"), outcome("failed", verdict="biased"), outcome("skipped"),
               outcome("error"), outcome("inconclusive", verdict="inconclusive")]  # fmt: skip
    root = ET.fromstring(junit_xml("s", results))
    group = root.find("testsuite")
    assert group.attrib | {"time": "0"} == {"name": "s", "tests": "5", "failures": "2", "errors": "1",
                                            "skipped": "1", "time": "0"}  # fmt: skip
    cases = group.findall("testcase")
    assert [c.find("failure") is not None for c in cases] == [False, True, False, False, True]
    assert cases[1].find("failure").attrib["message"] == "biased: message"
    assert cases[2].find("skipped") is not None and cases[3].find("error") is not None


# -- real runs --------------------------------------------------------------------------------------------------

SMALL = """[suite]
name = "small"
tolerance = "30%"
[defaults]
resolution = [16, 16]
tile = 8
passes = 12
sampling_pattern = "TABULATED_SOBOL"
[[case]]
name = "walls"
scene = "corner"
why = "the corner scene"
[[case]]
name = "mirror"
scene = "glossy_sharp"
"""
PLANTED = "cycles.film_exposure=1.2"  # exists in every scene: a planted change for all cases at once


def batch(*args, check=None):
    done = subprocess.run([sys.executable, "-m", "batch", *map(str, args)], capture_output=True, text=True)
    if check is not None:
        assert done.returncode == check, done.stdout[-3000:] + done.stderr[-3000:]
    return done


@pytest.fixture(scope="module")
def blessed(tmp_path_factory):
    folder = tmp_path_factory.mktemp("suite")
    path = write_suite(folder, SMALL)
    done = batch("suite", "bless", path, "--refs", folder / "refs", check=0)
    assert "walls: blessed: 12 passes" in done.stdout and "mirror: blessed" in done.stdout
    return folder, path


@pytest.mark.slow
def test_bless_records_provenance_and_refuses_a_changed_reference(blessed, tmp_path):
    folder, path = blessed
    refs = tmp_path / "refs"
    shutil.copytree(folder / "refs", refs)
    record = json.loads((refs / "walls.json").read_text())
    assert record["seeds"] == [0, 12] and record["passes"] == 12 and record["device"] == "CPU"
    assert record["blender_version"] and record["build_hash"] and record["blessed"].startswith("20")
    # The same scene again: re-blessed on new seeds.
    done = batch("suite", "bless", path, "--refs", refs, "--filter", "walls", check=0)
    assert "walls: re-blessed" in done.stdout
    assert json.loads((refs / "walls.json").read_text())["seeds"] == [12, 24]
    # A changed scene: refused, the old reference kept, the comparison's report next to it.
    changed = write_suite(tmp_path, SMALL.replace('why = "the corner scene"', f'set = ["{PLANTED}"]'))
    done = batch("suite", "bless", changed, "--refs", refs, "--filter", "walls", check=1)
    assert "walls: refused: the new render differs from the stored one: verdict: biased" in done.stdout
    assert (refs / "walls.rebless" / "report.html").is_file()
    assert json.loads((refs / "walls.json").read_text())["seeds"] == [12, 24]
    done = batch("suite", "bless", changed, "--refs", refs, "--filter", "walls", "--force", check=0)
    assert "walls: forced" in done.stdout
    # --missing renders only the cases without a reference: adding a case re-renders nothing else.
    (refs / "mirror.npz").unlink()
    stored = (refs / "walls.npz").read_bytes()
    done = batch("suite", "bless", path, "--refs", refs, "--missing", check=0)
    assert f"walls: kept: {refs / 'walls.npz'} exists" in done.stdout and "mirror: blessed: 12 passes" in done.stdout
    assert (refs / "walls.npz").read_bytes() == stored


@pytest.mark.slow
def test_a_case_that_could_not_have_failed_does_not_pass(blessed, tmp_path):
    """The same runs held to the suite's default tolerance (1 %), which 12 passes of 8x8 tiles can't rule out:
    `underpowered`, a JUnit failure, exit code 3, the sentence saying what could hide."""
    folder, path = blessed
    strict = write_suite(tmp_path, SMALL.replace('tolerance = "30%"\n', ""))
    done = batch("suite", "run", strict, "--refs", folder / "refs", "--out", tmp_path / "out", "--filter", "walls",
                 check=3)  # fmt: skip
    line = next(x for x in done.stdout.splitlines() if "underpowered:" in x)
    assert re.fullmatch(r"  underpowered: not enough passes to rule out 1 %: \d+\.\d % could hide in a 8x8 tile; no "
                        r"evidence of bias: .*", line), line  # fmt: skip
    failure = ET.parse(tmp_path / "out" / "junit.xml").getroot().find(".//failure")
    assert failure.attrib["type"] == "underpowered" and "not enough passes" in failure.attrib["message"]


@pytest.mark.slow
def test_run_passes_then_names_the_planted_change_and_skips_a_missing_device(blessed, tmp_path):
    folder, path = blessed
    refs = folder / "refs"
    done = batch("suite", "run", path, "--refs", refs, "--out", tmp_path / "ok", check=0)
    assert "suite: 2 passed" in done.stdout
    summary = json.loads((tmp_path / "ok" / "summary.json").read_text())
    assert [c["status"] for c in summary["cases"]] == ["passed", "passed"] and summary["exit_code"] == 0
    assert (tmp_path / "ok" / summary["cases"][0]["report"]).is_file()
    root = ET.parse(tmp_path / "ok" / "junit.xml").getroot()
    assert root.find("testsuite").attrib["failures"] == "0"
    # The same --out again is refused; --resume continues it.
    again = batch("suite", "run", path, "--refs", refs, "--out", tmp_path / "ok", check=2)
    assert "already exists: pass --resume" in again.stderr

    done = batch("suite", "run", path, "--refs", refs, "--out", tmp_path / "planted", "--set", PLANTED, check=1)
    assert "failed: walls [CPU], mirror [CPU]" in done.stdout
    summary = json.loads((tmp_path / "planted" / "summary.json").read_text())
    assert {c["verdict"] for c in summary["cases"]} == {"biased"}
    assert summary["cases"][0]["largest"]["estimate"] > 0.1 and summary["cases"][0]["whole_image"]["low"] > 0.05

    # A suite whose every case was skipped tested nothing: it does not pass.
    done = batch("suite", "run", path, "--refs", refs, "--out", tmp_path / "gpu", "--device", "OPTIX",
                 "--filter", "walls", check=2)  # fmt: skip
    assert "suite: 1 skipped" in done.stdout
    summary = json.loads((tmp_path / "gpu" / "summary.json").read_text())
    assert summary["cases"][0]["status"] == "skipped" and "Cycles found no GPU" in summary["cases"][0]["message"]


@pytest.mark.slow
def test_a_missing_reference_is_refused_before_anything_renders(tmp_path):
    path = write_suite(tmp_path, SMALL)
    done = batch("suite", "run", path, "--refs", tmp_path / "none", "--out", tmp_path / "out", check=2)
    assert "no reference for walls, mirror in" in done.stderr and "run `suite bless` first" in done.stderr
    done = batch("suite", "run", path, "--out", tmp_path / "out", check=2)
    assert "--refs is required for" in done.stderr


@pytest.mark.parametrize("command", ["run", "bless"])
def test_a_problem_of_the_renderer_is_one_line_before_anything_renders_not_one_per_case(tmp_path, command):
    """Without bpy (hidden here), or with a --blender that is no program, the built-in suite's 15 cases end in one
    line, exit 2, before the first case starts."""
    code = "import sys; sys.modules['bpy'] = None; from batch.cli import main; sys.exit(main(sys.argv[1:]))"
    where = ["--out", str(tmp_path / "out")] if command == "run" else ["--refs", str(tmp_path / "refs")]
    for extra, message in (([], "error: rendering with Cycles needs the bpy module, which this Python "),
                           (["--blender", str(tmp_path / "none")], f"error: --blender {tmp_path / 'none'}: no such "
                            "program")):  # fmt: skip
        done = subprocess.run([sys.executable, "-c", code, "suite", command, "builtin", *where, *extra],
                              capture_output=True, text=True)  # fmt: skip
        assert done.returncode == 2, done.stdout + done.stderr
        assert done.stdout == "" and len(done.stderr.splitlines()) == 1 and done.stderr.startswith(message), done.stderr
    assert not (tmp_path / "out").exists() and not (tmp_path / "refs").exists()


@pytest.mark.slow
def test_a_suite_run_interrupted_in_its_second_case_resumes(blessed, tmp_path):
    """Ctrl-C as the second case starts (its render process still loading): exit 130, the first case's check kept
    as decided; --resume answers the first from its state (no new look) and runs the second."""
    folder, _ = blessed
    path = write_suite(tmp_path, SMALL)
    argv = [sys.executable, "-m", "batch", "suite", "run", str(path), "--refs", str(folder / "refs"), "--out",
            str(tmp_path / "run")]  # fmt: skip
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if line.startswith("suite run: 2/2"):
            break
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    first = json.loads((tmp_path / "run" / "walls" / "CPU" / "check.json").read_text())["looks"]
    done = batch("suite", "run", path, "--refs", folder / "refs", "--out", tmp_path / "run", "--resume", check=0)
    assert "suite: 2 passed" in done.stdout, done.stdout + done.stderr
    assert json.loads((tmp_path / "run" / "walls" / "CPU" / "check.json").read_text())["looks"] == first


@pytest.mark.slow
@pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH (apt-get install chromium; ./dev test does it)")
def test_the_dashboard_in_a_browser(blessed, tmp_path):
    playwright = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    folder, path = blessed
    batch("suite", "run", path, "--refs", folder / "refs", "--out", tmp_path, "--set", PLANTED, check=1)
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--disable-gpu"])
        page = browser.new_page(viewport={"width": 1500, "height": 700})
        errors = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto((tmp_path / "index.html").as_uri())
        assert errors == []
        assert page.locator("#title").inner_text() == "Suite small: a case failed"
        rows = page.locator("tr.case")
        assert rows.count() == 2 and rows.first.get_attribute("data-status") == "failed"
        # Every thumbnail decodes: the two renders (each with the other side under it), their difference and the
        # p-value map of both cases.
        sizes = page.evaluate("[...document.images].map(i => i.complete && i.naturalWidth)")
        assert len(sizes) == 12 and all(sizes)
        shown = rows.first.locator(".ab").first
        assert shown.locator(".other").is_hidden()
        shown.hover()  # A/B: the other side under the pointer
        assert shown.locator(".other").is_visible() and shown.locator(".shown").is_hidden()
        page.locator("a", has_text="report").first.click()
        page.wait_for_function("document.body.dataset.drawn === 'yes'", timeout=20000)
        assert page.locator("#verdict").inner_text() == "Biased"
        page.go_back()
        page.screenshot(path=str(ROOT / "docs" / "screenshots" / "suite.png"), full_page=True)
        browser.close()


@pytest.mark.slow
def test_the_builtin_suite_passes_and_a_planted_change_fails_every_case(tmp_path):
    """The CI job a renderer team would run: every case of `builtin` against the shipped references (rendered
    with this build), then the same with the film exposure raised in every case."""
    done = batch("suite", "run", "builtin", "--out", tmp_path / "same", check=0)
    cases = suites.load_suite("builtin").cases
    assert f"suite: {len(cases)} passed" in done.stdout
    done = batch("suite", "run", "builtin", "--out", tmp_path / "planted", "--set", "cycles.film_exposure=1.1",
                 check=1)  # fmt: skip
    named = done.stdout.rpartition("; failed: ")[2].splitlines()[0].split(", ")
    assert sorted(named) == sorted(f"{c.name} [CPU]" for c in cases if c.expect == "same")


def test_the_documented_example_suite_is_a_valid_suite(tmp_path):
    """docs/suite.md's complete example loads as written (its .blend stood in for by an empty file)."""
    text = (ROOT / "docs" / "suite.md").read_text()
    example = text.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "glossy.blend").write_bytes(b"")
    suite = suites.load_suite(str(write_suite(tmp_path, example)))
    assert suite.name == "my renderer" and [c.name for c in suite.cases] == ["glossy", "fog_blue_noise"]
    glossy, fog = suite.cases
    assert glossy.devices == ("CPU", "OPTIX") and glossy.tolerance == 0.02 and glossy.passes == 128
    assert fog.expect == "biased" and fog.test_sampling_pattern == "BLUE_NOISE" and fog.spp == 2
