"""The pixel-variance test (`welch_core.pixels`): per tile-channel H0 "the expected tile sums are equal", tested with
Var(tile sum) estimated as the sum of the tile's pixel variances (independent pixels), inside the tool's family
(union-intersection over tile-channels and scales for `biased`). The moments' streaming path against the batch
one, the statistic against a direct computation with scipy, its fallback, its gate (the run record) and tripwire,
its calibration under H0 and its power where the tile test has none."""

import dataclasses

import numpy as np
import pytest
from scipy import stats

import welch_core as wc
from welch_core.pixels import (
    MIN_PIXEL_DF,
    POOLED_UP_TO,
    TRIPWIRE_RATIO,
    pixel_eligibility,
    pixel_paired,
    pixel_welch,
    tripwire,
)

SIZE, TILE = 64, 16
CYCLES = wc.RunInfo(
    renderer="Cycles",
    renderer_version="5.0.1",
    sampling_pattern="TABULATED_SOBOL",
    scene="corner",
    scene_id="builtin:corner:1",
    settings={
        "cycles.scrambling_distance": 1.0,
        "cycles.auto_scrambling_distance": False,
        "cycles.use_denoising": False,
        'view_layers["ViewLayer"].cycles.use_denoising': False,
        "cycles.use_adaptive_sampling": False,
    },
)


def run_of(images, seeds, info=CYCLES, tile=TILE):
    run = wc.TileStats(images.shape[1], images.shape[2], tile, 3, info, keep_pixel_moments=True)
    for image, seed in zip(images, seeds, strict=True):
        run.add_pass(image, seed)
    return run


def noisy(rng, n, scale=1.0, shift=0.0, size=SIZE):
    """n passes of independent pixels: gamma noise (skewed, like a renderer's), mean 1 + shift, per-pixel scales."""
    spread = np.linspace(0.5, 2.0, size * size * 3).reshape(size, size, 3)
    return (1.0 + shift) + scale * spread * (rng.gamma(2.0, 0.5, (n, size, size, 3)) - 1.0)


# -- the moments ---------------------------------------------------------------------------------------------


def test_streamed_moments_equal_the_batch_ones_and_merge_exactly():
    rng = np.random.default_rng(0)
    images = noisy(rng, 9) * 1e4  # a large offset: the streaming path must not lose the variance to it
    run = run_of(images, range(9))
    batch = wc.PixelMoments.of_passes(images)
    np.testing.assert_allclose(run.pixels.mean, batch.mean, rtol=1e-14)
    np.testing.assert_allclose(run.pixels.m2, batch.m2, rtol=1e-10)
    merged = run_of(images[:4], range(4)).merge(run_of(images[4:], range(4, 9)))
    np.testing.assert_allclose(merged.pixels.m2, batch.m2, rtol=1e-10)
    chunked = run_of(images[:2], range(2))
    chunk = run_of(images[2:], range(2, 9))
    chunked.add_sums(chunk.sums, chunk.seeds, chunk.pixel_sum, chunk.pixels)
    np.testing.assert_allclose(chunked.pixels.m2, batch.m2, rtol=1e-10)
    assert chunked.pixels.n == 9


def test_derived_runs_keep_the_moments_only_where_they_are_the_same_passes():
    run = run_of(noisy(np.random.default_rng(1), 4), range(4))
    assert run.retile(2).pixels is run.pixels
    assert run.subset([0, 1]).pixels is None and run.whole().pixels is None
    without = run_of(noisy(np.random.default_rng(2), 2), range(10, 12))
    without.pixels = None
    assert run.merge(without).pixels is None
    later = run_of(noisy(np.random.default_rng(3), 2), range(20, 22))
    later.add_sums(without.sums, [30, 31], without.pixel_sum)  # a chunk without moments: the run keeps none
    assert later.pixels is None


def test_pixel_terms_at_every_scale_are_the_block_sums_of_the_pixel_variances():
    images = noisy(np.random.default_rng(4), 5, size=40)  # partial tiles at the edges, a last scale beyond them
    run = run_of(images, range(5))
    s2 = images.var(axis=0, ddof=1)
    for factor in (1, 2, 4):
        scale = run.retile(factor) if factor > 1 else run
        v, q = scale.pixel_terms()
        tile = TILE * factor
        for r in range(scale.tiles_y):
            for c in range(scale.tiles_x):
                block = s2[r * tile : (r + 1) * tile, c * tile : (c + 1) * tile]
                np.testing.assert_allclose(v[r, c], block.sum(axis=(0, 1)), rtol=1e-12)
                np.testing.assert_allclose(q[r, c], (block**2).sum(axis=(0, 1)), rtol=1e-12)


