"""Progress events (batch.jobs.protocol) and their output (batch.present.progress): one way out, one way in."""

import io
import json
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest

from batch.jobs import protocol
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
    err = capsys.readouterr().err
    assert "smallest p 0.0049 (stops at 1.7e-06); a bias beyond 0.76 % ruled out; 28 looks left" in err
