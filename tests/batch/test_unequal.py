"""Runs of different pass counts, rendered: a glass caustic rendered by the tool (real Cycles through the bpy
module) split into unbiased pairs of 4 v 256 and 256 v 8 passes, `compare` calibrated on them, and what
`batch compare` says of one such pair and of a pair too short for any test that holds with fireflies."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

import welch_core as wc
from welch_core.tile_tests import tile_test_of

pytest.importorskip("bpy", reason="needs the bpy module (Cycles) to render the caustic")

ALPHA = 0.01


@pytest.fixture(scope="module")
def caustic(tmp_path_factory):
    """300 passes of the built-in glass caustic at 64x64, 1 spp, 16-px tiles, rendered by `batch render`."""
    out = tmp_path_factory.mktemp("caustic") / "pool.npz"
    command = [sys.executable, "-m", "batch", "render", "--scene", "corner_glass", "--resolution", "64", "64",
               "--tile", "16", "--seeds", "0:300", "--spp", "1", "--out", str(out)]  # fmt: skip
    subprocess.run(command, check=True, capture_output=True, text=True, timeout=600)
    return wc.load_stats(out)


def splits(pool, n_ref, n_test, count, seed):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        picked = rng.choice(pool.n, n_ref + n_test, replace=False)
        yield pool.subset(np.sort(picked[:n_ref])), pool.subset(np.sort(picked[n_ref:]))


@pytest.mark.slow
@pytest.mark.parametrize(("n_ref", "n_test"), [(4, 256), (256, 8)])
def test_unequal_splits_of_a_rendered_caustic_are_calibrated(caustic, n_ref, n_test, monkeypatch):
    """200 random disjoint splits of the rendered caustic: `biased` in at most alpha of them (the 99.9 % binomial
    limit, 7), where Welch's t-tests alone (the permutation test switched off) called most of them `biased`.
    Measured: 4 v 256: 1 of 200, alone 139; 256 v 8: 0 of 200, alone 104."""
    pairs = list(splits(caustic, n_ref, n_test, 200, [n_ref, n_test]))
    biased = sum(wc.compare(ref, test, ALPHA).verdict == "biased" for ref, test in pairs)
    monkeypatch.setattr(tile_test_of("welch"), "needs_resampling", lambda *args: False)
    alone = sum(wc.compare(ref, test, ALPHA).verdict == "biased" for ref, test in pairs)
    print(f"{n_ref} v {n_test}: biased in {biased} of 200; the t-tests alone {alone}")
    assert biased <= stats.binom.ppf(0.999, 200, ALPHA), biased
    assert alone > 10 * ALPHA * 200, alone  # the case could fail: the t-tests alone are far off here


@pytest.mark.slow
def test_batch_compare_of_unequal_runs_states_the_permutation_test(caustic, tmp_path):
    """`batch compare` of a 256 v 4 split: exit 0 with the permutation test in the notes and report.json; of a
    2 v 8 split: `inconclusive` (exit 3), saying that no bias can be shown with these passes."""
    for name, (n_ref, n_test) in {"long": (256, 4), "short": (2, 8)}.items():
        ref, test = next(splits(caustic, n_ref, n_test, 1, 7))
        wc.save_stats(tmp_path / f"{name}_ref.npz", ref)
        wc.save_stats(tmp_path / f"{name}_test.npz", test)
        done = subprocess.run(
            [sys.executable, "-m", "batch", "compare", str(tmp_path / f"{name}_ref.npz"),
             str(tmp_path / f"{name}_test.npz"), "--out", str(tmp_path / name)],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        report = json.loads((tmp_path / name / "report.json").read_text())
        resampling = report["outcome"]["resampling"]
        assert resampling is not None and resampling["method"] == "permutation max-T"
        if name == "long":
            assert done.returncode == 0 and report["outcome"]["verdict"] != "biased", done.stdout
            assert f"the sides differ in passes ({n_ref} v {n_test})" in done.stdout
        else:
            assert done.returncode == 3 and report["outcome"]["verdict"] == "inconclusive", done.stdout
            assert report["outcome"]["reason"] == "unreachable" and resampling["limited"]
            assert "with 2 v 8 passes no bias can be shown" in done.stdout