def test_a_kept_pass_with_non_finite_pixels_ends_the_moments_and_the_file_still_loads(tmp_path):
    images = noisy(np.random.default_rng(19), 3)
    images[1, 0, 0, 0] = np.nan
    run = wc.TileStats(SIZE, SIZE, TILE, 3, CYCLES, keep_pixel_moments=True)
    for seed, image in enumerate(images):
        run.add_pass(image, seed, allow_nonfinite=True)
    assert run.pixels is None
    wc.save_stats(tmp_path / "nan.npz", run)
    assert wc.load_stats(tmp_path / "nan.npz").n == 3


def test_the_terms_kept_for_the_scales_follow_new_passes():
    images = noisy(np.random.default_rng(18), 4)
    run = run_of(images[:3], range(3))
    before = run.retile(2).pixel_terms()[0].copy()
    run.add_pass(images[3], 3)
    np.testing.assert_allclose(run.retile(2).pixel_terms()[0], run_of(images, range(4)).retile(2).pixel_terms()[0])
    assert not np.allclose(run.retile(2).pixel_terms()[0], before)


def test_moments_survive_a_statistics_file_and_damaged_ones_are_refused(tmp_path):
    run = run_of(noisy(np.random.default_rng(5), 3), range(3))
    path = tmp_path / "run.npz"
    wc.save_stats(path, run)
    back = wc.load_stats(path, pixels=False)
    assert back.pixels.n == 3
    np.testing.assert_array_equal(back.pixels.m2, run.pixels.m2)
    plain = wc.TileStats(SIZE, SIZE, TILE, 3, CYCLES)
    plain.add_pass(noisy(np.random.default_rng(6), 1)[0], 0)
    wc.save_stats(tmp_path / "plain.npz", plain)
    assert wc.load_stats(tmp_path / "plain.npz").pixels is None
    bad = wc.TileStats.from_sums(run.sums, run.seeds, SIZE, SIZE, TILE, CYCLES)
    bad.pixels = wc.PixelMoments.of(run.pixels.mean, run.pixels.m2, 3)
    bad.pixels.m2 = -bad.pixels.m2
    wc.save_stats(tmp_path / "bad.npz", bad)
    damaged = r"bad.npz' is damaged: 'pixel_m2' must be finite and >= 0, got -\S+ \(pixel x 0, y 0, channel 0, and"
    with pytest.raises(wc.StatsFileError, match=damaged):
        wc.load_stats(tmp_path / "bad.npz")


def test_moments_added_in_bands_equal_the_whole_image_update_bit_for_bit():
    """`PixelMoments.add` updates a band of rows at a time (cache-sized): each pixel's operations are those of the
    update of the whole arrays at once, so the moments are identical, whatever the width (one row a band or many)."""
    rng = np.random.default_rng(21)
    for height, width in ((37, 41), (3, 20000), (300, 7)):
        banded, whole = wc.PixelMoments(height, width), wc.PixelMoments(height, width)
        for n in range(1, 5):
            image = (rng.gamma(2.0, 0.5, (height, width, 4)) * 1e3).astype(np.float32)
            banded.add(image)
            delta = image[..., :3] - whole.mean  # the update of the whole arrays, as `add` did before bands
            whole.m2 += delta * delta * ((n - 1) / n)
            whole.mean += delta / n
            whole.n = n
        np.testing.assert_array_equal(banded.mean, whole.mean)
        np.testing.assert_array_equal(banded.m2, whole.m2)


def test_the_mean_image_of_a_run_with_moments_is_theirs_and_outlives_them():
    """A run that keeps pixel moments keeps no pixel sum: its mean image is n x the moments' mean (float32). Where
    the moments end (a pass without them) the sum goes on from there."""
    rng = np.random.default_rng(22)
    images = noisy(rng, 5).astype(np.float32)
    run = run_of(images[:3], range(3))
    np.testing.assert_allclose(run.pixel_sum, images[:3].sum(axis=0), rtol=1e-6, atol=1e-5)  # float32's rounding
    np.testing.assert_allclose(run.mean_image, images[:3].mean(axis=0), rtol=1e-6, atol=1e-5)
    assert run.pixel_sum.dtype == np.float32 and run.pixel_sum is run.pixel_sum  # made once per pass count
    chunk = run_of(images[3:4], [3])
    run.add_sums(chunk.sums, chunk.seeds, pixels=chunk.pixels)  # with moments: no pixel sum needed
    np.testing.assert_allclose(run.pixel_sum, images[:4].sum(axis=0), rtol=1e-6, atol=1e-5)
    plain = wc.TileStats(SIZE, SIZE, TILE, 3, CYCLES)
    plain.add_pass(images[4], 4)
    run.add_sums(plain.sums, plain.seeds, plain.pixel_sum)  # without: the moments end, the mean image stays
    assert run.pixels is None and run.n == 5
    np.testing.assert_allclose(run.pixel_sum, images.sum(axis=0), rtol=1e-6, atol=1e-5)
    with pytest.raises(wc.WelchInputError, match="`pixel_sum` is needed"):
        run.add_sums(plain.sums, [9])
    merged = run_of(images[:2], range(2)).merge(run_of(images[2:], range(2, 5)))
    np.testing.assert_allclose(merged.mean_image, images.mean(axis=0), rtol=1e-6, atol=1e-5)


