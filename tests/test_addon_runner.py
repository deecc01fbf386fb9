"""blender_addon.runner without Blender: seeds of the two sides, sessions of real subprocesses, cancel."""

import os
import sys
import textwrap
import time
from pathlib import Path

import pytest

from batch.jobs.job import RenderJob
from batch.jobs.launch import Command
from blender_addon import runner

ROOT = Path(__file__).resolve().parent.parent


def test_seed_ranges_are_disjoint_unless_paired():
    assert runner.seed_ranges(0, 8, paired=False) == (range(0, 8), range(8, 16))
    assert runner.seed_ranges(100, 3, paired=False) == (range(100, 103), range(103, 106))
    assert runner.seed_ranges(5, 4, paired=True) == (range(5, 9), range(5, 9))


@pytest.mark.parametrize("first, passes", [(-1, 4), (0, 0), (2**31 - 4, 4)])
def test_seed_ranges_reject_bad_input(first, passes):
    with pytest.raises(ValueError, match="seeds"):
        runner.seed_ranges(first, passes, paired=False)


def test_overall_fraction_counts_both_sides():
    assert runner.overall_fraction(0, 2, 0, 0) == 0.0
    assert runner.overall_fraction(0, 2, 4, 8) == 0.25
    assert runner.overall_fraction(1, 2, 0, 8) == 0.5
    assert runner.overall_fraction(1, 2, 8, 8) == 1.0
    assert runner.overall_fraction(2, 2, 0, 0) == 1.0
    assert runner.overall_fraction(0, 1, 9, 8) == 1.0


# A stand-in for `python -m batch render`: the same output protocol, no rendering.
FAKE_BATCH = textwrap.dedent(
    """
    import json, sys, time
    out, passes, mode = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    print("Blender 5.0 (junk line)", flush=True)
    print(json.dumps({"event": "start", "total": passes, "todo": passes, "out": out}), flush=True)
    for k in range(1, passes + 1):
        print("Fra:1 | Sample 1/1", flush=True)
        print(json.dumps({"event": "pass", "done": k, "total": passes, "seed": k, "seconds": 0.01,
                          "eta": 0.01 * (passes - k)}), flush=True)
        if mode == "slow":
            open(out, "w").write(str(k))  # a checkpoint after every pass
            time.sleep(0.2)
    if mode == "error":
        print(json.dumps({"event": "error", "message": "override cycles.nope does not resolve"}), flush=True)
        sys.exit(2)
    if mode == "crash":
        print("Traceback (most recent call last):", file=sys.stderr)
        print("RuntimeError: renderer exploded", file=sys.stderr)
        sys.exit(1)
    if mode == "warn":
        print(json.dumps({"event": "warning", "message": "pass 3 has NaN pixels"}), flush=True)
    open(out, "w").write("stats")
    print(json.dumps({"event": "done", "out": out, "passes": passes}), flush=True)
    """
)


def _session(tmp_path, modes, passes=4):
    temp_copy = tmp_path / "scene.blend"
    temp_copy.write_text("copy")
    sides, commands = [], []
    for label, mode in zip(("Reference", "Test"), modes, strict=False):
        out = str(tmp_path / f"{label.lower()}.npz")
        sides.append(runner.Side(label, RenderJob(out=out, seeds=range(4), blend=str(temp_copy))))
        argv = [sys.executable, "-c", FAKE_BATCH, out, str(passes), mode]
        commands.append(Command(argv, dict(os.environ), str(tmp_path)))
    return runner.Session(sides, commands, temporary_files=[str(temp_copy)]), temp_copy


def test_session_runs_both_sides_and_tracks_progress(tmp_path):
    # "slow" on the first side: a loaded machine must not let it finish within the first poll.
    session, temp_copy = _session(tmp_path, ["slow", "warn"])
    assert session.poll() == runner.RUNNING
    assert session.status_text().startswith("Reference:")
    fractions = []
    while session.poll() == runner.RUNNING:
        fractions.append(session.fraction)
        time.sleep(0.01)
    assert session.state == runner.FINISHED, session.error
    assert fractions == sorted(fractions) and session.fraction == 1.0
    assert (tmp_path / "reference.npz").is_file() and (tmp_path / "test.npz").is_file()
    assert not temp_copy.exists()
    assert session.warnings == ["Test: pass 3 has NaN pixels"]
    assert session.status_text() == "Finished"


def test_session_reports_the_error_event_of_a_failed_side(tmp_path):
    session, temp_copy = _session(tmp_path, ["ok", "error"])
    assert session.wait(timeout=30) == runner.FAILED
    assert session.error == "Test run failed (exit code 2): override cycles.nope does not resolve"
    assert temp_copy.exists()  # kept: the run may be resumed with the scene it started from
    assert session.status_text().startswith("Failed: Test run failed")


def test_session_reports_stderr_of_a_crash(tmp_path):
    session, _ = _session(tmp_path, ["crash", "ok"])
    assert session.wait(timeout=30) == runner.FAILED
    assert session.error == "Reference run failed (exit code 1): RuntimeError: renderer exploded"
    assert not (tmp_path / "test.npz").exists()  # the test side never started


def test_session_fails_when_the_program_is_missing(tmp_path):
    side = runner.Side("Reference", RenderJob(out=str(tmp_path / "r.npz"), seeds=range(2), blend="x.blend"))
    command = Command([str(tmp_path / "no-such-program")], {}, str(tmp_path))
    session = runner.Session([side], [command])
    assert session.poll() == runner.FAILED
    assert session.error.startswith("Reference run could not start: can't start ")
    assert session.error.endswith("no-such-program: No such file or directory")


def test_session_builds_its_commands_from_the_jobs(tmp_path):
    job = RenderJob(out=str(tmp_path / "r.npz"), seeds=range(2), blend="x.blend", blender="/opt/blender")
    session = runner.Session([runner.Side("Reference", job)])
    assert session.commands[0].argv[:3] == ["/opt/blender", "-b", "x.blend"]


def test_cancel_terminates_a_running_side_and_keeps_its_checkpoint(tmp_path):
    session, temp_copy = _session(tmp_path, ["slow", "slow"], passes=1000)
    deadline = time.monotonic() + 30
    while session.poll() == runner.RUNNING and session.progress.done < 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert session.progress.done >= 2
    process = session.process
    started = time.monotonic()
    session.cancel()
    assert time.monotonic() - started < 5
    assert process.popen.poll() is not None
    assert session.state == runner.CANCELLED and session.poll() == runner.CANCELLED
    assert temp_copy.exists()
    assert (tmp_path / "reference.npz").is_file()  # the partial statistics stay for --resume
    assert 0 < session.fraction < 0.5


def test_wait_with_timeout_cancels(tmp_path):
    session, _ = _session(tmp_path, ["slow"], passes=1000)
    assert session.wait(timeout=0.5) == runner.CANCELLED


def test_prune_runs_keeps_the_newest_and_protected(tmp_path):
    names = ["20260101-000000-00-a", "20260102-000000-00-b", "20260103-000000-00-c", "20260104-000000-00-d"]
    for name in names:
        (tmp_path / name).mkdir()
    removed = runner.prune_runs(tmp_path, keep=2, protect=[tmp_path / names[0]])
    assert sorted(p.name for p in removed) == [names[1]]
    assert sorted(p.name for p in tmp_path.iterdir()) == [names[0], names[2], names[3]]
    assert runner.prune_runs(tmp_path / "missing", keep=1) == []
