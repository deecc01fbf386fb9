"""blender_addon.runner without Blender: the add-on's check (the command line's engine, stepped from a timer),
its progress and status line, a real check polled to its verdict, a start that fails in one line, Stop keeping
the state for a resume, and the clean-up of old runs."""

from __future__ import annotations

import json
import time

import pytest

from batch.cli.commands import build_parser
from batch.decide.check_job import check_job_from_args
from batch.jobs import protocol
from blender_addon import runner

WALLS = 'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value=0.3,0.3,0.3,1'


def check_run(tmp_path, *args) -> runner.CheckRun:
    argv = ["check", "--scene", "corner", "--resolution", "32", "32", *args, "--out", str(tmp_path / "run")]
    return runner.CheckRun(check_job_from_args(build_parser().parse_args(argv)))


def fake_blender(tmp_path, body: str) -> str:
    path = tmp_path / "blender"
    path.write_text("#!/bin/sh\nif [ \"$1\" = --version ]; then echo 'Blender 4.5.4 LTS'; exit 0; fi\n" + body)
    path.chmod(0o755)
    return str(path)


def test_side_progress_counts_a_resumed_sides_passes():
    side = runner.SideProgress("test")
    side.emit(protocol.Started(total=64, todo=40, out="t.npz"))
    assert (side.done, side.total) == (24, 64)
    side.emit(protocol.PassDone(seed=30, done=25, total=64, seconds=0.1, eta=4.0))
    assert (side.done, side.seconds) == (25, 0.1)


@pytest.mark.slow
def test_a_check_is_polled_to_its_verdict_look_by_look(tmp_path):
    pytest.importorskip("bpy")
    run = check_run(tmp_path, "--set", WALLS)  # walls 0.3 instead of 0.2: found in a few passes
    statuses, looks = set(), []
    deadline = time.monotonic() + 300
    while run.poll() == runner.RUNNING and time.monotonic() < deadline:
        statuses.add(run.status_text())
        taken = run.take_look()
        if taken is not None:
            looks.append(taken[0])
        time.sleep(0.01)
    assert run.state == runner.FINISHED and run.fraction == 1.0, run.error
    look, ref, test = run.result
    assert look.verdict == "biased" and ref.n == test.n == look.passes
    assert looks and looks[-1].passes == look.passes  # every look was offered to the live map, the last too
    assert any(s.startswith("pass ") and "smallest p" in s for s in statuses)
    state = json.loads((tmp_path / "run" / "check.json").read_text())
    assert state["looks"][-1]["verdict"] == "biased"  # what `check --resume` would answer with


def test_a_build_that_is_not_blender_fails_in_one_line(tmp_path):
    blender = tmp_path / "blender"
    blender.write_text("#!/bin/sh\necho hello\n")
    blender.chmod(0o755)
    run = check_run(tmp_path, "--unpaired", "--blender", str(blender))
    assert run.poll() == runner.FAILED
    assert run.error == f"--blender {blender} is not Blender: --version printed 'hello'"
    assert run.status_text() == f"Failed: {run.error}"


def test_stop_keeps_the_state_and_a_resume_continues_it(tmp_path):
    blender = fake_blender(tmp_path, "sleep 60\n")  # starts, never renders
    run = check_run(tmp_path, "--unpaired", "--blender", blender)
    assert run.poll() == runner.RUNNING and run.status_text() == "Starting the renders"
    processes = [side.process.popen for side in run.check.rendered]
    started = time.monotonic()
    run.cancel()
    assert run.state == runner.CANCELLED and time.monotonic() - started < 10
    assert all(p.poll() is not None for p in processes)  # the render processes are gone
    assert (tmp_path / "run" / "check.json").is_file()  # a resume has something to continue
    again = check_run(tmp_path, "--unpaired", "--blender", blender, "--resume")
    assert again.poll() == runner.RUNNING
    assert again.wait(timeout=0.5) == runner.CANCELLED


def test_prune_runs_keeps_the_newest_and_protected(tmp_path):
    names = ["20260101-000000-00-a", "20260102-000000-00-b", "20260103-000000-00-c", "20260104-000000-00-d"]
    for name in names:
        (tmp_path / name).mkdir()
    removed = runner.prune_runs(tmp_path, keep=2, protect=[tmp_path / names[0]])
    assert sorted(p.name for p in removed) == [names[1]]
    assert sorted(p.name for p in tmp_path.iterdir()) == [names[0], names[2], names[3]]
    assert runner.prune_runs(tmp_path / "missing", keep=1) == []