def test_a_file_holds_the_mean_in_float32_and_its_pixel_test_is_the_runs(tmp_path):
    """The statistics file stores a pixel's mean in float32 (M2 in float64, exactly) and no pixel sum beside it.
    What the pixel test computes from float32 passes read back is the run's own to 1e-5 in t and p, also at a
    bright offset (1000 x the spread) where the mean's rounding is largest against the spread, and over 200 A/A
    comparisons through files the verdicts are those made in memory."""
    rng = np.random.default_rng(23)
    for offset in (0.0, 1e3):
        passes = [(noisy(rng, n) + offset).astype(np.float32) for n in (3, 4)]
        ref, test = run_of(passes[0], range(3)), run_of(passes[1], range(10, 14))
        wc.save_stats(tmp_path / "ref.npz", ref)
        wc.save_stats(tmp_path / "test.npz", test)
        with np.load(tmp_path / "ref.npz") as data:
            assert data["pixel_mean"].dtype == np.float32 and data["pixel_m2"].dtype == np.float64
            assert "pixel_sum" not in data.files
        back_ref, back_test = wc.load_stats(tmp_path / "ref.npz"), wc.load_stats(tmp_path / "test.npz")
        np.testing.assert_array_equal(back_ref.pixels.m2, ref.pixels.m2)
        np.testing.assert_allclose(back_ref.pixel_sum, ref.pixel_sum, rtol=1e-6)
        memory, files = pixel_welch(ref, test), pixel_welch(back_ref, back_test)
        np.testing.assert_allclose(files.statistic, memory.statistic, rtol=0, atol=1e-5)
        np.testing.assert_allclose(files.pvalue, memory.pvalue, rtol=0, atol=1e-5)
    verdicts = {"memory": [], "files": []}
    for _ in range(200):
        ref, test = (run_of(noisy(rng, 2).astype(np.float32), seeds) for seeds in (range(2), range(2, 4)))
        wc.save_stats(tmp_path / "ref.npz", ref)
        wc.save_stats(tmp_path / "test.npz", test)
        back = wc.load_stats(tmp_path / "ref.npz"), wc.load_stats(tmp_path / "test.npz")
        for name, (a, b) in (("memory", (ref, test)), ("files", back)):
            verdicts[name].append(wc.compare(a, b, 0.05, pixel_variance="auto").verdict.label)
    assert verdicts["files"] == verdicts["memory"]


# -- the statistic -------------------------------------------------------------------------------------------


def test_the_statistic_equals_a_direct_computation_with_scipy():
    rng = np.random.default_rng(7)
    a_images, b_images = noisy(rng, 3), noisy(rng, 5, shift=0.01)
    result = pixel_welch(run_of(a_images, range(3)), run_of(b_images, range(10, 15)))
    chosen = set()
    for r, c, ch in np.ndindex(result.statistic.shape):
        box = (slice(r * TILE, (r + 1) * TILE), slice(c * TILE, (c + 1) * TILE), ch)
        a, b = a_images[(slice(None), *box)], b_images[(slice(None), *box)]
        sa, sb = a.var(axis=0, ddof=1), b.var(axis=0, ddof=1)
        s_both = np.concatenate([a, b]).var(axis=0, ddof=1)  # (4): each pixel over both sides' passes
        separate, pooled = sa.sum() / 3 + sb.sum() / 5, s_both.sum() * (1 / 3 + 1 / 5)
        if separate >= pooled:
            se2, df = separate, separate**2 / ((sa**2).sum() / (9 * 2) + (sb**2).sum() / (25 * 4))
        else:
            se2, df = pooled, 7 * s_both.sum() ** 2 / (s_both**2).sum()
        chosen.add(separate >= pooled)
        t = (a.sum(axis=(1, 2)).mean() - b.sum(axis=(1, 2)).mean()) / np.sqrt(se2)
        assert result.statistic[r, c, ch] == pytest.approx(t, rel=1e-10)
        assert result.df[r, c, ch] == pytest.approx(df, rel=1e-10)
        assert result.pvalue[r, c, ch] == pytest.approx(2 * stats.t.sf(abs(t), df), rel=1e-8)
    assert chosen == {True, False}  # both branches of (4) are checked


