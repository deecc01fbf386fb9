"""How a run stops when nobody waits for it to decide: a time budget (``check --max-seconds``, a suite case's
``seconds``) ends a pass still rendering, its process group with it, and the run ends with what it rendered; Ctrl-C
is exit 130 in one line wherever it lands (an import, a render, a blocking read, the renders' start), and leaves
no render running. The renderer is a shell command that copies a prepared EXR (it costs nothing) and hangs from a
given pass on, so every stop lands where it is meant to."""

from __future__ import annotations

import functools
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch import cli
from batch.decide.check import BUDGET_MARGIN
from batch.errors import INTERRUPTED_LINE, Exit
from batch.jobs import protocol

ROOT = Path(__file__).resolve().parents[2]

#: One pass: the image PREFIX(SEED % 8).exr; from the pass whose index (SEED % 1000: a check's test side starts at
#: seed 1000000) is in ./hang-from on, it writes its process id into ./hung-INDEX-PID and hangs; with ./slow, each
#: pass first sleeps its seconds.
PASS_SCRIPT = """\
i=$(( $2 % 1000 ))
if [ -e hang-from ] && [ "$i" -ge "$(cat hang-from)" ]; then echo $$ > "hung-$i-$$"; exec sleep 1000; fi
if [ -e slow ]; then sleep "$(cat slow)"; fi
cp "$1$(( $2 % 8 )).exr" "$3"
"""

#: A Blender for `matrix`: it answers --version, and hangs once asked to render (writing its process id first).
FAKE_BLENDER = """\
#!/bin/sh
if [ "$1" = --version ]; then echo "Blender $(basename "$0" | tr -dc 0-9.)"; exit 0; fi
echo $$ > "$(dirname "$0")/hung-blender-$$"
exec sleep 1000
"""

CHECK = ["check", "--command", "sh pass.sh p {seed} {out}", "--test-command", "sh pass.sh q {seed} {out}",
         "--tile", "16", "--no-futility"]  # fmt: skip

#: Seconds a run may take beyond its budget and `BUDGET_MARGIN` to start (Python, the render processes) and end
#: (the report): generous for a loaded machine, far below the 600 s a hung pass ran before.
ALLOWANCE = 10.0


@pytest.fixture
def renderer(tmp_path) -> Path:
    """A folder with the pass script, its images (32x32, noise about 1, two sets: p and q) and a suite of one case
    rendered by it: 8 passes of reference, a second for the test side."""
    rng = np.random.default_rng(45)
    for prefix in "pq":
        for index in range(8):
            image = 1.0 + 0.5 * rng.standard_normal((32, 32, 3))
            wc.write_exr(tmp_path / f"{prefix}{index}.exr", image.astype(np.float32))
    (tmp_path / "pass.sh").write_text(PASS_SCRIPT)
    (tmp_path / "welch_hang.toml").write_text('[[case]]\nname = "hang"\ncommand = "sh pass.sh p {seed} {out}"\n'
                                              "tile = 16\npasses = 8\nseconds = 1\n")  # fmt: skip
    return tmp_path


def hang_from(folder: Path, index: int | None) -> None:
    """Passes of this index (and later ones) hang; None: none does."""
    (folder / "hang-from").unlink(missing_ok=True)
    for mark in folder.glob("hung-*"):
        mark.unlink()
    if index is not None:
        (folder / "hang-from").write_text(str(index))


