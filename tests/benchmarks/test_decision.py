"""The simulated `check` runs of the benchmarks (charts 5-8): the simulation on synthetic pools, the tallies, chart
8's synthetic scene and its oracle, and the quick pipeline of charts 5 to 8 end to end (Cycles renders; the values
of the quick run mean nothing)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import welch_core as wc
from benchmarks.charts.equivalence import Model
from benchmarks.common import checks

REPO = Path(__file__).resolve().parents[2]
SIZE, TILE = 64, 16


class SyntheticPool:
    """What `checks` needs of a `benchmarks.common.pools.Pool`: per-pass tile sums at tile 16 (normal, 4x4 tiles)."""

    def __init__(self, passes: int, shift: float = 0.0, seed: int = 0, key: str = "synthetic"):
        rng = np.random.default_rng(seed)
        base = 100.0 * (1.0 + shift)
        self.sums = base + rng.normal(0.0, 10.0, size=(passes, SIZE // TILE, SIZE // TILE, 3))
        self.seeds = list(range(passes))
        self.n = passes
        self.spec = SimpleNamespace(key=f"{key}-{shift}-{seed}", resolution=SIZE)

    def stats(self, indices, tile, pixels=False):
        assert tile == TILE and not pixels  # tile sums only: no pixels to keep moments of
        indices = np.asarray(indices)
        return wc.TileStats.from_sums(self.sums[indices], [self.seeds[i] for i in indices], SIZE, SIZE, TILE)


def test_a_large_bias_stops_at_an_early_look_and_a_null_pair_is_not_biased():
    ref, test = SyntheticPool(64, seed=1), SyntheticPool(64, shift=0.2, seed=2)
    plan = wc.SequentialPlan(max_passes=32, alpha=0.01, tolerance=None)
    order = np.arange(64)
    biased = checks.one_run(ref, test, order[:32], order[32:], plan, TILE)
    assert biased["verdict"] == "biased"
    assert biased["passes"] in wc.look_schedule(32) and biased["passes"] < 32
    same = SyntheticPool(64, seed=3)
    null = checks.one_run(same, same, order[:32], order[32:], plan, TILE)
    assert null["verdict"] == "no_evidence"
    assert null["passes"] == 32  # without a tolerance an unbiased pair runs to the budget


def test_simulate_is_cached_and_paired_runs_share_seeds(tmp_path):
    ref, test = SyntheticPool(24, seed=4), SyntheticPool(24, shift=0.5, seed=4)
    runs = checks.simulate(ref, test, True, 3, tmp_path, tolerance=None)
    assert len(runs) == 3 and all(r["verdict"] == "biased" for r in runs)
    assert checks.simulate(ref, test, True, 3, tmp_path, tolerance=None) == runs
    assert len(list(tmp_path.glob("check-*.json"))) == 1
    assert checks.budget(ref, paired=True) == 24 and checks.budget(ref, paired=False) == 12
    with pytest.raises(ValueError):
        checks.simulate(ref, test, False, 1, tmp_path, max_passes=13)


def test_tally_counts_runs_that_never_end_biased_as_never():
    runs = [{"passes": p, "verdict": v} for p, v in [(2, "biased"), (4, "biased"), (6, "equivalent"), (8, "biased")]]
    t = checks.tally(runs, 0.5)
    assert (t["biased"], t["equivalent"], t["inconclusive"], t["runs"]) == (3, 1, 0, 4)
    assert t["decision_median_s"] == 3.0  # the "higher" median of 2, 4, 6, 8 passes (6) times 0.5 s
    assert t["biased_median_s"] == 4.0  # of 2, 4, 8 passes and one run that never reaches biased: 8
    assert t["biased_p90_s"] is None
    assert t["decision_p90_passes"] == 8


@pytest.mark.slow
def test_quick_decision_charts_write_every_output(tmp_path):
    pytest.importorskip("bpy")
    out, cache = tmp_path / "out", tmp_path / "cache"
    run = subprocess.run(
        [sys.executable, "-m", "benchmarks", "--quick", "--charts", "5", "6", "7", "8", "--out", str(out), "--cache",
         str(cache)],
        cwd=REPO, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    figures = json.loads((out / "figures.json").read_text())
    readme = (out / "README.md").read_text()
    for chart in ("chart5", "chart6", "chart7", "chart8"):
        for name in figures[chart]["files"]:
            assert (out / name).stat().st_size > 0, name
            if name.endswith(".png"):
                assert f"({name})" in readme
    modes = {r["mode"] for r in figures["chart5"]["rows"]}
    assert {"paired", "unpaired", "paired_noeq", "unpaired_noeq"} <= modes
    assert {r["pair"] for r in figures["chart6"]["rows"]} >= {"corner", "glass"}
    assert "The goals of issue 11, measured" in readme


def test_chart8_scene_has_the_moments_it_claims():
    """The synthetic passes' sample mean and variance match the model's (the oracle is computed from the model)."""
    model = Model()
    sums = model.draw(np.random.default_rng(1), 40_000)
    np.testing.assert_allclose(sums.mean(axis=0), model.mean, rtol=1e-3)
    np.testing.assert_allclose(sums.var(axis=0, ddof=1), model.variance, rtol=0.08)
    np.testing.assert_allclose(model.at(model.mean, 128), model.mean.sum(axis=(0, 1))[None, None])


def test_chart8_oracle_matches_its_design_simulated():
    """The oracle's median pass count, against the design it stands for simulated with known variances: at that n
    about half the A/A images have every tile-channel's two one-sided z-tests reject; at its p90 about 90 %."""
    from scipy import stats

    model, rng, z = Model(), np.random.default_rng(2), stats.norm.ppf(0.99)
    for tile, q in ((32, 0.5), (64, 0.9)):
        n = model.oracle(tile, q)
        mean, variance = model.at(model.mean, tile), model.at(model.variance, tile)
        d = rng.normal(0.0, np.sqrt(2 * variance / n), size=(4000, *mean.shape))  # difference of the means
        passed = np.all(np.abs(d) + z * np.sqrt(2 * variance / n) <= 0.01 * mean, axis=(1, 2, 3))
        assert abs(passed.mean() - q) < 0.03, (tile, n, passed.mean())
    medians = [model.oracle(tile, 0.5) for tile in (16, 32, 64, 128)]
    assert medians == sorted(medians, reverse=True)  # coarser tiles average the noise down