def test_past_a_few_passes_the_separate_estimate_alone_keeps_a_real_differences_power():
    """A bias that moves light between a tile's pixels (blurring a highlight: up here, down there) adds each
    pixel's difference to the variance over both sides' passes; past `POOLED_UP_TO` passes a side (4) no longer
    applies, so more passes find more."""
    rng = np.random.default_rng(20)
    n = POOLED_UP_TO + 4
    ref, test = noisy(rng, n), noisy(rng, n)
    test[:, ::2] += 0.5  # every other row brighter, the next darker: the tile sums move by the odd rows alone
    test[:, 1::2] -= 0.45
    result = pixel_welch(run_of(ref, range(n)), run_of(test, range(100, 100 + n)))
    a, b = ref[:, :TILE, :TILE, 0], test[:, :TILE, :TILE, 0]
    se2 = a.var(axis=0, ddof=1).sum() / n + b.var(axis=0, ddof=1).sum() / n
    t = (a.sum(axis=(1, 2)).mean() - b.sum(axis=(1, 2)).mean()) / np.sqrt(se2)
    assert result.statistic[0, 0, 0] == pytest.approx(t, rel=1e-10)


def test_a_pixel_whose_passes_agree_on_each_side_does_not_fake_a_difference():
    """A two-valued pixel (a light hit or not) equal in both passes of each side, different between them, has no
    variance on either side: without (4) it alone made |t| = 62 on a rendered caustic."""
    images = np.ones((4, SIZE, SIZE, 3))
    images += np.random.default_rng(17).normal(0, 0.01, images.shape)
    images[2:, 5, 5] = 76.4  # the test side's two passes both hit it, the reference's none
    result = pixel_welch(run_of(images[:2], range(2)), run_of(images[2:], range(2, 4)))
    assert abs(result.statistic[0, 0, 0]) < 2 and result.df[0, 0, 0] < 4


def test_tile_channels_below_the_df_floor_keep_the_tile_test():
    rng = np.random.default_rng(8)
    images = 1 + rng.normal(0, 1, (4, SIZE, SIZE, 3))
    images[:, :TILE, :TILE] = 1.0
    images[0, 2, 3] = 500.0  # one firefly carries the tile: Satterthwaite's df collapses
    ref, test = run_of(images[:2], range(2)), run_of(images[2:], range(2, 4))
    tested = wc.tile_tests.test_tiles(ref, test, "welch", pixels=True)
    welch = wc.welch_from_stats(ref.mean, ref.variance, 2, test.mean, test.variance, 2)
    by_pixels = pixel_welch(ref, test)
    assert by_pixels.df[0, 0, 0] < MIN_PIXEL_DF and not tested.pixel[0, 0, 0]
    assert tested.result.pvalue[0, 0, 0] == welch.pvalue[0, 0, 0]
    assert tested.pixel[1:, 1:].all()
    np.testing.assert_array_equal(tested.result.pvalue[1:, 1:], by_pixels.pvalue[1:, 1:])


@pytest.mark.parametrize(("n_ref", "n_test"), [(2, 2), (3, 8)])
def test_pvalues_are_conservative_under_h0_with_unequal_pixel_variances(n_ref, n_test):
    """(4) takes the larger of two estimates, each unbiased under H0: the p-values are at least uniform in the
    tail the decisions use."""
    rng = np.random.default_rng(9 + n_ref)
    pvalues = []
    for _ in range(60):
        ref = run_of(1 + rng.normal(0, 1, (n_ref, SIZE, SIZE, 3)), range(n_ref))
        test = run_of(1 + rng.normal(0, 3, (n_test, SIZE, SIZE, 3)), range(100, 100 + n_test))
        pvalues.append(pixel_welch(ref, test).pvalue.ravel())
    pvalues = np.concatenate(pvalues)
    for level in (0.01, 0.05, 0.2):
        assert np.mean(pvalues <= level) <= level + 3 * np.sqrt(level / len(pvalues))
    assert np.mean(pvalues <= 0.2) > 0.05  # not a test that never rejects


def test_false_biased_rate_of_the_family_under_h0_is_within_its_bound():
    """`biased` rejects the intersection of every tile-channel's H0 at every scale: at alpha 0.05, 300 seeded A/A
    pairs of 2 v 2 skewed passes (the design the pixel test is for) say it at most at the binomial bound."""
    rng = np.random.default_rng(10)
    found = 0
    for _ in range(300):
        ref, test = run_of(noisy(rng, 2), range(2)), run_of(noisy(rng, 2), range(2, 4))
        found += wc.compare(ref, test, 0.05, pixel_variance="auto").verdict.label == "biased"
    assert found <= stats.binom.ppf(0.999, 300, 0.05)


def test_it_finds_at_two_passes_a_bias_the_tile_test_cannot():
    rng = np.random.default_rng(11)
    found = {"auto": 0, "off": 0}
    for _ in range(20):
        ref, test = run_of(noisy(rng, 2), range(2)), run_of(noisy(rng, 2, shift=0.08), range(2, 4))
        for mode in found:
            found[mode] += wc.compare(ref, test, 0.01, pixel_variance=mode).verdict.label == "biased"
    assert found == {"auto": 20, "off": 9}  # seeded: the tile test finds it in under half


