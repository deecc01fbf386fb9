"""The benchmarks' pipeline end to end in its quick form: pools rendered with Cycles, trials, charts, README.

Checks that every output exists and is non-empty, not the values (the quick run's pools are far too small).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("bpy")

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_quick_benchmarks_write_every_output(tmp_path):
    out, cache = tmp_path / "out", tmp_path / "cache"
    run = subprocess.run(
        [sys.executable, "-m", "benchmarks", "--quick", "--out", str(out), "--cache", str(cache)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    figures = json.loads((out / "figures.json").read_text())
    assert figures["quick"] is True
    for chart in ("chart1", "chart2", "chart3", "chart4"):
        assert figures[chart]["files"], chart
        for name in figures[chart]["files"]:
            assert (out / name).stat().st_size > 0, name
    csvs, pngs = sorted(out.glob("*.csv")), sorted(out.glob("*.png"))
    assert len(csvs) >= 9 and len(pngs) == 4
    assert all(len(p.read_text().splitlines()) >= 2 for p in csvs)  # a header and at least one row
    readme = (out / "README.md").read_text()
    for png in pngs:
        assert f"({png.name})" in readme


@pytest.mark.slow
def test_the_production_benchmark_splits_the_wall_time():
    """At a tiny size (the figure is for 1920x1080): it runs a check and the bare renders and prints the split."""
    run = subprocess.run([sys.executable, "-m", "benchmarks.studies.production", "--resolution", "64", "36", "--spp",
                          "1", "--passes", "2"], cwd=REPO, capture_output=True, text=True, timeout=300)  # fmt: skip
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    lines = run.stdout.splitlines()
    lines = lines[2:]  # after the progress lines
    assert lines[0] == "textured at 64x36, 1 spp a pass, 2 passes a side, 1 look", lines
    assert lines[2].startswith("  everything else ") and lines[2].endswith(" % of the wall time")
    assert lines[3].startswith("    start-up of a render process: ") and lines[9].startswith("    these together: ")
    assert "peak memory: the largest process of the check" in lines[10]


@pytest.mark.slow
def test_the_sparse_power_and_moderated_studies_write_their_tables(tmp_path):
    """The quick forms (tiny pools, few trials; the power and moderated studies on the sparse study's pools): every
    case, size and method has a row, and the charts are written."""
    run = subprocess.run([sys.executable, "-m", "benchmarks.studies.sparse", "--quick", "--out", str(tmp_path),
                          "--cache", str(tmp_path / "cache")], cwd=REPO, capture_output=True, text=True,
                         timeout=600)  # fmt: skip
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    import csv

    from benchmarks.studies import sparse

    rows = list(csv.DictReader(open(tmp_path / "sparse.csv")))
    assert len(rows) == len(sparse.CASES) * len(sparse.QUICK["passes"]) * len(sparse.METHODS)
    assert all(0 <= int(r["biased"]) + int(r["inconclusive"]) <= int(r["trials"]) for r in rows)
    assert (tmp_path / "sparse.png").stat().st_size > 10_000

    for study in ("power", "moderated"):
        run = subprocess.run([sys.executable, "-m", f"benchmarks.studies.{study}", "--quick", "--out", str(tmp_path),
                              "--cache", str(tmp_path / "cache")], cwd=REPO, capture_output=True, text=True,
                             timeout=600)  # fmt: skip
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
        assert "pool " not in run.stdout + run.stderr  # the sparse study's pools, none rendered again
    power = list(csv.DictReader(open(tmp_path / "power.csv")))
    expected = [(case[0], test) for case in sparse.CASES[:2] for test in ("paired", "unpaired")]
    assert [(r["case"], r["test"]) for r in power] == expected
    assert all(int(r["check_runs"]) == int(r["previous_runs"]) == 4 for r in power)
    assert (tmp_path / "power.png").stat().st_size > 10_000
    moderated = list(csv.DictReader(open(tmp_path / "moderated.csv")))
    assert len(moderated) == 2 * 3 * 2  # per sparse case: bias paired and unpaired, A/A unpaired; n = 2 and 4
    assert all(0 <= float(r["t_biased"]) <= 1 and 0 <= float(r["moderated_biased"]) <= 1 for r in moderated)
