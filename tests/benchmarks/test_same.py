"""The study of what `check` says on unbiased pairs (benchmarks.studies.same): its quick run writes every part, and
the replay is `check`'s own rule (the claim's size kept from its sizing look)."""

from __future__ import annotations

import csv

import pytest

from benchmarks.studies import same


@pytest.mark.slow
def test_the_quick_run_writes_each_part_and_its_chart(tmp_path):
    pytest.importorskip("bpy")  # renders the quick pools that the cache does not hold
    assert same.main(["--quick", "--out", str(tmp_path)]) == 0
    for part in same.PARTS:
        rows = list(csv.DictReader((tmp_path / f"same_{part}.csv").open()))
        assert rows and {r["part"] for r in rows} == {part}, part
    aa = list(csv.DictReader((tmp_path / "same_aa.csv").open()))
    assert {r["scene"] for r in aa} == set(same.QUICK["scenes"])
    assert all(r["verdict"] in ("equivalent", "inconclusive", "biased") and int(r["passes"]) >= 2 for r in aa)
    futility = list(csv.DictReader((tmp_path / "same_futility.csv").open()))
    assert {r["design"] for r in futility} == {"unpaired stop", "unpaired no stop", "paired stop", "paired no stop"}
    assert (tmp_path / "same.png").stat().st_size > 10_000
