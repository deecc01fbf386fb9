"""Passes of a renderer that is not Cycles (batch/jobs/command.py): a command that writes one pass for a seed into
an EXR. Its template is checked in one line; `render --command` gives the statistics `ingest` gives for the same
files (raw path equals summary path) and resumes to the same statistics; suites and the pytest plugin run such
cases, with Mitsuba 3 as the other renderer where it is installed."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch.errors import BatchError
from batch.jobs import command
from batch.jobs.job import RenderJob
from batch.jobs.template import words as template_words
from tests.helpers.pytest_runs import pytest_in, skip_unless_plugin_installed

ROOT = Path(__file__).resolve().parents[2]
MITSUBA_EXAMPLE = ROOT / "docs" / "examples" / "mitsuba"

#: A renderer of our own: Gaussian noise about 1 (+ shift=X), 32x48, one pass per seed, written with write_exr.
TOY = """
import argparse, sys
import numpy as np
import welch_core as wc
p = argparse.ArgumentParser()
p.add_argument("--seed", type=int, required=True)
p.add_argument("--out", required=True)
p.add_argument("changes", nargs="*")
a = p.parse_args()
shift = float(dict(c.split("=", 1) for c in a.changes).get("shift", 0))
if a.seed == 777:
    sys.exit("toy: seed 777 is unlucky")
image = 1.0 + shift + 0.5 * np.random.default_rng(a.seed).standard_normal((32, 48, 3))
wc.write_exr(a.out, image.astype(np.float32))
"""
TEMPLATE = "{python} toy.py --seed={seed} --out {out} {set}"


def batch(*args, cwd=None, check=None) -> subprocess.CompletedProcess:
    """The tool run in `cwd` (a project's folder): the installed package, as a renderer project runs it."""
    done = subprocess.run([sys.executable, "-m", "batch", *map(str, args)], capture_output=True, text=True, cwd=cwd)
    if check is not None:
        assert done.returncode == check, done.stdout[-3000:] + done.stderr[-3000:]
    return done


@pytest.fixture
def toy(tmp_path):
    (tmp_path / "toy.py").write_text(TOY)
    return tmp_path


@pytest.mark.parametrize(
    ("template", "message"),
    [
        (
            "",
            "--command is empty: give the command that renders one pass, e.g. '{python} render.py --seed {seed} "
            "--out {out}'",
        ),  # fmt: skip
        ("r --out {out}", "--command 'r --out {out}' has no {seed}: each pass needs its own seed and file"),
        ("r {seed}", "--command 'r {seed}' has no {out}: each pass needs its own seed and file"),
        (
            "r {seed} {out} {x}",
            "--command 'r {seed} {out} {x}': unknown placeholder {x} (it takes {seed}, {out}, {spp}, {set}, {python})",
        ),  # fmt: skip
        (
            "r {seed} {out} --k={set}",
            "--command 'r {seed} {out} --k={set}': {set} must be a word of its own, not in '--k={set}'",
        ),  # fmt: skip
        ("r {seed} {out} 'open", '--command "r {seed} {out} \'open": No closing quotation'),
        (
            "r {seed} {out} {",
            "--command 'r {seed} {out} {': Single '{' encountered in format string (write {{ and }} "
            "for a literal brace)",
        ),  # fmt: skip
    ],
)
def test_a_bad_template_is_refused_in_one_line(template, message):
    with pytest.raises(BatchError) as caught:
        template_words(template)
    assert str(caught.value) == message


def test_a_pass_command_line_fills_every_placeholder():
    line = command.argv("{python} 'my render.py' --seed={seed} -o {out} --spp {spp} {set} {{literal}}", 7,
                        "/tmp/p 7.exr", 4, ("max_depth=3", "light_scale=2"))  # fmt: skip
    assert line == [sys.executable, "my render.py", "--seed=7", "-o", "/tmp/p 7.exr", "--spp", "4",
                    "max_depth=3", "light_scale=2", "{literal}"]  # fmt: skip
    assert command.argv("r {seed} {out} {set}", 1, "o.exr", 1) == ["r", "1", "o.exr"]  # no overrides: no words


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"scene": "corner"}, "--command renders the passes itself: a scene does not apply to it"),
        ({"blender": "/opt/blender"}, "--command renders the passes itself: --blender does not apply to it"),
        ({"device": "OPTIX"}, "--command renders the passes itself: --device does not apply to it"),
        ({"resolution": (64, 64)}, "--command renders the passes itself: --resolution does not apply to it"),
        ({"overrides": ("k=1",)}, "--command 'r {seed} {out}' has no {set} for the overrides ['k=1']"),
    ],
)
def test_a_command_job_takes_no_cycles_setting(changes, message):
    with pytest.raises(BatchError) as caught:
        RenderJob(out="a.npz", seeds=[0], command="r {seed} {out}", **changes)
    assert str(caught.value) == message


