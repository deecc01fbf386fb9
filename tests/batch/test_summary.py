"""What people read about a comparison (batch.present.summary): top tiles, notes, strict JSON, differences."""

import json

import numpy as np
import pytest

from batch.present import summary
from batch.present.pipeline import assess
from tests.helpers.synthetic import make_run, one_bright_tile, scene_means, tile_sum_samples
from welch_core import RunInfo, compare


def test_top_tile_of_a_large_local_bias():
    c = compare(*one_bright_tile())
    top = summary.top_tiles(c)[0]
    assert (top["row"], top["col"], top["x"], top["y"], top["size"]) == (5, 2, 64, 160, 32)
    assert top["significant"] and top["trusted"] and not top["decided"] and top["within"] is None
    assert top["rel_diff"] == pytest.approx(0.2, abs=0.03)
    assert 0.1 < top["ci_low"] < top["rel_diff"] < top["ci_high"] < 0.3


def test_top_tiles_sorted_by_pvalue():
    rng = np.random.default_rng(39)
    m = scene_means()
    shift = 1.0 + 0.02 * rng.uniform(size=m.shape)
    c = compare(
        make_run(tile_sum_samples(rng, 30, m), range(30)), make_run(tile_sum_samples(rng, 30, m, shift), range(30, 60))
    )
    top = summary.top_tiles(c)
    decided = top.pop(0)  # a bias of every tile: decided by a larger tile, listed first with its own interval
    assert decided["decided"] and decided["size"] > c.tile and decided["interval"].startswith("simultaneous")
    assert decided["pvalue"] == c.outcome.most_significant.p_value and not any(t["decided"] for t in top)
    assert len(top) == summary.TOP_TILES == 10
    p = [t["pvalue"] for t in top]
    assert p == sorted(p)
    assert p[0] == np.nanmin(c.tile_pvalues)
    for t in top:
        assert t["channel"] in ("R", "G", "B")
        assert t["pvalue"] == c.tile_pvalues[t["row"], t["col"]]


def test_notes_say_why_tiles_were_left_out():
    rng = np.random.default_rng(40)
    m = scene_means(2, 3)
    ref_sums, test_sums = tile_sum_samples(rng, 8, m), tile_sum_samples(rng, 8, m)
    ref_sums[:, 0, 2, 0], test_sums[:, 0, 2, 0] = 0.3 * 1024, 0.31 * 1024  # constant, different
    c = compare(make_run(ref_sums, range(8)), make_run(test_sums, range(8, 16)))
    assert "1 tile-channels are constant on both sides but differ: a deterministic difference" in summary.notes(c)
    black = np.zeros((5, 2, 3, 3))
    c = compare(make_run(black, range(5)), make_run(black, range(5, 10)))
    assert summary.notes(c) == [
        "fewer than 8 passes a side: the normality of the Welch samples is unchecked",
        "no tile can be tested: every tile-channel has too few passes, zero variance on both sides or non-finite "
        "values (see the counts per reason)",
        "18 tile-channels are the same on both sides in every pass: bounded at 0 once 44 passes are",
    ]


def test_notes_when_every_tile_is_untrusted_name_non_normal_samples():
    rng = np.random.default_rng(43)
    m = scene_means(2, 2)
    ref = tile_sum_samples(rng, 40, m)
    test = tile_sum_samples(rng, 40, m) + (rng.uniform(size=(40, 2, 2, 1)) < 0.03) * 5000.0
    ref = ref + (rng.uniform(size=(40, 2, 2, 1)) < 0.03) * 5000.0
    runs = make_run(ref, range(40)), make_run(test, range(40, 80))
    c = compare(*runs)
    assert c.n_untrusted == c.n_valid == 4 and c.verdict == "inconclusive"
    assert summary.notes(c) == [
        "all 4 testable 32x32 tiles have clearly non-normal Welch samples (fireflies or caustics)",
        "4 32x32 tiles can be tested at no tile size (their Welch samples stay non-normal): `biased` speaks for the "
        "rest of the image",
    ]
    assert c.outcome.reason == "too_untested"
    assert "too much of the image can't be tested" in summary.summarize(c, *runs)["sentence"]


def test_method_sentence_names_the_test_and_pvalue_method():
    rng = np.random.default_rng(45)
    m = scene_means(3, 3)
    ref = make_run(tile_sum_samples(rng, 30, m), range(30))
    test = make_run(tile_sum_samples(rng, 30, m), range(30, 60))
    sentence = summary.summarize(compare(ref, test, pvalue_method="gauss"), ref, test)["method"]
    assert sentence.startswith("Welch's t-test per tile and channel (p: gauss) at tile sizes 32, 64, 128; ")
    assert sentence.endswith("the sizes by Bonferroni")
    with_tolerance = summary.summarize(compare(ref, test, tolerance=0.01), ref, test)["method"]
    assert with_tolerance.endswith(
        "equivalent: every tile-channel of the 32x32 tiles has its 98% interval inside ±1.00 % (an intersection-union "
        "test at 0.01)"
    )


