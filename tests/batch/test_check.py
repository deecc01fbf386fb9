"""``python -m batch check`` with real Cycles renders (bpy module): render until decided, resume after Ctrl-C,
bad input refused before anything renders."""

from __future__ import annotations

import functools
import json
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch import cli
from batch.blender.scenes import WALL_COLOR_PATH
from batch.errors import Exit
from batch.jobs import protocol

ROOT = Path(__file__).resolve().parents[2]
SMALL = ("--scene", "corner", "--resolution", 64, 64)


def check(*args, expect=None) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", "batch", "check", *map(str, args)], capture_output=True, text=True)
    if expect is not None:
        assert done.returncode == expect, done.stdout[-2000:] + done.stderr[-2000:]
    return done


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--tolerance", "1"], "argument --tolerance: must be a percentage such as 0.5%, got '1'"),
        (["--tolerance", "abc%"], "argument --tolerance: must be a percentage such as 0.5%, got 'abc%'"),
        (
            ["--tolerance", "0.0005%"],
            "argument --tolerance: must be at least 0.001% (a smaller relative difference is float rounding), got "
            "'0.0005%'",
        ),
        (["--unpaired", "--max-passes", "1"], "argument --max-passes: must be an integer in 2..1000000, got '1'"),
        (["--unpaired", "--max-passes", "1e9"], "argument --max-passes: must be an integer in 2..1000000, got '1e9'"),
        (
            ["--unpaired", "--max-seconds", "0"],
            "argument --max-seconds: must be a number of seconds in (0, 604800], got '0'",
        ),
        (
            ["--unpaired", "--max-seconds", "inf"],
            "argument --max-seconds: must be a number of seconds in (0, 604800], got 'inf'",
        ),
        (["--scene", "cornr"], "error: unknown built-in scene 'cornr'"),
        (["--test-blend", "missing.blend"], "error: --test-blend missing.blend: no such file"),
        (
            [],
            "error: the two sides are identical by construction (same scene, build, settings and seeds): every "
            "difference would be zero; give --set, --test-blend, --test-blender, --test-command or a --test- setting "
            "such as --test-sampling-pattern, or --unpaired for an A/A check",
        ),
    ],
)
def test_bad_input_is_refused_before_anything_renders(tmp_path, args, message):
    done = check(*SMALL, *args, "--out", tmp_path / "check", expect=2)
    assert message in done.stderr and len(done.stderr.splitlines()) == 1
    assert not (tmp_path / "check").exists()


@pytest.mark.slow
def test_a_planted_bias_stops_early_as_biased(tmp_path):
    """Walls 0.21 instead of 0.2 (the paper's Fig. 16), paired: found within a few passes."""
    grey = f"{WALL_COLOR_PATH}=0.21,0.21,0.21,1"
    done = check(*SMALL, "--set", grey, "--json-progress", "--out", tmp_path, expect=1)
    looks = [e for e in map(protocol.parse, done.stdout.splitlines()) if isinstance(e, protocol.Looked)]
    assert looks[-1].verdict == "biased" and looks[-1].passes <= 8
    assert all(look.verdict is None for look in looks[:-1])
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["verdict"] == "biased" and report["test"] == "paired" and report["p_value"] is None
    assert report["check"]["stopped"] == "decided" and len(report["check"]["looks"]) == len(looks)
    assert report["top_tiles"][0]["rel_diff"] > 0.02


@pytest.mark.slow
def test_an_aa_check_ends_equivalent_at_the_size_its_budget_bounds_without_choosing_n(tmp_path):
    """The default check of an unbiased pair sizes its claim for the budget (16x16 tiles would need more than its
    512 passes here, 32x32 not), records the size, says what the finer one would need, and resumes to the same."""
    done = check(*SMALL, "--unpaired", "--out", tmp_path, expect=0)
    first = done.stdout.splitlines()[0]
    assert first.startswith("verdict: equivalent within ±1.00 % in every 32x32 tile (a bias beyond "), first
    assert "; 16x16 tiles would need about " in first and " passes a side; whole image " in first
    assert "\n  alpha 0.01, welch test, " in done.stdout
    state = json.loads((tmp_path / "check.json").read_text())
    assert state["claim_tile"] == 32 and state["looks"][-1]["claim_tile"] == 32
    assert state["looks"][-1]["verdict"] == "equivalent" and state["looks"][-1]["passes"] < 512
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["outcome"]["target_tile"] == 32 and report["outcome"]["scales"][0]["projected"] > 512
    again = check(*SMALL, "--unpaired", "--out", tmp_path, "--resume", expect=0)
    assert again.stdout.splitlines()[0] == first


