"""blender_addon.runner without Blender: command lines, progress parsing, sessions of real subprocesses, cancel."""

import os
import sys
import textwrap
import time
from pathlib import Path

import pytest

from blender_addon import runner

ROOT = Path(__file__).resolve().parent.parent


def test_seed_ranges_are_disjoint_unless_paired():
    assert runner.seed_ranges(0, 8, paired=False) == ("0:8", "8:16")
    assert runner.seed_ranges(100, 3, paired=False) == ("100:103", "103:106")
    assert runner.seed_ranges(5, 4, paired=True) == ("5:9", "5:9")


@pytest.mark.parametrize("first, passes", [(-1, 4), (0, 0), (2**31 - 4, 4)])
def test_seed_ranges_reject_bad_input(first, passes):
    with pytest.raises(ValueError, match="seeds"):
        runner.seed_ranges(first, passes, paired=False)


def _spec(**changes):
    fields = {
        "label": "Test",
        "blend": "/tmp/run/scene.blend",
        "out": "/tmp/run/test.npz",
        "seeds": "8:16",
        "spp": 2,
        "tile": 16,
        "overrides": ("cycles.blur_glossy=0", 'lights["Light"].energy=10'),
        "blend_scene": "Scene",
    }
    return runner.RunSpec(**(fields | changes))


def test_command_with_the_bpy_module_runs_python_m_batch_from_the_extension_root():
    command = runner.command_for(_spec(), ROOT, "", python="/py", python_paths=["/wheels"], base_env={})
    assert command.argv == [
        "/py", "-m", "batch", "render", "/tmp/run/scene.blend",
        "--json-progress", "--seeds", "8:16", "--spp", "2", "--tile", "16", "--device", "CPU",
        "--blend-scene", "Scene",
        "--set", "cycles.blur_glossy=0", "--set", 'lights["Light"].energy=10',
        "--out", "/tmp/run/test.npz",
    ]  # fmt: skip
    assert command.cwd == str(ROOT)
    assert command.env["PYTHONPATH"].split(os.pathsep) == [str(ROOT), "/wheels"]
    assert command.env["PYTHONUNBUFFERED"] == "1"


def test_command_with_a_blender_binary_passes_the_tool_arguments_after_dashdash():
    command = runner.command_for(_spec(resume=True, overrides=()), ROOT, "/opt/blender/blender", base_env={})
    entry = str(ROOT / "batch" / "blender_entry.py")
    assert command.argv[:8] == ["/opt/blender/blender", "-b", "/tmp/run/scene.blend", "--python-exit-code", "1",
                                "--python", entry, "--"]  # fmt: skip
    assert command.argv[8:] == [
        "render", "--json-progress", "--seeds", "8:16", "--spp", "2", "--tile", "16", "--device", "CPU",
        "--blend-scene", "Scene", "--resume", "--out", "/tmp/run/test.npz",
    ]  # fmt: skip
    assert "PYTHONPATH" not in command.env  # Blender ignores it unless started with --python-use-system-env


def test_command_lines_parse_with_the_batch_tool():
    cli = pytest.importorskip("batch.cli")
    module_argv = runner.command_for(_spec(), ROOT, "").argv
    args = cli.build_parser().parse_args(module_argv[3:])
    assert (args.command, args.blend, args.seeds, args.spp, args.tile) == ("render", "/tmp/run/scene.blend",
                                                                          list(range(8, 16)), 2, 16)  # fmt: skip
    assert args.overrides == list(_spec().overrides) and args.json_progress and args.blend_scene == "Scene"
    blender_argv = runner.command_for(_spec(resume=True), ROOT, "/blender").argv
    args = cli.build_parser().parse_args(cli.argv_after_dashdash(blender_argv))
    assert args.blend is None and args.resume and args.out == "/tmp/run/test.npz"


def test_progress_lines_are_picked_out_of_other_output():
    lines = [
        "Fra:1 Mem:12.00M | Time:00:00.01 | Sample 0/1",
        '{"event": "start", "total": 8, "todo": 8, "out": "x.npz"}',
        "{not json",
        '{"something": "else"}',
        '["event", "pass"]',
        '  {"event": "pass", "done": 1, "total": 8, "seed": 0, "seconds": 0.2, "eta": 1.4}  \n',
        '{"event": "unknown"}',
        "",
        '{"event": "done", "out": "x.npz", "passes": 8}',
    ]
    events = [e for e in map(runner.parse_progress_line, lines) if e is not None]
    assert [e["event"] for e in events] == ["start", "pass", "done"]
    assert events[1]["eta"] == 1.4


def test_overall_fraction_counts_both_sides():
    assert runner.overall_fraction(0, 2, 0, 0) == 0.0
    assert runner.overall_fraction(0, 2, 4, 8) == 0.25
    assert runner.overall_fraction(1, 2, 0, 8) == 0.5
    assert runner.overall_fraction(1, 2, 8, 8) == 1.0
    assert runner.overall_fraction(2, 2, 0, 0) == 1.0
    assert runner.overall_fraction(0, 1, 9, 8) == 1.0


def test_one_line_and_durations():
    assert runner.one_line("a\n  b\tc") == "a b c"
    assert len(runner.one_line("x" * 500)) == runner.ERROR_LENGTH
    assert runner.format_seconds(None) == "?"
    assert runner.format_seconds(42.4) == "42 s"
    assert runner.format_seconds(125) == "2 min 05 s"
    assert runner.format_seconds(7300) == "2 h 01 min"


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
    specs, commands = [], []
    for label, mode in zip(("Reference", "Test"), modes, strict=False):
        out = str(tmp_path / f"{label.lower()}.npz")
        specs.append(runner.RunSpec(label, str(temp_copy), out, "0:4"))
        argv = [sys.executable, "-c", FAKE_BATCH, out, str(passes), mode]
        commands.append(runner.Command(argv, str(tmp_path), dict(os.environ)))
    return runner.Session(specs, commands, temporary_files=[str(temp_copy)]), temp_copy


def test_session_runs_both_sides_and_tracks_progress(tmp_path):
    session, temp_copy = _session(tmp_path, ["ok", "warn"])
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
    assert not temp_copy.exists()
    assert session.status_text().startswith("Failed: Test run failed")


def test_session_reports_stderr_of_a_crash(tmp_path):
    session, _ = _session(tmp_path, ["crash", "ok"])
    assert session.wait(timeout=30) == runner.FAILED
    assert session.error == "Reference run failed (exit code 1): RuntimeError: renderer exploded"
    assert not (tmp_path / "test.npz").exists()  # the test side never started


def test_session_fails_when_the_program_is_missing(tmp_path):
    spec = runner.RunSpec("Reference", "x.blend", str(tmp_path / "r.npz"), "0:2")
    command = runner.Command([str(tmp_path / "no-such-program")], str(tmp_path), {})
    session = runner.Session([spec], [command])
    assert session.poll() == runner.FAILED
    assert session.error.startswith("Reference run could not start:")


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
    assert not temp_copy.exists()
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
