"""The study of the tool's own cost per pass (benchmarks.studies.pass_cost) at a tiny size: each source gives a
floor and a tool time a pass, measured in the same run, and a line of figures against that floor.

The values are not checked against a goal (a tiny image on a shared machine says nothing about 1080p); that each
source ran its passes and was timed is.
"""

from __future__ import annotations

import math
import re

import pytest

from benchmarks.studies import pass_cost

LINE = re.compile(
    r"^\s+(\S+) (\w+)\s+floor\s+(-?[\d.]+) ms \(.*\)\s+tool\s+(-?[\d.]+) ms \(.*\)\s+own\s+(-?[\d.]+) ms = "
    r"\s*(-?[\d.]+) % of a 1 s pass$"
)


def figures(out: str) -> dict[tuple[str, str], tuple[float, ...]]:
    rows = {}
    for line in out.splitlines():
        if match := LINE.match(line):
            rows[(match[1], match[2])] = tuple(float(v) for v in match.groups()[2:])
    return rows


def check(results: dict, out: str, size: str, sources: tuple[str, ...]) -> None:
    assert set(results) == {(size, source) for source in sources}
    printed = figures(out)
    assert set(printed) == set(results)
    for key, found in results.items():
        assert set(found) == {"floor", "tool"}
        assert all(math.isfinite(v) for v in found.values()), key
        floor, tool, own, share = printed[key]
        assert (floor, tool) == pytest.approx((found["floor"] * 1e3, found["tool"] * 1e3), abs=0.051)
        assert own == pytest.approx(tool - floor, abs=0.11)  # the tool's own cost is the difference
        assert share == pytest.approx(own / 10, abs=0.051)  # as a share of a 1 s pass, in per cent


def test_command_and_ingest_passes_are_timed_against_their_floor(capsys):
    results = pass_cost.main(["--sizes", "64x48", "--sources", "command", "ingest", "--runs", "1", "--passes", "6"])
    check(results, capsys.readouterr().out, "64x48", ("command", "ingest"))
    # Timed from the first pass's line to the last: a pass of a process on this machine takes some time.
    assert results[("64x48", "command")]["floor"] > 0 and results[("64x48", "command")]["tool"] > 0


def test_bpy_passes_are_timed_against_saving_and_reading_the_render_result(capsys):
    pytest.importorskip("bpy")
    results = pass_cost.main(["--sizes", "32x24", "--sources", "bpy", "--runs", "1", "--passes", "4"])
    check(results, capsys.readouterr().out, "32x24", ("bpy",))
    assert results[("32x24", "bpy")]["floor"] > 0 and results[("32x24", "bpy")]["tool"] > 0


def test_dask_workers_are_timed_over_the_difference_of_two_runs(capsys, monkeypatch):
    pytest.importorskip("distributed")
    lengths = []
    whole = pass_cost.whole
    monkeypatch.setattr(pass_cost, "whole", lambda argv, env: lengths.append(argv[argv.index("--seeds") + 1])
                        or whole(argv, env))  # fmt: skip
    results = pass_cost.main(["--sizes", "64x48", "--sources", "workers", "--runs", "1", "--passes", "24"])
    check(results, capsys.readouterr().out, "64x48", ("workers",))
    assert lengths == ["0:72", "0:24"]  # whole chunks of both workers, the longer run three times the shorter
    assert results[("64x48", "workers")]["floor"] > 0


@pytest.mark.parametrize("argv", [["--sizes", "64by48"], ["--sizes", "0x8"], ["--passes", "2"]])
def test_bad_sizes_and_pass_counts_are_refused(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        pass_cost.main([*argv, "--sources", "command"])
    assert exc.value.code == 2
    assert "error:" in capsys.readouterr().err