@pytest.mark.slow
def test_the_budget_ends_inconclusive_with_the_bias_it_rules_out(tmp_path):
    done = check(*SMALL, "--unpaired", "--tolerance", "0.01%", "--max-passes", 6, "--out", tmp_path, expect=3)
    assert "verdict: inconclusive: not shown within ±0.01 % in the whole image" in done.stdout  # nothing is reachable
    assert "bias ruled out per tile size: 16: not bounded, 32: not bounded, 64: not bounded" in done.stdout
    assert "would need about " in done.stdout and "—" not in done.stdout
    assert wc.load_stats(tmp_path / "reference.npz").n == 6


@pytest.mark.slow
def test_ctrl_c_keeps_everything_resume_continues_and_the_budget_grows(tmp_path):
    """Interrupted at its fourth look, resumed to its budget, then given more passes: the looks made stand, the
    new ones come at the schedule's next points and both sides' seeds grow without overlapping. 16 spp a pass,
    so that the interrupt lands long before the budget is spent however loaded the machine."""
    common = (*SMALL, "--unpaired", "--spp", 16, "--tolerance", "0.001%", "--no-futility", "--out", tmp_path)
    args = [sys.executable, "-m", "batch", "check", *map(str, common), "--max-passes", "200", "--json-progress"]
    # SIGINT as a terminal delivers it, whatever this process inherited (a background job of a non-interactive
    # shell starts with SIGINT ignored, and Python then keeps ignoring it: the check would run to its budget).
    reset = functools.partial(signal.signal, signal.SIGINT, signal.SIG_DFL)
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=reset)
    seen = 0
    for line in proc.stdout:
        if isinstance(protocol.parse(line), protocol.Looked):
            seen += 1
            if seen == 4:
                break
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    before = json.loads((tmp_path / "check.json").read_text())["looks"]
    assert len(before) >= 4
    done = check(*common, "--max-passes", 200)
    assert done.returncode == 2 and "already exists: pass --resume" in done.stderr
    done = check(*common, "--max-passes", 100, "--resume", expect=2)
    assert done.stderr.strip().endswith(
        f"can't resume {tmp_path} with --max-passes 100: it has a budget of 200 passes a side, which can grow but "
        "not shrink"
    )
    done = check(*common, "--max-passes", 200, "--resume", expect=3)
    after = json.loads((tmp_path / "check.json").read_text())["looks"]
    assert after[: len(before)] == before  # the earlier looks stand, their boundaries are recomputed alike
    assert after[-1]["passes"] == 200 and after[-1]["verdict"] == "inconclusive"
    assert re.search(r"the same check with --max-passes \d+ and --resume", done.stdout)  # the next step's advice
    assert "within ±0.001 % in the whole image" in done.stdout

    done = check(*common, "--max-passes", 200, "--resume", expect=3)  # spent and not grown: the same answer
    assert json.loads((tmp_path / "check.json").read_text())["looks"] == after
    done = check(*common, "--max-passes", 229, "--resume", expect=2)
    assert done.stderr.strip().endswith(f"--max-passes 229 adds no look to {tmp_path}: its next look is at 230 "
                                        "passes a side")  # fmt: skip
    done = check(*common, "--max-passes", 300, "--resume", expect=3)
    grown = json.loads((tmp_path / "check.json").read_text())
    assert grown["looks"][: len(after)] == after and [look["passes"] for look in grown["looks"][len(after) :]] == [
        230,
        265,
    ]  # the schedule goes on from 200 in 15 % steps; 305 does not fit
    assert grown["budget"] == 265 and grown["plan"]["max_passes"] == 200
    assert grown["looks"][-2]["fraction"] == 230 / 200
    ref, test = wc.load_stats(tmp_path / "reference.npz"), wc.load_stats(tmp_path / "test.npz")
    assert ref.seeds == list(range(265)) and test.seeds == list(range(1_000_000, 1_000_265))