def start(args, folder: Path) -> subprocess.Popen:
    """The tool in `folder` (this repository's code), with SIGINT as a terminal delivers it whatever this process
    inherited (a background job of a non-interactive shell starts with SIGINT ignored, and Python keeps it so)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    reset = functools.partial(signal.signal, signal.SIGINT, signal.SIG_DFL)
    return subprocess.Popen([sys.executable, "-m", "batch", *map(str, args)], cwd=folder, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=reset)  # fmt: skip


def tool(args, folder: Path, expect: int) -> tuple[subprocess.CompletedProcess, float]:
    """Run the tool to its end: what it did, and its wall time."""
    begun = time.monotonic()
    process = start(args, folder)
    out, err = process.communicate(timeout=120)
    done = subprocess.CompletedProcess(process.args, process.returncode, out, err)
    assert done.returncode == expect, out[-3000:] + err[-3000:]
    return done, time.monotonic() - begun


def running(folder: Path) -> list[str]:
    """The hung renders (their marks) whose process is still there."""
    time.sleep(0.2)  # a kill that was sent lands
    left = []
    for mark in folder.glob("hung-*"):
        stat = Path(f"/proc/{int(mark.read_text())}/stat")
        if stat.exists() and stat.read_text().rsplit(")", 1)[1].split()[0] != "Z":  # not dead unreaped
            left.append(mark.name)
    return left


# -- a time budget --------------------------------------------------------------------------------------------


def test_a_check_whose_renderer_hangs_in_its_first_pass_ends_at_its_time_budget(renderer):
    """The hostile round's case: the first pass never ends. The check stops it once the budget and its margin are
    spent (not at the pass limit, 600 s), ends `inconclusive` saying why in one line, keeps a state that
    answers the same when resumed, and leaves no render running."""
    hang_from(renderer, 0)
    out = renderer / "c"
    done, wall = tool([*CHECK, "--max-seconds", 1, "--out", out], renderer, expect=Exit.INCONCLUSIVE)
    assert wall < 1 + BUDGET_MARGIN + ALLOWANCE, wall
    verdict = done.stdout.strip()
    assert verdict.startswith("verdict: inconclusive: the time budget (1.0 s) ended the passes of both sides still "
                              "rendering at "), verdict  # fmt: skip
    assert verdict.endswith(" of render seconds: too few passes to look at (0 of the reference side, 0 of the test "
                            "side; a look needs 2 a side)"), verdict  # fmt: skip
    assert "Traceback" not in done.stderr and not running(renderer)
    state = json.loads((out / "check.json").read_text())
    assert state["ended_pass"] in verdict and state["render_seconds"] > 1 + BUDGET_MARGIN and state["looks"] == []

    hang_from(renderer, None)  # a resumed check renders no more: its budget is spent
    again, _ = tool([*CHECK, "--max-seconds", 1, "--out", out, "--resume"], renderer, expect=Exit.INCONCLUSIVE)
    assert again.stdout == done.stdout and not (out / "reference.npz").exists()


@pytest.mark.slow
def test_a_floor_of_passes_renders_them_whatever_their_seconds(renderer):
    """``--min-passes``: a pass of 1 s on each side, a budget of 1 s. Without a floor the check ends at its first
    look (2 passes a side); with a floor of 3 both sides render 3 passes and the check ends on them. A renderer that
    hangs in the floor's passes is still stopped, at 10 times the budget."""
    hang_from(renderer, None)
    (renderer / "slow").write_text("1")
    done, _wall = tool([*CHECK, "--max-seconds", 1, "--min-passes", 3, "--out", renderer / "floor"], renderer,
                       expect=Exit.INCONCLUSIVE)  # fmt: skip
    report = json.loads((renderer / "floor" / "report.json").read_text())
    assert report["n_ref"] == report["n_test"] == 3 and report["check"]["ended_pass"] is None
    assert report["check"]["min_passes"] == 3 and report["check"]["looks"][-1]["seconds"] > 1 + BUDGET_MARGIN + 2
    assert done.stdout.startswith("verdict: inconclusive: ")

    (renderer / "slow").unlink()
    hang_from(renderer, 0)
    done, wall = tool([*CHECK, "--max-seconds", 0.5, "--min-passes", 3, "--out", renderer / "hung"], renderer,
                      expect=Exit.INCONCLUSIVE)  # fmt: skip
    assert wall < 10 * 0.5 + BUDGET_MARGIN + ALLOWANCE, wall
    assert done.stdout.strip().endswith("too few passes to look at (0 of the reference side, 0 of the test side; a "
                                        "look needs 2 a side)")  # fmt: skip
    assert not running(renderer)


def test_a_floor_of_passes_needs_a_time_budget(renderer, capsys):
    assert cli.main([*CHECK, "--min-passes", "3", "--out", str(renderer / "c")]) == Exit.USAGE
    assert "--min-passes is the floor of a time budget: give --max-seconds too" in capsys.readouterr().err
    args = [*CHECK, "--min-passes", "30", "--max-passes", "20", "--max-seconds", "1", "--out", str(renderer / "c")]
    assert cli.main(args) == Exit.USAGE
    assert "--min-passes 30 is more than --max-passes 20" in capsys.readouterr().err


@pytest.mark.slow
def test_a_check_whose_renderer_hangs_after_some_passes_ends_with_the_verdict_on_them(renderer):
    hang_from(renderer, 3)  # passes 0-2 of each side render, the fourth hangs
    out = renderer / "c"
    done, wall = tool([*CHECK, "--max-seconds", 1, "--out", out], renderer, expect=Exit.INCONCLUSIVE)
    assert wall < 1 + BUDGET_MARGIN + ALLOWANCE, wall
    assert not running(renderer) and "Traceback" not in done.stderr
    assert wc.load_stats(out / "reference.npz").n == wc.load_stats(out / "test.npz").n == 3
    report = json.loads((out / "report.json").read_text())
    assert report["verdict"] == "inconclusive" and report["n_ref"] == report["n_test"] == 3
    ended = report["check"]["ended_pass"]
    assert ended.startswith("the time budget (1.0 s) ended the passes of both sides still rendering at ")
    assert report["check"]["stopped"] == "time budget ended a pass"
    assert f"  note: {ended}: the verdict is on the passes rendered before it" in done.stdout.splitlines()
    state = json.loads((out / "check.json").read_text())
    assert state["ended_pass"] == ended and state["looks"][-1]["passes"] == 3