def paired_runs(rng, n, shift=0.0):
    """Paired runs: the test's pass of a seed is the reference's plus independent zero-mean noise (and `shift`),
    with the moments of each pixel's difference."""
    ref_images = noisy(rng, n)
    test_images = ref_images + shift + 0.3 * (rng.gamma(2.0, 0.5, ref_images.shape) - 1.0)
    pairs = wc.PixelMoments.of_passes(test_images - ref_images)
    return run_of(ref_images, range(n)), run_of(test_images, range(n)), pairs, ref_images, test_images


def test_the_paired_statistic_equals_a_direct_computation_with_scipy():
    ref, test, pairs, ref_images, test_images = paired_runs(np.random.default_rng(15), 3)
    result = pixel_paired(wc.paired_test.paired_differences(ref, test, pairs))
    d = test_images - ref_images
    for r, c, ch in [(0, 0, 0), (2, 1, 2)]:
        box = d[:, r * TILE : (r + 1) * TILE, c * TILE : (c + 1) * TILE, ch]
        s2, about_zero = box.var(axis=0, ddof=1), (box**2).mean(axis=0)  # (4): the larger, about 0 with n df
        if about_zero.sum() > s2.sum():
            t, df = (
                box.sum(axis=(1, 2)).mean() / np.sqrt(about_zero.sum() / 3),
                3 * about_zero.sum() ** 2 / (about_zero**2).sum(),
            )
        else:
            t, df = box.sum(axis=(1, 2)).mean() / np.sqrt(s2.sum() / 3), 2 * s2.sum() ** 2 / (s2**2).sum()
        assert -result.statistic[r, c, ch] == pytest.approx(t, rel=1e-10)  # the sign of welch_ttest: ref - test
        assert result.df[r, c, ch] == pytest.approx(df, rel=1e-10)
        assert result.pvalue[r, c, ch] == pytest.approx(2 * stats.t.sf(abs(t), df), rel=1e-8)


def test_paired_runs_use_it_with_their_pairs_calibrated_and_with_power():
    rng = np.random.default_rng(16)
    false, found = 0, {"auto": 0, "off": 0}
    for _ in range(200):
        ref, test, pairs, *_ = paired_runs(rng, 2)
        c = wc.compare(ref, test, 0.05, pixel_variance="auto", pairs=pairs)
        assert c.test == "paired" and c.pixel_use.used
        false += c.verdict.label == "biased"
    assert false <= stats.binom.ppf(0.999, 200, 0.05)
    for _ in range(20):
        ref, test, pairs, *_ = paired_runs(rng, 2, shift=0.01)
        for mode in found:
            found[mode] += wc.compare(ref, test, 0.01, pixel_variance=mode, pairs=pairs).verdict.label == "biased"
    assert found["auto"] >= 18 and found["off"] <= found["auto"] // 2
    with pytest.raises(
        wc.WelchInputError, match=r"^`pairs` must be the moments of the 2 paired passes' differences, got 3$"
    ):
        wc.compare(ref, test, pairs=wc.PixelMoments.of_passes(np.zeros((3, SIZE, SIZE, 3))))


# -- where it is used ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"renderer": "my renderer", "scene_id": ""},
         "not Cycles passes rendered by this tool (vouch for the renderer with --pixel-variance on)"),
        ({"scene_id": "command:0123"},
         "not Cycles passes rendered by this tool (vouch for the renderer with --pixel-variance on)"),
        ({"renderer_version": "4.2.14"},
         "the sampling pattern TABULATED_SOBOL of Blender 4.2 is not measured independent"),
        ({"sampling_pattern": "SOBOL_BURLEY"},
         "the sampling pattern SOBOL_BURLEY of Blender 5.0 is not measured independent"),
        ({"settings": {**CYCLES.settings, "cycles.scrambling_distance": 0.1}},
         "cycles.scrambling_distance is 0.1 (pixels share samples below 1)"),
        ({"settings": {**CYCLES.settings, "cycles.auto_scrambling_distance": True}, "spp": 4},
         "cycles.auto_scrambling_distance is on (pixels share samples)"),
        ({"settings": {**CYCLES.settings, 'view_layers["ViewLayer"].cycles.use_denoising': True}},
         'view_layers["ViewLayer"].cycles.use_denoising is on'),
        ({"settings": {**CYCLES.settings, "cycles.use_adaptive_sampling": True}}, "cycles.use_adaptive_sampling is on"),
    ],
)  # fmt: skip
def test_the_record_must_prove_the_settings_it_was_measured_under(change, reason):
    assert pixel_eligibility(dataclasses.replace(CYCLES, **change)) == reason