def test_render_command_gives_what_ingest_gives_for_the_same_files_and_resumes_to_it(toy):
    done = batch("render", "--command", TEMPLATE, "--seeds", "0:5", "--spp", 1, "--tile", 16, "--out", "run.npz",
                 cwd=toy, check=0)  # fmt: skip
    assert "render: 5 passes in run.npz" in done.stderr
    run = wc.load_stats(toy / "run.npz")
    assert run.info.renderer == "command" and run.info.scene == TEMPLATE
    assert run.info.scene_id == command.scene_id(TEMPLATE) and (run.height, run.width) == (32, 48)
    assert not list(toy.glob("*.exr")) and run.seeds == [0, 1, 2, 3, 4]

    # The same passes, written by the toy itself and ingested: the same tile sums (to the last bit).
    files = []
    for seed in range(5):
        files.append(toy / f"pass{seed}.exr")
        subprocess.run([sys.executable, "toy.py", "--seed", str(seed), "--out", files[-1]], cwd=toy, check=True)
    batch("ingest", *files, "--spp", 1, "--tile", 16, "--seeds", "0:5", "--out", "ingested.npz", cwd=toy, check=0)
    ingested = wc.load_stats(toy / "ingested.npz")
    np.testing.assert_array_equal(run.sums, ingested.sums)

    # Two passes, then the rest with --resume: the run of all five at once.
    batch("render", "--command", TEMPLATE, "--seeds", "0:2", "--spp", 1, "--tile", 16, "--out", "part.npz",
          cwd=toy, check=0)  # fmt: skip
    again = batch("render", "--command", TEMPLATE, "--seeds", "0:5", "--spp", 1, "--tile", 16, "--out", "part.npz",
                  cwd=toy, check=2)  # fmt: skip
    assert again.stderr == "error: part.npz already exists: pass --resume to continue it, or choose another --out\n"
    batch("render", "--command", TEMPLATE, "--seeds", "0:5", "--spp", 1, "--tile", 16, "--out", "part.npz",
          "--resume", cwd=toy, check=0)  # fmt: skip
    np.testing.assert_array_equal(wc.load_stats(toy / "part.npz").sums, run.sums)


def test_a_failing_command_is_one_line_and_keeps_the_passes_before_it(toy):
    done = batch("render", "--command", TEMPLATE, "--seeds", "774:780", "--spp", 1, "--tile", 16, "--out", "r.npz",
                 "--checkpoint-every", 1, cwd=toy, check=2)  # fmt: skip
    assert (
        done.stderr.splitlines()[-1] == "error: --command failed for seed 777 (exit code 1): toy: seed 777 is unlucky"
    )
    assert wc.load_stats(toy / "r.npz").seeds == [774, 775, 776]
    done = batch("render", "--command", "true {seed} {out}", "--seeds", "0:2", "--spp", 1, "--out", "t.npz",
                 cwd=toy, check=2)  # fmt: skip
    # the run's start line (a log sees its progress), then the one error line
    assert done.stderr.splitlines()[-1].startswith("error: --command exited 0 for seed 0 without writing {out} (")
    assert sum(line.startswith("error:") for line in done.stderr.splitlines()) == 1
    # a pass with another channel set (a light component written instead of the image) is refused in one line
    (toy / "layers.py").write_text(
        "import sys\nimport numpy as np\nimport welch_core as wc\nseed, out = int(sys.argv[1]), sys.argv[2]\n"
        "image = np.ones((32, 48), np.float32)\n"
        "names = ['diffuse.R', 'diffuse.G', 'diffuse.B'] if seed == 2 else ['R', 'G', 'B']\n"
        "wc.exr.write_exr_channels(out, {n: image for n in names})\n"
    )
    done = batch("render", "--command", "{python} layers.py {seed} {out}", "--seeds", "0:4", "--spp", 1, "--tile",
                 16, "--out", "l.npz", "--checkpoint-every", 1, cwd=toy, check=2)  # fmt: skip
    assert done.stderr.splitlines()[-1] == (
        "error: --command wrote channels ['diffuse.B', 'diffuse.G', 'diffuse.R'] for seed 2, its first pass ['B', "
        "'G', 'R']: every pass must hold the same channels"
    )
    assert wc.load_stats(toy / "l.npz").seeds == [0, 1]
    # ...and so is a pass of another size, without advice about non-finite pixels
    (toy / "size.py").write_text(
        "import sys\nimport numpy as np\nimport welch_core as wc\nseed, out = int(sys.argv[1]), sys.argv[2]\n"
        "wc.write_exr(out, np.ones((40 if seed == 2 else 32, 48, 3), np.float32))\n"
    )
    done = batch("render", "--command", "{python} size.py {seed} {out}", "--seeds", "0:4", "--spp", 1, "--tile",
                 16, "--out", "z.npz", cwd=toy, check=2)  # fmt: skip
    assert done.stderr.splitlines()[-1] == "error: `image` must be 32x48 (height x width) like the run, got 40x48"
    # a command's own exit code 130 is its failure, not an interrupt of the tool (nobody pressed Ctrl-C)
    (toy / "stop.py").write_text("import sys\nsys.exit(130)\n")
    done = batch("render", "--command", "{python} stop.py {seed} {out}", "--seeds", "0:2", "--spp", 1, "--out", "s.npz",
                 cwd=toy, check=2)  # fmt: skip
    assert done.stderr.splitlines()[-1] == "error: --command failed for seed 0 (exit code 130): no output"
    assert sum(line.startswith("error:") for line in done.stderr.splitlines()) == 1


