"""The pixel-variance study (benchmarks.studies.pixel_variance): its statistic against direct computations on
stacked images and scipy, its p-values uniform where pixels are iid, the dependence ratio D, and the quick run."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from scipy import stats

import welch_core as wc
from benchmarks.studies import pixel_variance as pv

TILE = 16


def _images(rng, n: int, size: int = 32, scale=None) -> np.ndarray:
    """n passes of iid normal pixels (n, size, size, 3), each pixel with its own mean and standard deviation."""
    if scale is None:
        scale = rng.uniform(0.2, 3.0, (size, size, 3))
    return 5.0 + scale * rng.standard_normal((n, size, size, 3))


def test_statistic_matches_a_direct_computation_per_tile_channel():
    rng = np.random.default_rng(1)
    a, b = _images(rng, 3), _images(rng, 5)
    result = pv.pixel_test(pv.side(a), pv.side(b), df_floor=None)
    for i in range(2):
        for j in range(2):
            for c in range(3):
                block = np.s_[:, i * TILE : (i + 1) * TILE, j * TILE : (j + 1) * TILE, c]
                xa, xb = a[block].reshape(3, -1), b[block].reshape(5, -1)
                va, vb = np.var(xa, axis=0, ddof=1) / 3, np.var(xb, axis=0, ddof=1) / 5
                se2 = va.sum() + vb.sum()
                df = se2**2 / ((va**2).sum() / 2 + (vb**2).sum() / 4)
                t = (xb.sum(axis=1).mean() - xa.sum(axis=1).mean()) / np.sqrt(se2)
                assert result.df[i, j, c] == pytest.approx(df, rel=1e-10)
                assert result.pvalue[i, j, c] == pytest.approx(2 * stats.t.sf(abs(t), df), rel=1e-8)
    assert not result.fallback.any()


def test_tile_welch_is_scipys_welch_on_the_tile_sums():
    rng = np.random.default_rng(2)
    a, b = _images(rng, 4), _images(rng, 7)
    p, _df = pv.tile_welch(pv.side(a), pv.side(b))
    sums_a, sums_b = pv.tile_total(a), pv.tile_total(b)
    expected = stats.ttest_ind(sums_b, sums_a, axis=0, equal_var=False).pvalue
    np.testing.assert_allclose(p, expected, rtol=1e-8)


@pytest.mark.parametrize("n_a, n_b", [(2, 2), (3, 8)])
def test_pvalues_are_uniform_where_pixels_are_iid(n_a, n_b):
    rng = np.random.default_rng([3, n_a, n_b])
    scale = rng.uniform(0.2, 3.0, (32, 32, 3))
    trials = 400
    a = _images(rng, trials * n_a, scale=scale).reshape(trials, n_a, 32, 32, 3)
    b = _images(rng, trials * n_b, scale=2 * scale).reshape(trials, n_b, 32, 32, 3)  # unequal variances
    result = pv.pixel_test(pv.side(a), pv.side(b), df_floor=None)
    assert np.median(result.df) > 30  # far above the tile test's n - 1
    assert stats.kstest(result.pvalue.ravel(), "uniform").pvalue > 0.001


def test_the_fallback_takes_the_tile_test_where_few_pixels_vary():
    rng = np.random.default_rng(4)
    a, b = _images(rng, 3), _images(rng, 3)
    a[:, :TILE, :TILE, 0], b[:, :TILE, :TILE, 0] = 1.0, 1.0  # tile (0, 0), red: one varying pixel a side
    a[:, 0, 0, 0], b[:, 0, 0, 0] = rng.standard_normal(3), rng.standard_normal(3)
    sa, sb = pv.side(a), pv.side(b)
    plain, fallback = pv.pixel_test(sa, sb, None), pv.pixel_test(sa, sb, pv.DF_FLOOR)
    assert plain.df[0, 0, 0] < 5 and fallback.fallback[0, 0, 0] and fallback.fallback.sum() == 1
    assert fallback.pvalue[0, 0, 0] == pytest.approx(pv.tile_welch(sa, sb)[0][0, 0, 0])
    np.testing.assert_array_equal(np.delete(fallback.pvalue.ravel(), 0), np.delete(plain.pvalue.ravel(), 0))
    dropped = pv.pixel_test(sa, sb, pv.DF_FLOOR, "drop").pvalue
    assert np.isnan(dropped[0, 0, 0]) and np.array_equal(
        np.delete(dropped.ravel(), 0), np.delete(plain.pvalue.ravel(), 0)
    )


def test_a_constant_tile_is_untestable_and_a_constant_difference_is_found():
    a, b = np.ones((2, 16, 16, 3)), np.ones((2, 16, 16, 3))
    b[..., 1] = 2.0
    p = pv.pixel_test(pv.side(a), pv.side(b)).pvalue
    assert np.isnan(p[0, 0, 0]) and p[0, 0, 1] == 0.0


def test_family_pvalue_is_the_smallest_holm_adjusted_tile_pvalue():
    rng = np.random.default_rng(5)
    p = rng.uniform(0, 0.2, (6, 4, 4, 3))
    p[0, 1, 2, :] = np.nan  # an untestable tile
    p[1, 0, 0, 1] = np.nan  # one untestable channel
    expected = [np.nanmin(wc.holm(wc.combine_channels(trial))) for trial in p]
    np.testing.assert_allclose(pv.family_pvalue(p), expected)


def test_dependence_is_one_for_independent_pixels_and_the_tile_area_for_copies():
    rng = np.random.default_rng(6)
    independent = pv.dependence(_images(rng, 2000))
    assert abs(np.median(independent) - 1) < 0.05
    copies = np.repeat(np.repeat(rng.standard_normal((50, 2, 2, 3)), TILE, axis=1), TILE, axis=2)
    np.testing.assert_allclose(pv.dependence(copies + 1e-9 * rng.standard_normal(copies.shape)), TILE**2, rtol=1e-6)


def test_quick_run_writes_its_csv_and_chart(tmp_path):
    pytest.importorskip("bpy")  # renders the quick pools that the cache does not hold
    assert pv.main(["--quick", "--out", str(tmp_path)]) == 0
    with open(tmp_path / "pixel_variance.csv") as f:
        rows = list(csv.DictReader(f))
    kinds = [r["kind"] for r in rows]
    assert kinds.count("dependence") == len(pv.POOLS)
    assert kinds.count("aa") == len(pv.POOLS) * len(pv.CONFIGS) * len(pv.METHODS)
    assert kinds.count("power") == len(pv.POWER_PAIRS) * len(pv.QUICK["power_n"]) * len(pv.METHODS)
    scrambled = next(r for r in rows if r["kind"] == "dependence" and r["pool"] == "corner_scrambling")
    assert float(scrambled["d_median"]) > 10
    assert (tmp_path / "pixel_variance.png").stat().st_size > 0


def test_the_calibration_study_runs_the_tool_and_shows_the_broken_settings_refused(tmp_path):
    """`benchmarks.studies.pixel_calibration --quick`: `compare` and the check replays with --pixel-variance on the
    pools' own records: the pixel test runs on Tabulated Sobol, the records refuse SOBOL_BURLEY and the scrambling
    distance 0.1, and where the user vouches for the latter the tripwire refuses it."""
    from benchmarks.studies import pixel_calibration

    assert pixel_calibration.main(["--quick", "--out", str(tmp_path)]) == 0
    rows = list(csv.DictReader((tmp_path / "pixel_calibration.csv").open()))
    cell = {(r["pool"], r["design"], r["mode"]): r for r in rows}
    assert {r["kind"] for r in rows} == {"fixed", "sequential", "paired", "paired sequential", "consecutive"}
    assert (
        cell["corner+corner_blue", "2 paired", "auto"]["pixel_used"]
        == cell["corner+corner_blue", "2 paired", "auto"]["trials"]
    )
    assert cell["corner_seeds", "check, budget 16", "auto"]["pixel_used"] != "0"  # check's own consecutive seeds
    assert cell["corner", "2 v 2", "auto"]["pixel_used"] == cell["corner", "2 v 2", "auto"]["trials"]
    assert cell["corner", "check, budget 16", "auto"]["pixel_used"] != "0"
    for pool in ("corner_burley", "corner_scrambling"):
        assert all(cell[pool, d, "auto"]["pixel_used"] == "0" for d in ("2 v 2", "8 v 8", "check, budget 16"))
    assert all(cell["corner_scrambling", d, "on"]["pixel_used"] == "0" for d in ("2 v 2", "4 v 16"))
    assert (tmp_path / "pixel_calibration.png").stat().st_size > 10_000


@pytest.mark.slow
def test_the_pixel_test_is_calibrated_on_a_rendered_caustic():
    """Seeded A/A on 200 passes of the glass caustic rendered by the tool (64², 1 spp, Tabulated Sobol: skewed
    pixels, fireflies): `compare` at 2 v 2 and 3 v 8 and `check`'s looks up to 8 passes a side with the pixel test
    on the pool's own record, `biased` at most at the binomial bound of alpha 0.05."""
    from benchmarks.common import checks
    from benchmarks.common.cache import DEFAULT_DIR
    from benchmarks.common.pools import PoolSpec, load_or_render

    pool = load_or_render(PoolSpec("corner_glass", (), 64, passes=200), DEFAULT_DIR)
    rng = np.random.default_rng(32)
    bound = stats.binom.ppf(0.999, 150, 0.05)
    for n_ref, n_test in ((2, 2), (3, 8)):
        found = used = 0
        for _ in range(150):
            perm = rng.permutation(pool.n)
            ref, test = pool.stats(perm[:n_ref], TILE, True), pool.stats(perm[100 : 100 + n_test], TILE, True)
            c = wc.compare(ref, test, 0.05, "welch", pixel_variance="auto")
            found, used = found + (c.verdict == wc.Verdict.BIASED), used + c.pixel_use.used
        assert used == 150 and found <= bound, (n_ref, n_test, found)
    plan = wc.SequentialPlan(max_passes=8, alpha=0.05, test_kind="welch", pixel_variance="auto")
    runs = [checks.one_run(pool, pool, p[:100], p[100:], plan) for p in (rng.permutation(pool.n) for _ in range(150))]
    assert all(run["pixels"] for run in runs)
    assert sum(run["verdict"] == "biased" for run in runs) <= bound