@pytest.mark.slow
def test_a_suite_case_whose_renderer_hangs_ends_near_its_seconds(renderer):
    """`seconds = 1` with a command that hangs in the case's first pass, then after three passes: the case ends
    within its seconds, the margin and start-up, `inconclusive` (too few passes) or on the passes before."""
    hang_from(renderer, None)
    tool(["suite", "bless", "welch_hang.toml", "--refs", "refs"], renderer, expect=Exit.OK)  # seeds 0-7
    hang_from(renderer, 8)  # the run's first pass
    done, wall = tool(["suite", "run", "welch_hang.toml", "--refs", "refs", "--out", "first"], renderer,
                      expect=Exit.INCONCLUSIVE)  # fmt: skip
    assert wall < 1 + BUDGET_MARGIN + ALLOWANCE, wall
    case = json.loads((renderer / "first" / "summary.json").read_text())["cases"][0]
    assert case["status"] == "inconclusive" and case["passes"] == 0 and case["report"] is None
    assert case["message"].startswith("the time budget (1.0 s) ended the test side's pass still rendering at ")
    assert case["message"].endswith("too few passes to look at (0 of the test side; a look needs 2 a side)")
    assert f"  inconclusive: {case['message']}" in done.stdout.splitlines() and not running(renderer)

    hang_from(renderer, 11)  # seeds 8-10 render, 11 hangs
    done, wall = tool(["suite", "run", "welch_hang.toml", "--refs", "refs", "--out", "later"], renderer,
                      expect=Exit.INCONCLUSIVE)  # fmt: skip
    assert wall < 1 + BUDGET_MARGIN + ALLOWANCE, wall
    case = json.loads((renderer / "later" / "summary.json").read_text())["cases"][0]
    assert case["status"] in ("inconclusive", "underpowered") and case["passes"] == 3, case
    assert "(the time budget (1.0 s) ended the test side's pass still rendering at " in case["message"]
    assert not running(renderer)


# -- Ctrl-C ---------------------------------------------------------------------------------------------------

SIGTERM_CAUGHT = 1 << (signal.SIGTERM - 1)


