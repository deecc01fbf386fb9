"""Progress events (batch.jobs.protocol) and their output (batch.present.progress): one way out, one way in."""

import io
import json
import os
import subprocess
import sys
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest

from batch.jobs import protocol
from batch.present import fmt
from batch.present import progress as progress_module
from batch.present.progress import Progress

ROOT = Path(__file__).resolve().parents[2]

EVERY_EVENT = [
    protocol.Started(total=8, todo=5, out="runs/ref.npz"),
    protocol.PassDone(done=4, total=8, seed=3, seconds=0.25, eta=1.0),
    protocol.PassDone(done=8, total=8, seed=7, seconds=0.5, eta=None),
    protocol.Warned(message="pass with seed 3 has 2 non-finite pixel values: skipped"),
    protocol.Failed(message="--set cycles.nope=1: 'CyclesRenderSettings' has no property 'nope'"),
    protocol.Saved(out="runs/ref.npz", passes=5),
    protocol.Looked(passes=9, p_value=0.0049, threshold=1.7e-06, ruled_out=0.0076, verdict=None, left=28, seconds=0.7),
    protocol.Looked(passes=11, p_value=1e-9, threshold=1.7e-06, ruled_out=None, verdict="biased", left=27, seconds=0.8),
    protocol.Finished(out="runs/ref.npz", passes=8),
    protocol.Probed(samples=4096, settings={"cycles.use_guiding": True, "cycles.sampling_pattern": "BLUE_NOISE"}),
]


@pytest.mark.parametrize("event", EVERY_EVENT, ids=lambda e: type(e).__name__)
def test_every_event_round_trips(event):
    line = protocol.to_line(event)
    assert "\n" not in line and json.loads(line)["event"] == event.name
    assert protocol.parse(line) == event
    assert protocol.parse("  " + line + "\n") == event


def test_every_event_type_is_tested():
    assert {type(e) for e in EVERY_EVENT} == set(protocol.EVENT_TYPES.values())


def test_other_output_is_skipped():
    lines = [
        "Fra:1 Mem:12.00M | Time:00:00.01 | Sample 0/1",
        "{not json",
        '{"something": "else"}',
        '["event", "pass"]',
        '{"event": "unknown"}',
        '{"event": "pass", "done": "1", "total": 8, "seed": 0, "seconds": 0.2}',  # a mistyped field
        '{"event": "pass", "done": true, "total": 8, "seed": 0, "seconds": 0.2}',
        '{"event": "done", "out": "x.npz"}',  # a missing field
        "",
    ]
    assert [protocol.parse(line) for line in lines] == [None] * len(lines)


def test_non_finite_numbers_become_null():
    line = protocol.to_line(protocol.PassDone(done=1, total=2, seed=0, seconds=0.1, eta=float("inf")))
    assert json.loads(line)["eta"] is None


def test_progress_lines_for_people_and_programs():
    for json_lines in (False, True):
        out, err = io.StringIO(), io.StringIO()
        with redirect_stdout(out), redirect_stderr(err):
            progress = Progress(4, json_lines=json_lines, label="reference")
            progress.start(1, "ref.npz")
            progress.pass_done(7, 0.5)
            progress.warning("careful")
            progress.finished("ref.npz", 4)
        if json_lines:
            assert err.getvalue() == ""
            parsed = [protocol.parse(line) for line in out.getvalue().splitlines()]
            assert parsed == [
                protocol.Started(total=4, todo=3, out="ref.npz"),
                protocol.PassDone(done=2, total=4, seed=7, seconds=0.5, eta=1.0),
                protocol.Warned(message="careful"),
                protocol.Finished(out="ref.npz", passes=4),
            ]
        else:
            assert out.getvalue() == ""
            assert err.getvalue().splitlines() == [
                "reference: 3 of 4 passes to render into ref.npz",
                "reference: pass 2/4 (seed 7) 0.50 s, ETA 1.0 s",
                "warning: careful",
                "reference: 4 passes in ref.npz",
            ]


def test_a_reader_that_goes_away_does_not_stop_the_job():
    """`--json-progress | head -1`: no BrokenPipeError traceback; the job goes on and ends normally."""
    code = (
        "from batch.present.progress import Progress\n"
        "p = Progress(100000, json_lines=True)\n"
        "for seed in range(100000):\n"
        "    p.pass_done(seed, 0.001)\n"
        "import sys; sys.stderr.write('finished\\n')\n"
    )
    producer = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = producer.stdout.readline()
    producer.stdout.close()  # what `head -1` does after one line
    _, err = producer.communicate(timeout=60)
    assert protocol.parse(first.decode()) is not None
    assert producer.returncode == 0 and err.decode() == "finished\n"


def test_a_terminal_gets_one_live_line(capsys):
    progress = Progress(4, label="reference", live=True)
    progress.start(0, "ref.npz")
    for seed in range(3):
        progress.pass_done(seed, 0.01)
    progress.warning("careful")
    progress.finished("ref.npz", 4)
    err = capsys.readouterr().err
    assert "reference:" in err and "3/4" in err and "pass/s" in err  # tqdm's line: done, total, rate
    assert "warning: careful" in err and "reference: 4 passes in ref.npz" in err
    assert "pass 1/4 (seed 0)" not in err  # no line per pass