def test_tolerance_off_means_no_equivalent_verdict():
    from batch.decide.check_job import check_job_from_args

    args = cli.build_parser().parse_args(["check", "--scene", "corner", "--set", "cycles.film_exposure=1.01",
                                          "--tolerance", "off", "--out", "x"])  # fmt: skip
    assert args.tolerance is None and check_job_from_args(args).plan(16).tolerance is None
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["check", "--scene", "corner", "--tolerance", "none", "--out", "x"])


@pytest.mark.parametrize(
    ("given", "message"),
    [
        (["--equivalence-tile", "8"], "--equivalence-tile 8 is not a tested tile size: the tile (16) times a power of "
                                      "two (16, 32, 64, ...)"),
        (["--equivalence-tile", "48"], "--equivalence-tile 48 is not a tested tile size: the tile (16) times a power "
                                       "of two (16, 32, 64, ...)"),
        (["--equivalence-tile", "128", "--resolution", "64", "64"], "--equivalence-tile 128 is larger than the image "
                                                                     "(64x64)"),
    ],
)  # fmt: skip
def test_an_equivalence_tile_the_check_does_not_test_is_refused_before_it_renders(tmp_path, capsys, given, message):
    out = tmp_path / "c"
    assert cli.main(["check", "--scene", "corner", "--unpaired", *given, "--out", str(out)]) == Exit.USAGE
    assert capsys.readouterr().err == f"error: {message}\n" and not out.exists()
    from batch.decide.check_job import check_job_from_args

    allowed = [
        "check",
        "--scene",
        "corner",
        "--unpaired",
        "--equivalence-tile",
        "64",
        "--resolution",
        "64",
        "64",
        "--out",
        "x",
    ]
    assert check_job_from_args(cli.build_parser().parse_args(allowed)).plan(16).equivalence_tile == 64


@pytest.mark.slow
def test_a_time_budget_is_spent_on_passes_not_on_start_up(tmp_path):
    """--max-seconds counts the passes' own seconds, not the render processes' start-up (which made a 20 s budget
    stop after 2-3 s of rendering): the check renders for most of its budget."""
    done = check("--scene", "corner", "--resolution", 32, 32, "--unpaired", "--tolerance", "0.01%", "--no-futility",
                 "--max-seconds", 4, "--out", tmp_path)  # fmt: skip
    assert done.returncode == 3, done.stderr[-2000:]
    state = json.loads((tmp_path / "check.json").read_text())
    assert 0.5 * 4 <= state["render_seconds"] <= 4 * 1.3, state["render_seconds"]
    assert state["plan"]["max_passes"] > 20


@pytest.mark.slow
def test_a_check_started_before_the_early_design_resumes_without_it(tmp_path):
    """The design is fixed before the data: a check's state records the early design's share of `biased` (half
    by 16 passes a side) and a resumed check keeps it; a state written before that design existed has no such
    field and resumes as it was started, with none."""
    common = (*SMALL, "--unpaired", "--tolerance", "0.01%", "--out", tmp_path)
    check(*common, "--max-passes", 18, expect=3)
    state = json.loads((tmp_path / "check.json").read_text())
    report = json.loads((tmp_path / "report.json").read_text())
    assert state["plan"]["early_share"] == 0.5 and report["check"]["early_share"] == 0.5
    assert report["check"]["early_passes"] == 16 and "50% of it by 16 passes a side" in report["method"]
    del state["plan"]["early_share"]
    (tmp_path / "check.json").write_text(json.dumps(state))
    check(*common, "--max-passes", 21, "--resume", expect=3)
    state = json.loads((tmp_path / "check.json").read_text())
    report = json.loads((tmp_path / "report.json").read_text())
    assert state["plan"]["early_share"] == 0.0 and report["check"]["early_share"] == 0.0
    assert state["looks"][-1]["passes"] == 21 and "by 16 passes" not in report["method"]