def test_eligible_records():
    assert pixel_eligibility(CYCLES) is None
    one_spp = {"settings": {**CYCLES.settings, "cycles.auto_scrambling_distance": True}, "spp": 1}
    assert pixel_eligibility(dataclasses.replace(CYCLES, **one_spp)) is None  # changes nothing at 1 spp
    assert pixel_eligibility(dataclasses.replace(CYCLES, sampling_pattern="BLUE_NOISE")) is None
    for release, pattern in (("5.2.3", "AUTOMATIC"), ("4.5.4", "TABULATED_SOBOL"), ("3.4.1", "SOBOL")):
        assert (
            pixel_eligibility(dataclasses.replace(CYCLES, renderer_version=release, sampling_pattern=pattern)) is None
        )


def test_why_it_did_not_run_is_said():
    rng = np.random.default_rng(12)
    ref, test = run_of(noisy(rng, 3), range(3)), run_of(noisy(rng, 3), range(3, 6))
    assert wc.compare(ref, test, pixel_variance="off").pixel_use.reason == "off (--pixel-variance off)"
    same = run_of(noisy(rng, 3), range(3))
    assert wc.compare(ref, same).pixel_use is not None
    paired = wc.tile_test_of("paired")
    assert wc.pixel_use(ref, same, paired, "auto").reason == "the paired runs' per-seed pixel differences were not kept"
    plain = wc.TileStats.from_sums(test.sums, test.seeds, SIZE, SIZE, TILE, CYCLES)
    assert wc.pixel_use(ref, plain, wc.tile_test_of("welch"), "auto").reason == (
        "a run keeps no pixel moments (made before they were kept, or it kept a pass with non-finite pixels)"
    )
    other = run_of(noisy(rng, 3), range(3, 6), dataclasses.replace(CYCLES, renderer="mine", scene_id=""))
    use = wc.compare(ref, other, pixel_variance="auto").pixel_use
    assert not use.used and use.reason.startswith("the test: not Cycles passes")
    vouched = wc.compare(ref, other, pixel_variance="on").pixel_use
    assert vouched.used and vouched.reason == "vouched for (--pixel-variance on)" and vouched.share == 1.0


def test_the_tripwire_refuses_pixels_that_share_their_noise():
    """Pixels of a pass that share most of their noise (a low scrambling distance) make the tile sums vary far
    more than the pixel variances say: refused at 2 passes a side, whatever the user vouches."""
    rng = np.random.default_rng(13)

    def correlated(n):
        shared = rng.normal(0, 1, (n, 1, 1, 3))
        return 1 + shared + 0.1 * rng.normal(0, 1, (n, SIZE, SIZE, 3))

    ref, test = run_of(correlated(2), range(2)), run_of(correlated(2), range(2, 4))
    assert tripwire(ref, test).ratio > 10 * TRIPWIRE_RATIO
    use = wc.compare(ref, test, pixel_variance="on").pixel_use
    assert not use.used and use.reason.startswith("refused: the tile sums vary ")
    assert use.reason.endswith("x more than their pixels say (pixels correlated within a pass)")
    independent = run_of(noisy(rng, 2), range(10, 12)), run_of(noisy(rng, 2), range(12, 14))
    assert tripwire(*independent).ratio < TRIPWIRE_RATIO and tripwire(*independent).refusal() is None


def test_pixels_correlated_in_one_region_only_are_refused_by_the_local_tripwire():
    """A shift common to the pixels of one 16x16 tile per pass (pixel sd about 0.9, the shift's 1) left the median
    over the image's tile-channels at 1, so the tripwire passed and `compare --pixel-variance on` said `biased` at
    8 v 8 unbiased passes. Each tile-channel of every size now has a limit of its own (`local_limit`), which that
    tile exceeds about 18-fold; the tile test then finds nothing."""
    rng = np.random.default_rng(41)

    def shifted(n):
        images = noisy(rng, n)
        images[:, 16:32, 16:32] += rng.standard_normal(n)[:, None, None, None]
        return images

    ref, test = run_of(shifted(8), range(8)), run_of(shifted(8), range(8, 16))
    measured = tripwire(ref, test)
    assert measured.ratio < 1.1 and measured.local > 15
    assert measured.where == "the 16x16 tile at x 16, y 16, channel 2"
    assert measured.local_limit == pytest.approx(wc.pixels.local_limit(8, 2 * 3 * (16 + 4 + 1)))
    c = wc.compare(ref, test, pixel_variance="on")
    assert not c.pixel_use.used and c.verdict != wc.Verdict.BIASED
    assert c.pixel_use.reason == (
        "refused: the tile sums of the 16x16 tile at x 16, y 16, channel 2 vary 214x more than their pixels say, "
        "past the 11.7x independent pixels reach (pixels correlated within a pass there)"
    )
    independent = run_of(noisy(rng, 8), range(20, 28)), run_of(noisy(rng, 8), range(28, 36))
    assert tripwire(*independent).local < 0.5 and wc.compare(*independent, pixel_variance="on").pixel_use.used