def test_summary_is_strict_json_for_every_verdict():
    rng = np.random.default_rng(46)
    m = scene_means(3, 3)
    ref_sums = tile_sum_samples(rng, 12, m)
    runs = {
        "no_evidence": (ref_sums, tile_sum_samples(rng, 12, m)),
        "biased": (ref_sums, tile_sum_samples(rng, 12, m, 1.3)),
        "inconclusive": (np.zeros_like(ref_sums), np.zeros_like(ref_sums)),
    }
    for verdict, (a, b) in runs.items():
        ref, test = make_run(a, range(12)), make_run(b, range(12, 24))
        c = compare(ref, test)
        assert c.verdict == verdict
        data = json.loads(json.dumps(assess(c, ref, test).summary, allow_nan=False))
        assert data["verdict"] == verdict and data["alpha"] == 0.01
        assert data["verdict_text"] == c.verdict.text
        assert data["grid"] == {"width": 96, "height": 96, "tile": 32, "tiles_x": 3, "tiles_y": 3}
        assert data["tiles"]["total"] == 9
        assert sum(data["tile_channels"].values()) == 27
        assert data["n_ref"] == data["n_test"] == 12
        assert data["reference_selftest"]["n_ref"] == 6
        assert data["sentence"].startswith(c.outcome.verdict_text)
        if verdict == "inconclusive":
            assert data["p_value"] is None and data["top_tiles"] == []
            assert data["outcome"]["min_detectable"] is None
        else:
            assert 0.0 <= data["p_value"] <= 1.0
            assert data["outcome"]["min_detectable"] > 0


def test_differences_as_a_person_writes_them_split_by_what_they_change():
    a = RunInfo(spp=4, renderer="cycles", settings={"cycles.max_bounces": 12, "clamp": 0.0}, overrides=("x=1",))
    b = RunInfo(spp=8, renderer="cycles", settings={"cycles.max_bounces": 2, "denoise": True}, overrides=())
    image, noise = summary.differences(a, b)
    assert image == [
        "spp: 4 → 8",
        "clamp: 0.0 → not in this build",
        "max_bounces: 12 → 2",
        "denoise: not in this build → on",
        "overrides of the reference side: x=1",
    ]
    assert noise == [] and summary.differences(a, a) == ([], [])
    built = RunInfo(renderer="Cycles", renderer_version="3.4.1", build_hash="Unknown", sampling_pattern="SOBOL")
    other = RunInfo(renderer="Cycles", renderer_version="5.0.1", build_hash="a3db93c5b259",
                    sampling_pattern="TABULATED_SOBOL", settings={"cycles.use_light_tree": True})  # fmt: skip
    image, noise = summary.differences(built, other)
    assert image == ["renderer_version: 3.4.1 → 5.0.1", "build_hash: Unknown → a3db93c5b259"]
    assert noise == ["sampling_pattern: SOBOL → TABULATED_SOBOL", "use_light_tree: not in this build → on"]


def test_sides_are_named_by_what_differs():
    old = RunInfo(renderer="Cycles", renderer_version="4.5.4", build_hash="abc")
    new = RunInfo(renderer="Cycles", renderer_version="5.0.1", build_hash="def")
    assert summary.side_names(old, new, None, None) == ("Cycles 4.5.4 (abc)", "Cycles 5.0.1 (def)")
    plain, changed = RunInfo(), RunInfo(overrides=("cycles.max_bounces=2",))
    assert summary.side_names(plain, changed, None, None) == ("the scene as it is", "cycles.max_bounces=2")
    assert summary.side_names(plain, plain, "a.npz", None) == ("a.npz", "test")


def test_a_failed_reference_selftest_is_a_warning():
    fake = {"reference_selftest": {"verdict": "biased"}}
    assert summary.warnings(fake) == ["the reference against itself (two halves) is biased: trust this with care"]
    assert summary.warnings({"reference_selftest": None}) == []


def test_one_meaning_of_significant_a_tile_inside_a_significant_larger_one_is_not_called_significant():
    """A small bias over a 2x2 block of tiles that no 32 px tile shows alone but the 64 px tile around them does:
    the finest tiles are `within` it, not `significant`; the deciding 64 px tile leads the list; the counts per
    size agree with the rows."""
    rng = np.random.default_rng(7)
    m = scene_means()
    shift = np.ones_like(m)
    shift[2:4, 2:4] = 1.012
    c = compare(make_run(tile_sum_samples(rng, 64, m), range(64)), make_run(tile_sum_samples(rng, 64, m, shift),
                                                                               range(64, 128)))  # fmt: skip
    assert c.verdict.label == "biased" and c.outcome.scales[0].significant == 0
    top = summary.top_tiles(c)
    assert top[0]["decided"] and top[0]["size"] == c.outcome.most_significant.tile > c.tile
    rows = top[1:]
    assert not any(t["significant"] for t in rows)
    inside = [t for t in rows if t["within"] is not None]
    assert inside and all(t["within"] == top[0]["size"] or t["within"] > c.tile for t in inside)
    assert all(t["adjusted_pvalue"] > c.alpha for t in rows)