def test_a_check_on_a_terminal_shows_the_evidence_on_its_line(capsys):
    progress = Progress(0, label="check", live=True)
    progress.emit(protocol.Looked(passes=9, p_value=0.0049, threshold=1.7e-06, ruled_out=0.0076, verdict=None,
                                left=28, seconds=0.7))  # fmt: skip
    progress.emit(protocol.Looked(passes=11, p_value=0.0049, threshold=1.7e-06, ruled_out=0.0076, verdict=None,
                                left=1, seconds=0.9))  # fmt: skip
    err = capsys.readouterr().err
    assert "smallest p 0.0049 (stops at 1.7e-06); a bias beyond 0.76 % ruled out; 28 looks left" in err
    assert "check: look 2 after 00:00, 11 passes a side, rendering 0.9 s (sides summed): " in err
    assert "; 1 look left" in err and "/s" not in err  # no rate of looks ('22310.13look/s'), no '1 looks'


def test_counts_are_singular_or_plural():
    assert [fmt.count(n, "look") for n in (0, 1, 2)] == ["0 looks", "1 look", "2 looks"]
    assert [fmt.count(n, "pass") for n in (1, 2)] == ["1 pass", "2 passes"]
    assert Progress(1, label="render").describe(protocol.Finished(out="a.npz", passes=1)) == "render: 1 pass in a.npz"


class Clock:
    """A monotonic clock the test moves."""

    def __init__(self):
        self.now = 100.0

    def monotonic(self) -> float:
        return self.now


def test_a_log_gets_a_pass_line_at_most_every_few_seconds_and_a_line_while_a_pass_takes_long(monkeypatch, capsys):
    """Not a terminal: 1000 passes of 1 ms are one line, not 1000; passes 2 s apart a line every 5 s; and while a
    render process is polled during a long pass, a line every 5 s saying how far each job polled lately is."""
    clock = Clock()
    monkeypatch.setattr(progress_module, "time", clock)
    monkeypatch.setattr(progress_module, "_PLAIN", progress_module._PlainLog())  # this process's log, on the clock
    monkeypatch.delenv("WELCH_PROGRESS_SECONDS", raising=False)
    fast = Progress(1000, label="render", live=False)
    for seed in range(1000):
        clock.now += 0.001
        fast.pass_done(seed, 0.001)
    assert capsys.readouterr().err.splitlines() == ["render: pass 1/1000 (seed 0) 0.00 s, ETA 1.0 s"]
    slow = Progress(10, label="test", live=False, brief=True)
    for seed in range(10):
        clock.now += 2.0
        slow.pass_done(seed, 2.0)
    lines = capsys.readouterr().err.splitlines()
    assert [line.split(" (")[0] for line in lines] == ["test: pass 1/10", "test: pass 4/10", "test: pass 7/10",
                                                       "test: pass 10/10"]  # fmt: skip
    reference = Progress(10, label="reference", live=False, brief=True)
    reference.emit(protocol.PassDone(done=3, total=10, seed=2, seconds=2.0, eta=14.0))  # relayed from its process
    capsys.readouterr()
    for _ in range(48):  # 12 s of polling both sides every 0.25 s, no pass ending
        clock.now += 0.25
        reference.tick()
        slow.tick()
    lines = capsys.readouterr().err.splitlines()
    assert lines == [
        "reference: 3/10 passes, 5.0 s since the last; test: 10/10 passes, 5.0 s since the last",
        "reference: 3/10 passes, 10 s since the last; test: 10/10 passes, 10 s since the last",
    ]
    monkeypatch.setenv("WELCH_PROGRESS_SECONDS", "1")
    clock.now += 1.5  # the reference side is no longer polled: its job ended
    for _ in range(8):
        clock.now += 0.25
        slow.tick()
    assert capsys.readouterr().err.splitlines() == ["test: 10/10 passes, 14 s since the last",
                                                    "test: 10/10 passes, 15 s since the last"]  # fmt: skip


def test_a_piped_check_says_how_far_it_is_while_its_passes_take_long(tmp_path):
    """`check` with its output piped (a CI log): a renderer whose passes take 1.2 s, lines every 0.4 s
    (WELCH_PROGRESS_SECONDS): no gap in stderr longer than about that, and no flood."""
    (tmp_path / "slow.py").write_text(
        "import sys, time\nimport numpy as np\nimport welch_core as wc\n"
        "seed, out = int(sys.argv[1]), sys.argv[2]\ntime.sleep(1.2)\n"
        "wc.write_exr(out, (1 + 0.1 * np.random.default_rng(seed).standard_normal((16, 16, 3))).astype(np.float32))\n"
    )
    template = f"{{python}} {tmp_path / 'slow.py'} {{seed}} {{out}} {{set}}"
    env = dict(os.environ, WELCH_PROGRESS_SECONDS="0.4")
    argv = [sys.executable, "-m", "batch", "check", "--command", template, "--set", "a=1", "--tile", "8",
            "--max-passes", "3", "--out", str(tmp_path / "c")]  # fmt: skip
    start = time.monotonic()
    with subprocess.Popen(argv, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as job:
        arrivals = [(time.monotonic(), line.rstrip()) for line in job.stderr]
        job.wait(60)
    elapsed = time.monotonic() - start
    assert job.returncode in (0, 3), arrivals
    times = [start] + [t for t, _ in arrivals]
    gaps = [b - a for a, b in zip(times[1:], times[2:], strict=False)]  # from the first line on
    assert max(gaps) < 1.0, arrivals
    assert any("passes, " in line and "since the" in line for _, line in arrivals)  # a line while a pass ran
    assert len(arrivals) <= elapsed / 0.4 + 3 * 2 + 6, arrivals  # a line per interval, per pass and side, per look