def test_the_local_limit_holds_its_level_on_independent_pixels():
    """Under independent normal pixels some tile-channel of some size passes its limit before the margin in at most
    about `TRIPWIRE_ALPHA` of the comparisons (Bonferroni over the tile-channels): 900 comparisons of 2 v 2, 3 v 3 and
    8 v 8 passes of a 32x32 image in 8-px tiles (126 tile-channels): 1 beyond it (0.09 expected at most), none
    refused, the largest at 0.52 of the limit, the median's largest at 0.48 of its own."""
    from welch_core.pixels import LOCAL_MARGIN, TRIPWIRE_ALPHA

    rng = np.random.default_rng(42)
    local, median = [], []
    for n in (2, 3, 8):
        for _ in range(300):
            ref, test = (run_of(rng.normal(1.0, 0.3, (n, 32, 32, 3)), range(k, k + n), tile=8) for k in (0, 100))
            measured = tripwire(ref, test)
            local.append(measured.local)
            median.append(measured.ratio / measured.ratio_limit)
    assert (TRIPWIRE_ALPHA, LOCAL_MARGIN) == (1e-4, 2.0)
    assert sum(x * LOCAL_MARGIN > 1 for x in local) <= 2 and max(local) < 0.6 and max(median) < 0.6


def test_a_median_over_few_tiles_has_a_limit_of_its_own():
    """The median over a 32x32 image's four 16-px tiles (twelve tile-channels, whose channels share their noise)
    at 2 passes a side passed 3 in 9 of 100 A/A trials of the rendered diffuse corner: too few values for a median
    to be steady. Its limit is now the median's own upper `TRIPWIRE_ALPHA` point over that many tiles (9.7 for 8),
    and 3 where the tiles are many; of 400 such synthetic trials of a grey scene 20 passed 3, none the limit."""
    from welch_core.pixels import global_limit

    assert global_limit(2, 8) == pytest.approx(9.71, abs=0.01) and global_limit(3, 8) == pytest.approx(4.81, abs=0.01)
    assert global_limit(2, 512) == global_limit(8, 32) == TRIPWIRE_RATIO
    rng = np.random.default_rng(43)

    def grey(n):  # a grey scene: the channels of a pixel share their noise
        return np.repeat(noisy(rng, n, size=32)[..., :1], 3, axis=-1)

    above, refused = 0, 0
    for _ in range(400):
        ref, test = run_of(grey(2), range(2)), run_of(grey(2), range(2, 4))
        measured = tripwire(ref, test)
        assert measured.ratio_limit == pytest.approx(global_limit(2, 8))
        above += measured.ratio > TRIPWIRE_RATIO
        refused += measured.refusal() is not None
    assert above > 10 and refused == 0, (above, refused)


def test_moments_that_contradict_the_tile_sums_are_refused_not_tested():
    """Pixel M2s of zero beside tile sums that vary made the tripwire skip every tile-channel (its ratio NaN) and
    8 v 8 unbiased passes `biased`: tile sums of pixels that never vary can't vary, so the pixel test is refused,
    whether the moments are a side's own or a paired run's differences."""
    rng = np.random.default_rng(15)
    ref, test = run_of(noisy(rng, 8), range(8)), run_of(noisy(rng, 8), range(8, 16))
    assert wc.pixels.moment_conflict(test) is None
    zero = wc.PixelMoments.of(test.pixels.mean, np.zeros(test.pixels.shape), test.n)
    broken = wc.TileStats.from_sums(test.sums, test.seeds, SIZE, SIZE, TILE, CYCLES, pixels=zero)
    assert wc.pixels.moment_conflict(broken) == (
        "pixel_m2",
        "in 48 of 48 tile-channels the tile sums vary more than their pixels can",
    )
    for mode in ("on", "auto"):
        use = wc.compare(ref, broken, pixel_variance=mode).pixel_use
        assert not use.used and use.reason == (
            "refused: the test's pixel moments contradict its tile sums: in 48 of 48 tile-channels the tile sums "
            "vary more than their pixels can"
        )
    measured = tripwire(ref, broken)  # the tripwire alone, as for a paired run's differences
    assert measured.contradicted == 48 and measured.refusal() == (
        "refused: in 48 tile-channels the tile sums vary while their pixels do not (pixel moments that contradict "
        "the passes)"
    )