def test_a_hung_pass_is_ended_by_sigterm_at_once_and_by_the_pass_limit(toy):
    """A pass that never ends: SIGTERM stops the run at once (exit 130, the command's process gone); the pass limit
    ends it with one line (exit 2)."""
    (toy / "hang.py").write_text("import sys, time\nif int(sys.argv[1]) == 1:\n    time.sleep(1000)\n"
                                 "import numpy as np\nimport welch_core as wc\n"
                                 "wc.write_exr(sys.argv[2], np.ones((16, 16, 3), np.float32))\n")  # fmt: skip
    line = [sys.executable, "-m", "batch", "render", "--command", "{python} hang.py {seed} {out}", "--seeds", "0:3",
            "--spp", "1", "--tile", "8", "--out", "h.npz", "--checkpoint-every", "1"]  # fmt: skip
    process = subprocess.Popen(line, cwd=toy, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(3)  # the first pass is done, the second hangs
    start = time.monotonic()
    process.send_signal(signal.SIGTERM)
    _out, err = process.communicate(timeout=30)
    assert process.returncode == 130 and time.monotonic() - start < 5, err
    assert "Traceback" not in err and wc.load_stats(toy / "h.npz").seeds == [0]
    hung = subprocess.run(["pgrep", "-f", "hang.py 1 "], capture_output=True)
    assert hung.returncode == 1  # no command left running
    env = {**os.environ, "WELCH_PASS_TIMEOUT": "1.5"}
    done = subprocess.run([*line, "--resume"], cwd=toy, capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 2 and done.stderr.splitlines()[-1] == (
        "error: --command's pass for seed 1 ran past 1.5 s and was stopped (WELCH_PASS_TIMEOUT)"
    )


#: A renderer that says when a pass starts (a file started-SEED) and, for seed 1, waits for a file "go" first;
#: seed 3 fails.
WAITING = """
import os, sys, time
import numpy as np
import welch_core as wc
seed, out = int(sys.argv[1]), sys.argv[2]
open(f"started-{seed}", "w").close()
while seed == 1 and not os.path.exists("go"):
    time.sleep(0.01)
if seed == 3:
    sys.exit("waiting: no pass for seed 3")
wc.write_exr(out, np.full((8, 8, 3), seed, np.float32))
"""


def wait_for(path: Path, seconds: float = 30.0) -> None:
    deadline = time.monotonic() + seconds
    while not path.exists():
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.01)


def test_the_next_pass_renders_while_this_one_is_added(tmp_path):
    """`start_next` runs the next pass's command at once, on a thread of its own: `render` of that seed takes it.
    A failure of a pass started ahead is raised when the pass is taken; one nobody takes ends with the run."""
    (tmp_path / "waiting.py").write_text(WAITING)
    job = RenderJob(out="w.npz", seeds=range(5), command="{python} waiting.py {seed} {out}", command_dir=str(tmp_path))
    with command.CommandRenderer(job) as renderer:
        assert renderer.render(0)[0, 0, 0] == 0
        first = renderer.pass_file
        renderer.start_next(1)
        wait_for(tmp_path / "started-1")  # the next pass runs while this process is free to add the last one
        assert renderer.pass_file == first and os.path.exists(first)  # the pass taken keeps its file meanwhile
        (tmp_path / "go").touch()
        assert renderer.render(1)[0, 0, 0] == 1 and not os.path.exists(first)
        renderer.start_next(3)
        with pytest.raises(BatchError) as failed:
            renderer.render(3)
        assert str(failed.value) == "--command failed for seed 3 (exit code 1): waiting: no pass for seed 3"
        (tmp_path / "go").unlink()
        (tmp_path / "started-1").unlink()
        renderer.start_next(1)  # waits for "go", which never comes
        wait_for(tmp_path / "started-1")
        start = time.monotonic()
    assert time.monotonic() - start < 5  # the pass nobody took was ended with the run
    assert subprocess.run(["pgrep", "-f", "waiting.py 1 "], capture_output=True).returncode == 1


def suite_file(folder: Path, passes: int = 16) -> Path:
    path = folder / "welch_toy.toml"
    path.write_text(
        f'[suite]\ntolerance = "15%"\n[[case]]\nname = "toy"\ncommand = "{TEMPLATE}"\ntile = 16\npasses = {passes}\n'
    )
    return path


@pytest.mark.slow
def test_a_suite_of_command_cases_passes_on_other_seeds_and_finds_a_planted_change(toy):
    """The suite runs the command in its own folder, whatever the current one; the reference knows its command."""
    suite = suite_file(toy)
    elsewhere = toy / "elsewhere"
    elsewhere.mkdir()
    batch("suite", "bless", suite, "--refs", toy / "refs", cwd=elsewhere, check=0)
    done = batch("suite", "run", suite, "--refs", toy / "refs", "--out", toy / "ok", cwd=elsewhere, check=0)
    assert "suite: 1 passed" in done.stdout
    done = batch("suite", "run", suite, "--refs", toy / "refs", "--out", toy / "planted", "--set", "shift=0.05",
                 cwd=elsewhere, check=1)  # fmt: skip
    assert "failed: toy [CPU]" in done.stdout
    summary = json.loads((toy / "planted" / "summary.json").read_text())
    assert summary["cases"][0]["verdict"] == "biased" and summary["cases"][0]["whole_image"]["low"] > 0

    # The same case with another command is refused: its reference was rendered by the old one.
    suite.write_text(suite.read_text().replace("--seed={seed}", "--seed {seed}"))
    done = batch("suite", "run", suite, "--refs", toy / "refs", "--out", toy / "other", cwd=elsewhere, check=2)
    assert "not this case's reference: it should be of the command '{python} toy.py --seed {seed}" in done.stdout


def mitsuba_missing() -> str | None:
    probe = subprocess.run([sys.executable, "-c", "import mitsuba"], capture_output=True, text=True)
    return None if probe.returncode == 0 else "Mitsuba 3 is not installed (./dev test installs it: pip install mitsuba)"


@pytest.mark.slow
def test_a_mitsuba_suite_through_the_pytest_plugin(tmp_path):
    """The example project of docs/examples/mitsuba as a renderer project uses it: blessed once, passing on other
    seeds, failing with a planted change (max_depth 3: no light after the third bounce)."""
    reason = mitsuba_missing()
    if reason:
        pytest.skip(reason)
    skip_unless_plugin_installed()
    for name in ("render.py", "welch_mitsuba.toml"):
        shutil.copy(MITSUBA_EXAMPLE / name, tmp_path / name)
    blessed = pytest_in(tmp_path, "--welch-bless")
    assert blessed.returncode == 0, blessed.stdout[-3000:]
    assert "PASSED welch_mitsuba.toml::cornell_path[CPU]" in blessed.stdout
    reference = wc.load_stats(tmp_path / "welch_mitsuba-refs" / "cornell_path.npz", pixels=False)
    assert reference.n == 32 and (reference.width, reference.height) == (32, 32) and reference.info.spp == 4

    planted = pytest_in(tmp_path, "--welch-set", "max_depth=3")
    assert planted.returncode == 1, planted.stdout[-3000:]
    assert any(line.startswith("failed: biased: ") and "whole image -" in line for line in planted.stdout.splitlines())


def test_check_with_a_command_pairs_the_seeds_of_one_command_and_refuses_what_cannot_work(toy):
    """The toy's passes depend on the seed alone, so a shift is the same in every paired pass (to float32's
    rounding, exactly so in 2 tile-channels): a deterministic difference, `biased` at the first look."""
    done = batch("check", "--command", TEMPLATE, "--set", "shift=0.01", "--spp", 1, "--tile", 16, "--max-passes", 8,
                 "--out", "c", cwd=toy, check=1)  # fmt: skip
    verdict = next(line for line in done.stdout.splitlines() if line.startswith("verdict:"))
    assert verdict == "verdict: biased: 2 tile-channels differ by the same amount in every pass", done.stdout
    done = batch("check", "--command", TEMPLATE, "--spp", 1, "--out", "d", cwd=toy, check=2)
    assert "the two sides are identical by construction" in done.stderr and "--test-command" in done.stderr
    done = batch("check", "--test-command", TEMPLATE, "--spp", 1, "--out", "e", cwd=toy, check=2)
    assert (
        done.stderr == "error: --test-command needs --command: the reference side's passes are rendered the same way\n"
    )
    done = batch("check", "--command", TEMPLATE, "--scene", "corner", "--spp", 1, "--out", "f", cwd=toy, check=2)
    assert done.stderr == "error: --command renders the passes itself: a scene does not apply to it\n"