def took_over_its_signals(pid: int) -> bool:
    """Whether the tool's process handles SIGTERM itself (`batch.jobs.protocol.Interrupts`, from the first line
    of `batch.__main__.run`): before, the interpreter is starting, and a signal is Python's own affair."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:  # it has ended
        return True
    caught = next(line for line in status.splitlines() if line.startswith("SigCgt:"))
    return bool(int(caught.split()[1], 16) & SIGTERM_CAUGHT)


def interrupt(args, folder: Path, moment) -> subprocess.CompletedProcess:
    """Start the tool, send SIGINT `moment` seconds after it took over its signals (or once the file `moment`
    exists: a render started), and return what it did."""
    if not Path("/proc/self/status").exists():
        pytest.skip("needs /proc to know when the tool has started")
    process = start(args, folder)
    while not took_over_its_signals(process.pid):
        time.sleep(0.001)
    if isinstance(moment, str):
        deadline = time.monotonic() + 60
        while not list(folder.glob(moment)) and time.monotonic() < deadline:
            time.sleep(0.01)
    else:
        time.sleep(moment)
    assert process.poll() is None, "it ended before the interrupt"
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=60)
    return subprocess.CompletedProcess(process.args, process.returncode, out, err)


#: Moments of the start-up (seconds after the tool took over its signals) and after a render started.
MOMENTS = [0.05, 0.2, 0.5, 1.0, "render"]
#: The suite's line as each case starts: on stderr where --json-progress has stdout.
SUITE_CASE_LINE = re.compile(r"suite run: \d+/\d+ \S+ on \S+$")


def command_line(command: str, folder: Path) -> tuple[list, str, str | None]:
    """The command line of `command` in `folder`, what it writes (removed before each run), and the mark of its
    first render that hangs."""
    if command == "check":  # the first pass of each side renders, the second hangs
        hang_from(folder, 1)
        return [*CHECK, "--json-progress", "--out", "c"], "c", "hung-1-*"
    if command == "render":
        hang_from(folder, 1)
        return ["render", "--command", "sh pass.sh p {seed} {out}", "--seeds", "0:4", "--spp", 1, "--json-progress",
                "--out", "r.npz"], "r.npz", "hung-1-*"  # fmt: skip
    if command == "suite run":  # the run's first pass (seed 8) renders, the second hangs
        hang_from(folder, None)
        tool(["suite", "bless", "welch_hang.toml", "--refs", "refs"], folder, expect=Exit.OK)
        hang_from(folder, 9)
        return ["suite", "run", "welch_hang.toml", "--refs", "refs", "--json-progress", "--out", "s"], "s", "hung-9-*"
    if command == "matrix":  # scipy imports late here (the hostile round's traceback); the builds' renders hang
        for version in ("4.5.4", "5.0.1"):
            (folder / f"blender{version}").write_text(FAKE_BLENDER)
            (folder / f"blender{version}").chmod(0o755)
        builds = [str(folder / "blender4.5.4"), str(folder / "blender5.0.1")]
        return ["matrix", "--scene", "corner", "--builds", *builds, "--out", "m"], "m", "hung-blender-*"
    assert command == "compare"  # its reference a pipe nobody writes: it waits reading it, as on a stuck mount
    rng = np.random.default_rng(1)
    stats = wc.TileStats.from_sums(rng.normal(100, 2, (8, 2, 2, 3)), range(100, 108), 32, 32, 16)
    wc.save_stats(folder / "test.npz", stats)
    os.mkfifo(folder / "reference.npz")
    return ["compare", "reference.npz", "test.npz", "--out", "r"], "r", None


@pytest.mark.slow
@pytest.mark.parametrize("command", ["check", "matrix", "compare", "suite run", "render"])
def test_ctrl_c_is_exit_130_in_one_line_wherever_it_lands(renderer, command):
    """SIGINT at several moments of each command's start (imports, scipy's among them; the render processes'
    start) and once a render hangs: exit 130, the one line on stderr (the commands' progress goes to stdout or
    nowhere; the suite's line per case stays), and no render left running."""
    args, output, mark = command_line(command, renderer)
    for moment in MOMENTS:
        if moment == "render" and mark is None:
            continue
        for leftover in renderer.glob("hung-*"):
            leftover.unlink()
        written = renderer / output  # (its lock is released however the run ends)
        shutil.rmtree(written) if written.is_dir() else written.unlink(missing_ok=True)
        done = interrupt(args, renderer, mark if moment == "render" else moment)
        said = [line for line in done.stderr.splitlines() if not SUITE_CASE_LINE.match(line)]
        assert (done.returncode, said) == (Exit.INTERRUPTED, [INTERRUPTED_LINE]), (moment, done.stderr)
        assert not running(renderer), moment
    if command == "render":  # the pass before the hang is kept
        assert wc.load_stats(renderer / "r.npz").seeds == [0]


def test_ctrl_c_in_matrix_once_its_renders_started_is_exit_130(renderer):
    """The quick subset's share of the test above."""
    args, _output, mark = command_line("matrix", renderer)
    done = interrupt(args, renderer, mark)
    assert (done.returncode, done.stderr) == (Exit.INTERRUPTED, INTERRUPTED_LINE + "\n"), done.stderr
    assert not running(renderer)


def test_an_interrupt_that_surfaced_as_another_exception_is_exit_130(capsys, monkeypatch):
    """Inside an import, an extension module turns the KeyboardInterrupt into an ImportError (scipy's
    `_highspy` did: exit 4, "internal error", a traceback); a library may wrap it in its own error."""

    def imports(_args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise ImportError("initialization failed") from None  # what pybind11 raises; the interrupt is its context

    def wraps(_args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise RuntimeError("the library's own error") from exc

    for command in (imports, wraps):
        monkeypatch.setitem(cli.COMMANDS, "selftest", command)
        assert cli.main(["selftest", "run.npz", "--out", "r"]) == Exit.INTERRUPTED
        captured = capsys.readouterr()
        assert (captured.out, captured.err) == ("", INTERRUPTED_LINE + "\n")


def test_an_interrupt_a_library_swallowed_still_ends_the_run(capsys, monkeypatch):
    """The signal came and the KeyboardInterrupt was swallowed (a library's `except BaseException`, an import that
    went on): the command's waits raise it again, and whatever it returns, the exit is 130."""

    def swallows(_args):
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)  # the handler runs here
        except KeyboardInterrupt:
            pass
        assert protocol.Interrupts.pending()
        return Exit.OK

    monkeypatch.setitem(cli.COMMANDS, "selftest", swallows)
    assert cli.main(["selftest", "run.npz", "--out", "r"]) == Exit.INTERRUPTED
    assert capsys.readouterr().err == INTERRUPTED_LINE + "\n"
    assert not protocol.Interrupts.pending()  # nothing of it outlives the command


def test_an_interrupt_waits_for_a_process_to_be_started_and_recorded():
    """`Interrupts.held`: a render process is started and recorded in one step, so that the stop reaches it."""
    steps = []
    with pytest.raises(KeyboardInterrupt), protocol.Interrupts():
        with protocol.Interrupts.held():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.2)
            steps.append("recorded")
    assert steps == ["recorded"]
