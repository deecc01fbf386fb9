"""Data integrity under hostile input and faults, through the public command line: one writer per output, exit
codes that mean one thing, interrupts that stop the work, paths and terminals of every kind, atomic writes.
The classes of failure each have a test with the exact message (file contents are in core/test_formats.py,
EXR input in core/test_exr.py, run identity in core/test_tiles.py)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch import cli
from batch.errors import BatchError, Exit
from batch.jobs.lock import OutputLock

ROOT = Path(__file__).resolve().parents[2]


def batch(*args, cwd=ROOT, env=None, check=None) -> subprocess.CompletedProcess:
    """``python -m batch ARGS`` as a user runs it."""
    argv = [sys.executable, "-m", "batch", *(a if isinstance(a, bytes) else str(a) for a in args)]
    done = subprocess.run(argv, cwd=cwd, capture_output=True, env=env)
    done.stdout, done.stderr = done.stdout.decode("utf-8", "replace"), done.stderr.decode("utf-8", "replace")
    if check is not None:
        assert done.returncode == check, done.stderr[-3000:]
    return done


def write_run(path, seeds, scale=1.0, size=32, tile=16) -> str:
    rng = np.random.default_rng(min(seeds))
    run = wc.TileStats(size, size, tile, 3, wc.RunInfo(renderer="synthetic"))
    for seed in seeds:
        run.add_pass((rng.exponential(0.5, (size, size, 3)) * scale).astype(np.float32), seed)
    wc.save_stats(path, run)
    return str(path)


# -- one writer per output ---------------------------------------------------------------------------------


def test_a_second_writer_is_refused_at_once_naming_the_first(tmp_path):
    out = tmp_path / "run.npz"
    holder = subprocess.Popen(
        [sys.executable, "-c", f"from batch.jobs.lock import OutputLock\nwith OutputLock({str(out)!r}):\n input()"],
        cwd=ROOT,
        stdin=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 30
        while not any(p.name.startswith(".welch-lock-") for p in tmp_path.iterdir()):
            assert time.monotonic() < deadline
            time.sleep(0.02)
        time.sleep(0.2)  # the PID is written right after the lock is taken
        with pytest.raises(BatchError) as info:
            with OutputLock(out):
                pass
        assert str(info.value) == (
            f"{out} is being written by another process (PID {holder.pid}); wait for it to finish or choose "
            "another --out"
        )
    finally:
        holder.communicate("\n", timeout=30)
    with OutputLock(out):  # released when its holder ends
        pass
    assert [p.name for p in tmp_path.iterdir()] == []  # no lock file left behind


def test_ingest_and_merge_refuse_to_overwrite(tmp_path, capsys):
    a = write_run(tmp_path / "a.npz", range(8))
    b = write_run(tmp_path / "b.npz", range(8, 16))
    exr = tmp_path / "pass.exr"
    wc.write_exr(exr, np.ones((32, 32, 3), np.float32))
    for args in (["ingest", str(exr), "--spp", "1", "--out", a], ["merge", a, b, "--out", b]):
        before = Path(args[-1]).read_bytes()
        assert cli.main(args) == Exit.USAGE
        assert capsys.readouterr().err == f"error: {args[-1]} already exists: choose another --out or remove it first\n"
        assert Path(args[-1]).read_bytes() == before


# -- exit codes mean one thing -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--seeds", "0:2147483647"], "argument --seeds: 0:2147483647 gives 2147483647 seeds; a run takes at most"),
        (
            ["--seeds", "0:4", "--resolution", "70000", "16"],
            "argument --resolution: must be an integer in 1..65536, got ",
        ),
        (["--seeds", "0:4", "--spp", "16777217"], "argument --spp: must be an integer in 1..16777216, got '16777217'"),
        (["--seeds", "0:4", "--resolution", "64", "16", "--tile", "32"], "error: --tile 32 is larger than the image"),
    ],
)
def test_sizes_are_checked_before_anything_is_allocated(tmp_path, args, message):
    base = ["render", "--scene", "corner", "--spp", "1", "--out", tmp_path / "x.npz"]
    if "--spp" in args:
        base = ["render", "--scene", "corner", "--out", tmp_path / "x.npz"]
    done = batch(*base, *args)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.splitlines()) == 1


def test_python_m_batch_works_from_any_folder(tmp_path):
    done = batch("compare", "--help", cwd=tmp_path, check=0)
    assert "usage: python -m batch compare" in done.stdout


def test_a_failure_before_argument_parsing_is_internal_not_biased(tmp_path):
    """A broken installation must not exit 1, which means `biased` to CI."""
    broken = tmp_path / "batch"
    (broken / "jobs").mkdir(parents=True)
    (broken / "__init__.py").write_text("")
    # the entry point, the exit codes and the interrupts' handling it needs (standard library only)
    for name in ("__main__.py", "errors.py", "jobs/__init__.py", "jobs/protocol.py"):
        (broken / name).write_text((ROOT / "batch" / name).read_text())
    (broken / "cli.py").write_text("import no_such_module\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    done = subprocess.run([sys.executable, "-m", "batch", "render"], cwd=tmp_path, capture_output=True, text=True,
                          env=env)  # fmt: skip
    assert done.returncode == 4
    assert done.stderr == (
        "error: internal error: the batch tool can't start: ModuleNotFoundError: No module named 'no_such_module'\n"
    )


def test_dev_keeps_the_callers_folder(tmp_path):
    a = write_run(tmp_path / "a.npz", range(8))
    b = write_run(tmp_path / "b.npz", range(8, 16))
    done = subprocess.run([str(ROOT / "dev"), "batch", "compare", "a.npz", "b.npz", "--out", "report"], cwd=tmp_path,
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "report" / "report.html").is_file()
    assert os.path.samefile(a, tmp_path / "a.npz") and os.path.exists(b)


# -- paths and terminals of every kind -----------------------------------------------------------------------


def test_undecodable_bytes_in_a_path(tmp_path):
    a = write_run(tmp_path / "a.npz", range(8))
    b = write_run(tmp_path / "b.npz", range(8, 16))
    out = os.fsencode(tmp_path) + b"/report-\xff"
    done = batch("compare", a, b, "--out", out, check=0)
    assert "Traceback" not in done.stderr
    assert "report: " in done.stdout and "\\udcff" in done.stdout  # shown escaped, not a crash
    assert os.path.isfile(out + b"/report.json")


def test_a_terminal_that_only_shows_ascii(tmp_path):
    a = write_run(tmp_path / "a.npz", range(8))
    b = write_run(tmp_path / "b.npz", range(8, 16))
    env = dict(os.environ, PYTHONIOENCODING="ascii")
    done = batch("compare", a, b, "--out", tmp_path / "résumé", env=env, check=0)
    assert "Traceback" not in done.stderr and "r\\xe9sum\\xe9" in done.stdout
    done = batch("compare", a, tmp_path / "missing-é.npz", "--out", tmp_path / "r", env=env, check=2)
    assert done.stderr.startswith("error: statistics file ") and "missing-\\xe9.npz" in done.stderr


# -- writes are atomic and checked ---------------------------------------------------------------------------


def test_a_full_disk_keeps_the_previous_report_and_prints_no_success(tmp_path, capsys, monkeypatch):
    a = write_run(tmp_path / "a.npz", range(8))
    b = write_run(tmp_path / "b.npz", range(8, 16), scale=1.5)
    out = tmp_path / "report"
    assert cli.main(["compare", a, b, "--out", str(out)]) == Exit.BIASED
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()

    def full_disk(_fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    assert cli.main(["compare", a, a.replace("a.npz", "b.npz"), "--out", str(out)]) == Exit.USAGE
    captured = capsys.readouterr()
    assert captured.err == "error: No space left on device\n" and "report:" not in captured.out
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # every file as it was, no temporary left


# -- clear words for odd but legal input ---------------------------------------------------------------------


def test_negative_pixels_are_kept_with_a_warning(tmp_path, capsys):
    paths = []
    for seed in range(4):
        image = np.random.default_rng(seed).normal(0.5, 1.0, (32, 32, 3)).astype(np.float32)  # negative lobes
        paths.append(str(tmp_path / f"{seed}.exr"))
        wc.write_exr(paths[-1], image)
    assert cli.main(["ingest", *paths, "--spp", "1", "--out", str(tmp_path / "run.npz")]) == 0
    err = capsys.readouterr().err
    assert err.count("negative pixel values") == 1
    assert f"warning: {paths[0]} has negative pixel values (a filter with negative lobes?): they are kept" in err


# -- with real renders -----------------------------------------------------------------------------------------

SMALL = ("--scene", "corner", "--resolution", 32, 32, "--tile", 16)


@pytest.mark.slow
def test_resume_and_merge_refuse_another_configuration(tmp_path):
    out = tmp_path / "run.npz"
    batch("render", *SMALL, "--seeds", "0:4", "--spp", 1, "--out", out, check=0)
    done = batch("render", "--scene", "glossy", "--resolution", 32, 32, "--tile", 16, "--seeds", "0:8", "--spp", 1,
                 "--resume", "--out", out, check=2)  # fmt: skip
    assert done.stderr == f"error: {out}: can't resume runs that differ in scene: 'corner' and 'glossy'\n"
    assert wc.load_stats(out).n == 4
    exrs = []
    for seed in range(4, 8):
        exrs.append(str(tmp_path / f"{seed}.exr"))
        wc.write_exr(exrs[-1], np.full((32, 32, 3), 0.1 + seed, np.float32))
    batch("ingest", *exrs, "--spp", 1, "--tile", 16, "--seeds", "4:8", "--out", tmp_path / "other.npz", check=0)
    done = batch("merge", out, tmp_path / "other.npz", "--out", tmp_path / "m.npz", check=2)
    assert done.stderr == f"error: {tmp_path / 'other.npz'}: can't merge runs that differ in scene: 'corner' and ''\n"


@pytest.mark.slow
def test_an_override_that_changes_the_samples_is_refused(tmp_path):
    done = batch("render", *SMALL, "--seeds", "0:2", "--spp", 1, "--set", "cycles.samples=64", "--out",
                 tmp_path / "x.npz", check=2)  # fmt: skip
    assert done.stderr == (
        "error: --set cycles.samples=64 changes cycles.samples (1 -> 64), which the job fixes: use --spp instead\n"
    )
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.slow
def test_two_renders_into_one_output(tmp_path):
    out = tmp_path / "run.npz"
    args = [sys.executable, "-m", "batch", "render", *map(str, SMALL), "--seeds", "0:100000", "--spp", "1",
            "--json-progress", "--out", str(out)]  # fmt: skip
    first = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        for line in first.stdout:
            if '"event": "pass"' in line:
                break
        for extra in ([], ["--resume"]):
            done = batch("render", *SMALL, "--seeds", "200000:200004", "--spp", 1, *extra, "--out", out, check=2)
            assert done.stderr == (
                f"error: {out} is being written by another process (PID {first.pid}); wait for it to finish or "
                "choose another --out\n"
            )
    finally:
        first.send_signal(signal.SIGTERM)
        first.communicate(timeout=60)
    assert first.returncode == 130
    assert set(wc.load_stats(out).seeds) <= set(range(100000))  # only the first writer's passes


@pytest.mark.slow
def test_ctrl_c_stops_after_the_current_pass_and_keeps_it(tmp_path):
    """Blender's render operator swallows KeyboardInterrupt: SIGINT must still stop the run, save, exit 130."""
    out = tmp_path / "run.npz"
    args = [sys.executable, "-m", "batch", "render", *map(str, SMALL), "--seeds", "0:100000", "--spp", "1",
            "--checkpoint-every", "100000", "--json-progress", "--out", str(out)]  # fmt: skip
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    done_passes = 0
    for line in proc.stdout:
        if line.startswith("{") and json.loads(line).get("event") == "pass":
            done_passes = json.loads(line)["done"]
            if done_passes >= 3:
                break
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted: the statistics written so far are kept (continue with --resume)" in err
    saved = wc.load_stats(out)
    assert 3 <= saved.n < 1000  # stopped soon after, nothing rendered was lost
    assert saved.seeds == list(range(saved.n))
