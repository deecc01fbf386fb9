"""The batch command line without rendering: seeds, argument handling after ``--``, ingest, compare, selftest,
reports and exit codes, on EXR passes written here."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch import cli
from batch.errors import Exit
from batch.jobs.seeds import format_seeds, parse_seeds

ROOT = Path(__file__).resolve().parents[2]


def write_passes(folder: Path, seeds, scale=1.0, shape=(64, 96)) -> list[str]:
    """Exponential pixels (non-normal, like path-traced samples), one EXR per seed."""
    paths = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        image = (rng.exponential(0.5, (*shape, 4)) * scale).astype(np.float32)
        path = folder / f"pass_{seed:03d}.exr"
        wc.write_exr(path, image)
        paths.append(str(path))
    return paths


def ingest(tmp_path: Path, name: str, seeds, scale=1.0, explicit_seeds=True, tile=16) -> str:
    folder = tmp_path / name
    folder.mkdir()
    paths = write_passes(folder, seeds, scale)
    out = str(tmp_path / f"{name}.npz")
    args = ["ingest", *paths, "--spp", "1", "--tile", str(tile), "--out", out]
    if explicit_seeds:
        args += ["--seeds", ",".join(map(str, seeds))]
    assert cli.main(args) == 0
    return out


# -- seeds and argv ----------------------------------------------------------------------------------------


def test_parse_seeds_range_is_half_open():
    assert parse_seeds("0:4") == [0, 1, 2, 3]
    assert parse_seeds("5,3,9") == [5, 3, 9]
    assert format_seeds([4, 5, 6]) == "4:7"
    assert format_seeds([1, 5]) == "1,5"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("a:b", "--seeds must be A:B or S1,S2,... with integers, got 'a:b'"),
        ("4:4", "--seeds gives no seeds: '4:4'"),
        ("1,2,1", "--seeds repeats a seed: '1,2,1'"),
        ("-3:2", "--seeds must lie in 0..2147483647, got '-3:2'"),
    ],
)
def test_parse_seeds_errors(text, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_seeds(text)


def test_blender_arguments_after_dashdash():
    argv = [
        "blender",
        "-b",
        "scene.blend",
        "--python-exit-code",
        "1",
        "--python",
        "batch/blender_entry.py",
        "--",
        "render",
        "--seeds",
        "0:8",
        "--spp",
        "2",
        "--out",
        "ref.npz",
    ]
    args = cli.build_parser().parse_args(cli.argv_after_dashdash(argv))
    assert args.command == "render" and args.seeds == list(range(8)) and args.spp == 2 and args.blend is None
    assert cli.argv_after_dashdash(["blender", "-b"]) == []


def test_blender_entry_script_parses_arguments_after_dashdash():
    """The entry script, run as Blender runs it (a plain script), hands the arguments after -- to the tool."""
    code = (
        "import runpy, sys; sys.argv = ['blender', '-b', '--python', 'x.py', '--', 'compare', '--help'];"
        f"runpy.run_path({str(ROOT / 'batch' / 'blender_entry.py')!r}, run_name='__main__')"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd="/")
    assert done.returncode == 0, done.stderr
    assert "REF TEST" in done.stdout and "--paired" in done.stdout


def test_blender_entry_script_imports_the_tools_packages_and_nothing_else_of_their_folder(tmp_path):
    """Installed, the tool's packages sit in a venv's site-packages beside another Python's numpy: the entry
    imports batch and welch_core from there, numpy from the Blender's own Python, and never puts the folder on
    sys.path."""
    site = tmp_path / "site-packages"
    (site / "numpy").mkdir(parents=True)
    (site / "numpy" / "__init__.py").write_text("raise ImportError('the venv numpy, built for another Python')\n")
    for name in ("batch", "welch_core"):
        (site / name).symlink_to(ROOT / name)
    code = (
        "import runpy, sys; runpy.run_path(sys.argv[1]);"
        "import batch.cli, welch_core, numpy; print(numpy.__file__);"
        "print(any(p.startswith(sys.argv[2]) for p in sys.path))"
    )
    entry = site / "batch" / "blender_entry.py"
    done = subprocess.run([sys.executable, "-c", code, str(entry), str(site)], capture_output=True, text=True,
                          cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    numpy_file, on_path = done.stdout.split()
    assert not numpy_file.startswith(str(site)) and on_path == "False"


def test_blender_entry_script_says_in_one_line_which_python_lacks_numpy(tmp_path):
    """A Blender whose Python can't import numpy: one line naming that Python and the module, exit 2, and the
    same line as the job's error event for whoever started it."""
    code = (
        "import runpy, sys; sys.modules['numpy'] = sys.modules['bpy'] = None;"
        "sys.argv = ['blender', '-b', '--python', 'x.py', '--', 'render', '--json-progress'];"
        f"runpy.run_path({str(ROOT / 'batch' / 'blender_entry.py')!r}, run_name='__main__')"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == Exit.USAGE
    version = sys.version.split()[0]
    expected = (
        f"this Blender runs Python {version} ({sys.executable}), which can't import numpy (import of numpy halted; "
        "None in sys.modules): install numpy for that Python (Debian's blender package: apt-get install "
        "python3-numpy)"
    )
    assert done.stderr.splitlines() == [f"error: {expected}"]
    from batch.jobs import protocol

    assert [protocol.parse(line) for line in done.stdout.splitlines()] == [protocol.Failed(expected)]


@pytest.mark.parametrize("command", ["render", "ingest", "compare", "selftest", "merge", "lint", "demo"])
def test_every_command_has_help(command, capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main([command, "--help"])
    assert exit_info.value.code == 0
    assert "usage: python -m batch " + command in capsys.readouterr().out


def test_bad_arguments_exit_2(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["render", "--scene", "corner", "--seeds", "x", "--spp", "1", "--out", "a.npz"])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (
        "python -m batch render: error: argument --seeds: must be A:B or S1,S2,... with integers, got 'x' "
        "(see python -m batch render --help)\n"
    )


# -- ingest, compare, selftest ---------------------------------------------------------------------------


def test_compare_unbiased_biased_and_reports(tmp_path, capsys):
    ref = ingest(tmp_path, "ref", range(0, 16))
    same = ingest(tmp_path, "same", range(100, 116))
    brighter = ingest(tmp_path, "brighter", range(200, 216), scale=1.05)

    assert cli.main(["compare", ref, same, "--out", str(tmp_path / "aa")]) == Exit.OK
    assert cli.main(["compare", ref, brighter, "--out", str(tmp_path / "ab")]) == Exit.BIASED
    out = capsys.readouterr().out
    assert "verdict: no evidence of bias" in out and "verdict: biased" in out

    report = json.loads((tmp_path / "ab" / "report.json").read_text())
    assert report["verdict"] == "biased" and report["test"] == "welch" and report["alpha"] == 0.01
    assert report["n_ref"] == report["n_test"] == 16
    assert report["p_value"] < 0.01
    assert report["tiles"]["total"] == 24 and report["tiles"]["valid"] == 24
    assert report["top_tiles"][0]["rel_diff"] > 0
    for name in report["files"].values():
        assert (tmp_path / "ab" / name).stat().st_size > 0
    html = (tmp_path / "ab" / "report.html").read_text()
    assert "<title>Bias test: biased</title>" in html and "P-value histogram" in html
    pmap = wc.read_exr(tmp_path / "ab" / "pvalues.exr")
    assert pmap.shape == (4, 6, 3)


def test_ingested_runs_use_the_pixel_variances_only_where_the_user_vouches(tmp_path, capsys):
    """`ingest` proves nothing about the renderer's pixels: `auto` keeps the tile test and says why; `on` vouches,
    and at 2 passes a side it finds a 5 % brighter image the tile test does not."""
    ref = ingest(tmp_path, "ref", range(0, 2))
    brighter = ingest(tmp_path, "brighter", range(200, 202), scale=1.05)
    capsys.readouterr()
    assert cli.main(["compare", ref, brighter, "--out", str(tmp_path / "auto")]) == Exit.OK
    out = capsys.readouterr().out
    assert "  pixel variances: not used, the reference: not Cycles passes rendered by this tool (vouch for the " \
           "renderer with --pixel-variance on); tile sums' variances everywhere\n" in out  # fmt: skip
    on = ["compare", ref, brighter, "--out", str(tmp_path / "on"), "--pixel-variance", "on"]
    assert cli.main(on) == Exit.BIASED
    out = capsys.readouterr().out
    share = (r"  pixel variances: \d+% of the tile-channels of every size tested by them "
             r"\(vouched for \(--pixel-variance on\)\)\n")  # fmt: skip
    assert re.search(share, out)
    report = json.loads((tmp_path / "on" / "report.json").read_text())
    assert report["pixel_variance"]["used"] and report["pixel_variance"]["mode"] == "on"
    assert "take their variance from their pixels' variances" in report["method"]
    assert cli.main([*on[:-1], "off"]) == Exit.OK
    assert "pixel variances" not in capsys.readouterr().out


def test_full_maps_on_request(tmp_path):
    ref = ingest(tmp_path, "ref", range(0, 8))
    test = ingest(tmp_path, "test", range(100, 108))
    assert cli.main(["compare", ref, test, "--out", str(tmp_path / "r"), "--full-maps"]) == Exit.OK
    files = json.loads((tmp_path / "r" / "report.json").read_text())["files"]
    assert files == {"pvalues_exr": "pvalues.exr", "html": "report.html", "pvalue_map_png": "pvalue_map.png",
                     "overlay_png": "overlay.png"}  # fmt: skip
    for name in files.values():
        assert (tmp_path / "r" / name).stat().st_size > 0
    assert cli.main(["selftest", ref, "--out", str(tmp_path / "s")]) == Exit.OK
    assert not (tmp_path / "s" / "overlay.png").exists()


def test_paired_is_chosen_for_identical_seeds(tmp_path):
    ref = ingest(tmp_path, "ref", range(16))
    brighter = ingest(tmp_path, "brighter", range(16), scale=1.01)
    out = tmp_path / "paired"
    assert cli.main(["compare", ref, brighter, "--out", str(out)]) == Exit.BIASED
    assert json.loads((out / "report.json").read_text())["test"] == "paired"


def test_a_run_compared_with_itself_says_so(tmp_path, capsys):
    ref = ingest(tmp_path, "ref", range(16))
    capsys.readouterr()
    assert cli.main(["compare", ref, ref, "--out", str(tmp_path / "same")]) == Exit.USAGE
    assert capsys.readouterr().err == (
        "error: the two runs hold the same passes and were made the same way (a run compared with itself): compare "
        "it with a run rendered with "
        "other seeds or settings, or run selftest on it\n"
    )


def test_overlapping_seeds_are_refused(tmp_path, capsys):
    a = ingest(tmp_path, "a", range(0, 10))
    b = ingest(tmp_path, "b", range(5, 15))
    assert cli.main(["compare", a, b, "--out", str(tmp_path / "r")]) == Exit.USAGE
    assert "error: the runs share 5 seeds but not all" in capsys.readouterr().err
    assert cli.main(["compare", a, a, "--unpaired", "--out", str(tmp_path / "r")]) == Exit.USAGE
    assert "unpaired Welch test would be invalid" in capsys.readouterr().err


def test_ingest_without_seeds_counts_as_independent(tmp_path):
    a = wc.load_stats(ingest(tmp_path, "a", range(8), explicit_seeds=False))
    b = wc.load_stats(ingest(tmp_path, "b", range(8, 16), explicit_seeds=False))
    assert wc.seed_relation(a.seeds, b.seeds) == "disjoint"


def test_selftest(tmp_path, capsys):
    run = ingest(tmp_path, "run", range(32))
    assert cli.main(["selftest", run, "--out", str(tmp_path / "self")]) == Exit.OK
    report = json.loads((tmp_path / "self" / "report.json").read_text())
    assert report["n_ref"] == report["n_test"] == 16
    assert "even passes" in report["reference"]["name"]


def test_compare_grid_mismatch_exits_2(tmp_path, capsys):
    a = ingest(tmp_path, "a", range(8), tile=16)
    b = ingest(tmp_path, "b", range(8, 16), tile=32)
    assert cli.main(["compare", a, b, "--out", str(tmp_path / "r")]) == Exit.USAGE
    assert (
        "statistics have different grids (width, height, tile, channels): (96, 64, 16, 3) against (96, 64, 32, 3)"
        in (capsys.readouterr().err)
    )


def test_compare_missing_and_foreign_files_exit_2(tmp_path, capsys):
    a = ingest(tmp_path, "a", range(8))
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.arange(3))
    assert cli.main(["compare", a, str(tmp_path / "nope.npz"), "--out", str(tmp_path / "r")]) == Exit.USAGE
    assert f"error: statistics file {str(tmp_path / 'nope.npz')!r} does not exist" in capsys.readouterr().err
    assert cli.main(["compare", a, str(foreign), "--out", str(tmp_path / "r")]) == Exit.USAGE
    assert "is not a welch-bias-stats file" in capsys.readouterr().err


def test_ingest_errors(tmp_path, capsys):
    folder = tmp_path / "p"
    folder.mkdir()
    paths = write_passes(folder, [1, 2])
    small = write_passes(folder, [3], shape=(32, 32))
    out = str(tmp_path / "x.npz")
    assert cli.main(["ingest", *paths, *small, "--spp", "1", "--out", out]) == Exit.USAGE
    assert "must be 64x96 (height x width) like the run, got 32x32" in capsys.readouterr().err
    assert not os.path.exists(out)
    assert cli.main(["ingest", *paths, "--spp", "1", "--seeds", "0:3", "--out", out]) == Exit.USAGE
    assert "error: --seeds gives 3 seeds for 2 files" in capsys.readouterr().err
    nan_pass = folder / "nan.exr"
    image = np.ones((64, 96, 3), np.float32)
    image[3, 4, 1] = np.nan
    wc.write_exr(nan_pass, image)
    assert cli.main(["ingest", *paths, str(nan_pass), "--spp", "1", "--out", out]) == Exit.USAGE
    assert "has 1 non-finite pixel values" in capsys.readouterr().err
    assert cli.main(["ingest", *paths, str(nan_pass), "--spp", "1", "--on-nan", "skip", "--out", out]) == 0
    assert wc.load_stats(out).n == 2


def test_unwritable_report_folder_exits_2(tmp_path, capsys):
    a = ingest(tmp_path, "a", range(8))
    b = ingest(tmp_path, "b", range(8, 16))
    blocker = tmp_path / "file"
    blocker.write_text("x")
    capsys.readouterr()
    assert cli.main(["compare", a, b, "--out", str(blocker / "sub")]) == Exit.USAGE
    assert capsys.readouterr().err == f"error: {blocker / 'sub'}: Not a directory\n"


def test_report_includes_the_reference_against_itself(tmp_path):
    ref = ingest(tmp_path, "ref", range(0, 16))
    test = ingest(tmp_path, "test", range(100, 116))
    cli.main(["compare", ref, test, "--out", str(tmp_path / "r")])
    selftest = json.loads((tmp_path / "r" / "report.json").read_text())["reference_selftest"]
    assert selftest["verdict"] == "no_evidence" and selftest["n_ref"] == selftest["n_test"] == 8
    assert "the reference against itself (two halves of 16 passes)" in (tmp_path / "r" / "report.html").read_text()


def test_merge_equals_one_run(tmp_path, capsys):
    """Two halves ingested separately (other seeds, other machines) merge into the run of all passes."""
    whole = wc.load_stats(ingest(tmp_path, "whole", range(0, 12)))
    first = ingest(tmp_path, "first", range(0, 5))
    second = ingest(tmp_path, "second", range(5, 12))
    out = tmp_path / "merged.npz"
    assert cli.main(["merge", first, second, "--out", str(out)]) == 0
    merged = wc.load_stats(out)
    assert merged.seeds == list(range(12))
    np.testing.assert_allclose(merged.mean, whole.mean, rtol=1e-12)
    np.testing.assert_allclose(merged.variance, whole.variance, rtol=1e-10)
    capsys.readouterr()
    assert cli.main(["merge", first, second, "--out", str(out)]) == Exit.USAGE
    assert capsys.readouterr().err == f"error: {out} already exists: choose another --out or remove it first\n"
    assert cli.main(["merge", first, first, "--out", str(tmp_path / "twice.npz")]) == Exit.USAGE
    assert f"error: {first}: seed 0 is already in this run" in capsys.readouterr().err


def test_no_evidence_says_what_could_have_been_found(tmp_path, capsys):
    ref = ingest(tmp_path, "ref", range(0, 16))
    other = ingest(tmp_path, "other", range(100, 116))
    assert cli.main(["compare", ref, other, "--out", str(tmp_path / "r")]) == Exit.OK
    assert "would have been found with 80 % power" in capsys.readouterr().out