@pytest.mark.slow
def test_neither_claim_in_reach_stops_early_says_why_and_resumes_to_the_same(tmp_path):
    """An A/A check whose tolerance (0.01 %) no size reaches within its budget of 256: it stops `inconclusive`
    once no tile-channel could reach `biased` by the budget with a 5 % chance even with the bias the budget
    detects there (after half the budget, not at the end), says so with the projection, answers the same when
    resumed, refuses a resume with another design by naming the option, and with --no-futility renders it all."""
    common = (*SMALL, "--unpaired", "--spp", 2, "--tolerance", "0.01%", "--max-passes", 256)
    done = check(*common, "--out", tmp_path / "a", expect=3)
    state = json.loads((tmp_path / "a" / "check.json").read_text())
    last = state["looks"][-1]
    assert last["reason"] == "futile" and 128 <= last["passes"] < 256 and last["promise"] < 0.05, last
    assert f"verdict: inconclusive: stopped early after {last['passes']} of 256 passes a side, neither claim" in (
        done.stdout
    )
    assert "would need about " in done.stdout and "gave up at most 5 % of the power" in done.stdout
    again = check(*common, "--out", tmp_path / "a", "--resume", expect=3)
    assert json.loads((tmp_path / "a" / "check.json").read_text())["looks"] == state["looks"]
    assert again.stdout.splitlines()[0] == done.stdout.splitlines()[0]
    refused = check(*common, "--no-futility", "--out", tmp_path / "a", "--resume", expect=2)
    assert refused.stderr.strip().endswith("it was started with the futility stop, not --no-futility"), refused.stderr
    full = check(*common, "--no-futility", "--out", tmp_path / "b", expect=3)
    assert json.loads((tmp_path / "b" / "check.json").read_text())["looks"][-1]["passes"] == 256, full.stdout


@pytest.mark.slow
def test_a_paired_check_tests_each_pixels_differences_and_finds_sooner(tmp_path):
    """Two bounces instead of unlimited ones on the diffuse corner, paired: each side writes its passes' images,
    the check folds them into the moments of each pixel's difference (their mean is the difference of the sides'
    mean images), deletes them, and decides in fewer passes than with the tile sums alone."""
    common = (*SMALL, "--set", "cycles.max_bounces=2", "--max-passes", 64)
    check(*common, "--out", tmp_path / "pixels", expect=1)
    check(*common, "--pixel-variance", "off", "--out", tmp_path / "tiles", expect=1)
    report = json.loads((tmp_path / "pixels" / "report.json").read_text())
    assert report["pixel_variance"]["used"] and report["test"] == "paired"
    ref, test = (wc.load_stats(tmp_path / "pixels" / name) for name in ("reference.npz", "test.npz"))
    with np.load(tmp_path / "pixels" / "pairs.npz") as pairs:
        assert pairs["seeds"].tolist() == ref.seeds
        np.testing.assert_allclose(pairs["mean"], test.pixels.mean - ref.pixels.mean, atol=1e-6)
    assert not any((tmp_path / "pixels" / "pairs" / "test").iterdir())
    assert not (tmp_path / "tiles" / "pairs.npz").exists()
    passes = [json.loads((tmp_path / run / "check.json").read_text())["looks"][-1]["passes"] for run in ("pixels",
              "tiles")]  # fmt: skip
    assert passes[0] < passes[1]


@pytest.mark.slow
def test_a_check_started_before_the_pixel_test_resumes_without_it(tmp_path):
    common = (*SMALL, "--unpaired", "--tolerance", "0.01%", "--out", tmp_path)
    check(*common, "--max-passes", 18, expect=3)
    state = json.loads((tmp_path / "check.json").read_text())
    assert state["plan"]["pixel_variance"] == "auto"
    del state["plan"]["pixel_variance"]
    (tmp_path / "check.json").write_text(json.dumps(state))
    done = check(*common, "--max-passes", 21, "--resume", expect=3)
    state = json.loads((tmp_path / "check.json").read_text())
    assert state["plan"]["pixel_variance"] == "off" and "pixel variances" not in done.stdout
    done = check(*common, "--max-passes", 21, "--resume", "--pixel-variance", "on", expect=2)
    assert "it was started with --pixel-variance off, not --pixel-variance on" in done.stderr


def test_the_futility_stops_price_goes_from_the_command_line_into_the_design():
    from batch.decide.check_job import check_job_from_args
    from batch.decide.check_state import _plan_difference

    parse = cli.build_parser().parse_args
    common = ["check", "--scene", "corner", "--set", "cycles.film_exposure=1.01", "--out", "x"]
    job, default = (check_job_from_args(parse(args)) for args in ([*common, "--futility-loss", "0.2"], common))
    assert job.plan(16).futility_loss == 0.2 and default.plan(16).futility_loss == 0.05
    assert _plan_difference(default.plan(16), job.plan(16)) == "--futility-loss 0.05, not --futility-loss 0.2"