def test_the_looks_keep_the_pixel_df_and_say_what_they_used():
    rng = np.random.default_rng(14)
    ref, test = run_of(noisy(rng, 3), range(3)), run_of(noisy(rng, 3), range(3, 6))
    plan = wc.SequentialPlan(max_passes=16, pixel_variance="auto")
    look = wc.sequential_look(ref, test, plan, [3 / 16])
    assert look.pixel_use.used and look.pixel_use.share > 0.9
    tested = wc.tile_tests.test_tiles(ref, test, "welch", pixels=True)
    kept = wc.looks.conservative(tested, 3)
    np.testing.assert_array_equal(kept.result.df[tested.pixel], tested.result.df[tested.pixel])
    assert (kept.result.df[~tested.pixel & (tested.result.reason == 0)] == 2).all()
    with pytest.raises(wc.WelchInputError, match=r"^`pixel_variance` must be one of \('auto', 'on', 'off'\), got 'x'$"):
        wc.SequentialPlan(max_passes=16, pixel_variance="x")


def test_below_the_normality_checks_passes_a_tile_few_pixels_carry_is_not_trusted_on_its_tile_sums():
    """At 3 v 3 passes a tile-channel whose variance a few pixels carry (a caustic: the pixel test below
    `MIN_PIXEL_DF`) would fall back to Welch's t on its three skewed tile sums, which is not calibrated there: it is
    left out of the family until the normality of its tile sums can be checked (8 passes), then tested by them."""
    from welch_core.diagnostics import MIN_PASSES_FOR_NORMALITY
    from welch_core.pixels import MIN_PIXEL_DF

    rng = np.random.default_rng(33)
    ref, test = noisy(rng, MIN_PASSES_FOR_NORMALITY), noisy(rng, MIN_PASSES_FOR_NORMALITY)
    for images in (ref, test):  # tile (0, 0), red: flat but one pixel, which is bright in a few passes
        images[:, :TILE, :TILE, 0] = 1.0
    ref[:, 0, 0, 0] = [1, 51, 1, 1, 1, 51, 1, 1]
    test[:, 0, 0, 0] = [51, 51, 1, 1, 51, 1, 1, 1]  # 2 of the first 3 passes bright: Welch's t sees a difference
    a, b = run_of(ref[:3], range(3)), run_of(test[:3], range(10, 13))
    assert wc.pixels.pixel_welch(a, b).df[0, 0, 0] < MIN_PIXEL_DF
    few = wc.compare(a, b, pixel_variance="on").scales[0]
    assert not few.tested.pixel[0, 0, 0] and few.tested.result.reason[0, 0, 0] == wc.ttest.Reason.VALID
    assert not few.trusted[0, 0] and few.trusted.sum() == few.trusted.size - 1 and not few.used[0, 0]
    enough = wc.compare(run_of(ref, range(8)), run_of(test, range(10, 18)), pixel_variance="on").scales[0]
    assert enough.tested.checked and not enough.tested.pixel[0, 0, 0]
    assert enough.trusted[0, 0] == (not enough.tested.suspect[0, 0].any())  # the tile sums' own check decides


@pytest.mark.slow
def test_at_three_passes_a_side_the_rendered_caustic_is_calibrated():
    """1000 unbiased 3 v 3 splits of the glass caustic rendered by the tool (64², 1 spp, the pixel test on its
    record) at alpha 0.01: `biased` at most 1.5 alpha. Measured on a 400-pass pool: 37 of 4000 before tiles that
    few pixels carry were left out below 8 passes (all but one such a tile's Welch t on its tile sums), 4 of 4000
    after; on 2 v 2 and 4 v 4 2 and 1 of 2000."""
    from benchmarks.common.cache import DEFAULT_DIR
    from benchmarks.common.pools import PoolSpec, load_or_render

    pool = load_or_render(PoolSpec("corner_glass", (), 64, passes=200), DEFAULT_DIR)
    rng = np.random.default_rng(34)
    found = 0
    for _ in range(1000):
        perm = rng.permutation(pool.n)
        ref, test = pool.stats(np.sort(perm[:3]), TILE, True), pool.stats(np.sort(perm[3:6]), TILE, True)
        c = wc.compare(ref, test, 0.01, pixel_variance="auto")
        assert c.pixel_use.used
        found += c.verdict == wc.Verdict.BIASED
    assert found <= 15, found


def test_moments_whose_sum_overflows_are_finite_still():
    """The moments' check sums an array first (one pass where all is well): finite values whose sum overflows
    are finite still, and a NaN or a negative M2 beside them is named."""
    big = np.full((2, 3, 3), 1e308)
    assert wc.PixelMoments.of(big, big, 4).n == 4
    big[1, 2, 0] = np.nan
    with pytest.raises(wc.WelchInputError, match=r"`mean` must be finite, got nan \(pixel x 2, y 1, channel 0\)"):
        wc.PixelMoments.of(big, np.zeros_like(big), 4)
    m2 = np.zeros((2, 3, 3))
    m2[0, 1, 2] = -1e-300
    named = r"`m2` must be finite and >= 0, got -1e-300 \(pixel x 1, y 0, channel 2\)"
    with pytest.raises(wc.WelchInputError, match=named):
        wc.PixelMoments.of(np.zeros_like(m2), m2, 4)