def test_the_tripwire_study_reads_the_cached_pools_and_writes_its_table(tmp_path):
    """`benchmarks.studies.local_tripwire --quick` on a cache of one synthetic pool of the diffuse corner's
    configuration (independent pixels, its record Cycles' with Tabulated Sobol): A/A rows never refused, planted
    rows refused once the planted ratio is large."""
    import json
    from dataclasses import asdict

    from benchmarks.common.pools import PoolSpec
    from benchmarks.studies import local_tripwire

    spec = PoolSpec("corner", (), 64, passes=40)
    folder = tmp_path / "cache" / f"pool-{spec.key}"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(3)
    np.save(folder / "images.npy", _images(rng, 40, size=64).astype(np.float32))
    info = wc.RunInfo(renderer="Cycles", renderer_version="5.0.1", sampling_pattern="TABULATED_SOBOL",
                      scene="corner", scene_id="builtin:corner:1", settings={
                          "cycles.scrambling_distance": 1.0, "cycles.auto_scrambling_distance": False,
                          "cycles.use_denoising": False, "cycles.use_adaptive_sampling": False})  # fmt: skip
    meta = {"spec": asdict(spec), "info": info.to_json(), "render_seconds": [0.0] * 40, "io_seconds": [0.0] * 40}
    (folder / "meta.json").write_text(json.dumps(meta))
    assert local_tripwire.main(["--quick", "--cache", str(tmp_path / "cache"), "--out", str(tmp_path)]) == 0
    rows = list(csv.DictReader((tmp_path / "local_tripwire.csv").open()))
    aa = [r for r in rows if r["kind"] == "aa"]
    assert [int(r["passes"]) for r in aa] == [n for n in local_tripwire.COUNTS if 2 * n <= 40]
    assert all(r["record"] == "independent pixels" and r["refused"] == "0" for r in aa)
    planted = {(float(r["ratio"]), int(r["passes"])): int(r["refused"]) for r in rows if r["kind"] == "planted"}
    assert planted[64.0, 16] == 3 and planted[2.0, 16] == 0
