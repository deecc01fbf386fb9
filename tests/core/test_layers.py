"""The layers as a family of their own (`welch_core.compare_layers`), the one split of alpha (`bonferroni`) and the
reference's self-test (`welch_core.selftest`): the hypotheses each rejects and the family each controls."""

import numpy as np
import pytest

import welch_core as wc
from tests.helpers.synthetic import make_run, scene_means, tile_sum_samples

COMPONENTS = ("diffuse", "glossy", "emission")


def test_bonferroni_is_alpha_over_the_product_of_the_family_sizes():
    assert wc.bonferroni(0.01) == 0.01
    assert wc.bonferroni(0.01, 2, 3, 64) == pytest.approx(0.01 / 384, rel=1e-15)
    assert wc.bonferroni(0.01, 0) == 0.01  # an empty family leaves alpha whole
    assert wc.bonferroni_p(0.002, 2, 3) == pytest.approx(0.012)
    assert wc.bonferroni_p(0.4, 5) == 1.0
    np.testing.assert_allclose(wc.bonferroni_p([0.001, 0.3, np.nan], 2), [0.002, 0.6, np.nan])


def _layers(rng, n, seeds, shifts=None):
    """Three components that add up to the image, each a third of its light; `shifts` scales a component."""
    means = scene_means(3, 3) / 3
    parts = {name: tile_sum_samples(rng, n, means, (shifts or {}).get(name)) for name in COMPONENTS}
    image = make_run(sum(parts.values()), seeds)
    return image, {name: make_run(sums, seeds) for name, sums in parts.items()}


def test_each_layer_is_tested_at_alpha_over_the_lit_layers_and_a_dark_one_is_not_tested():
    rng = np.random.default_rng(3)
    (ref, ref_layers), (test, test_layers) = _layers(rng, 12, range(12)), _layers(rng, 12, range(12, 24))
    dark = make_run(np.zeros((12, 3, 3, 3)), range(12))
    ref_layers["volume"] = dark
    test_layers["volume"] = make_run(np.zeros((12, 3, 3, 3)), range(12, 24))
    image = wc.compare(ref, test, alpha=0.03)
    family = wc.compare_layers(image, ref, test, ref_layers, test_layers, COMPONENTS)
    assert family.alpha == pytest.approx(0.01)
    assert [layer.name for layer in family.layers] == [*COMPONENTS, "volume"]
    assert family.layers[-1].comparison is None and set(family.comparisons) == set(COMPONENTS)
    assert all(c.alpha == pytest.approx(0.01) for c in family.comparisons.values())
    assert all(layer.share == pytest.approx(1 / 3, abs=0.01) for layer in family.layers[:3])
    assert family.component_sum["reference"] < 1e-12 and family.component_sum["test"] < 1e-12


def test_a_biased_component_explains_a_biased_image_and_a_spread_difference_is_called_spread():
    rng = np.random.default_rng(5)
    ref, ref_layers = _layers(rng, 24, range(24))
    test, test_layers = _layers(rng, 24, range(24, 48), {"glossy": 1.5})
    image = wc.compare(ref, test)
    assert image.verdict == wc.Verdict.BIASED
    family = wc.compare_layers(image, ref, test, ref_layers, test_layers, COMPONENTS)
    assert family.explained_by == ("glossy",) and family.attribution == "components"
    # Every component 0.3 % brighter: the image (a third of the relative noise of each) finds it, no component
    # does on its own at alpha / 3.
    rng = np.random.default_rng(5)
    ref, ref_layers = _layers(rng, 100, range(100))
    test, test_layers = _layers(rng, 100, range(100, 200), dict.fromkeys(COMPONENTS, 1.003))
    image = wc.compare(ref, test)
    family = wc.compare_layers(image, ref, test, ref_layers, test_layers, COMPONENTS)
    assert image.verdict == wc.Verdict.BIASED
    assert family.explained_by == () and family.attribution == "spread"


def test_nothing_is_attributed_when_the_image_is_not_biased_unless_described_after_looks():
    rng = np.random.default_rng(7)
    ref, ref_layers = _layers(rng, 12, range(12))
    test, test_layers = _layers(rng, 12, range(12, 24))
    image = wc.compare(ref, test)
    assert image.verdict == wc.Verdict.NO_EVIDENCE
    assert wc.compare_layers(image, ref, test, ref_layers, test_layers, COMPONENTS).attribution is None
    described = wc.compare_layers(image, ref, test, ref_layers, test_layers, COMPONENTS, after_looks=True)
    assert described.after_looks and described.attribution is None  # nothing biased anywhere: nothing to say


def test_layers_only_one_run_has_are_named_and_a_missing_component_breaks_the_sum():
    rng = np.random.default_rng(9)
    ref, ref_layers = _layers(rng, 8, range(8))
    test, test_layers = _layers(rng, 8, range(8, 16))
    del test_layers["glossy"]
    family = wc.compare_layers(wc.compare(ref, test), ref, test, ref_layers, test_layers, COMPONENTS)
    assert family.untested == {"reference": ("glossy",), "test": ()}
    assert family.component_sum["test"] is None and family.component_sum["reference"] < 1e-12
    partial = {name: ref_layers[name] for name in ("diffuse", "emission")}
    error = wc.component_sum_error(ref.sums, [partial["diffuse"].sums, partial["emission"].sums])
    assert error > 0.1
    assert wc.compare_layers(wc.compare(ref, test), ref, test, {}, {}) is None


@pytest.mark.slow
def test_the_layer_family_calls_an_unbiased_layer_biased_at_most_alpha_of_the_time():
    """H0 for every layer (and the image): the chance that any layer is `biased` is at most alpha = 0.05 over
    400 seeded trials (the upper end of the 95 % interval of the rate above it would be a failure)."""
    rng = np.random.default_rng(11)
    hits = 0
    for _ in range(400):
        ref, ref_layers = _layers(rng, 6, range(6))
        test, test_layers = _layers(rng, 6, range(6, 12))
        family = wc.compare_layers(wc.compare(ref, test, 0.05), ref, test, ref_layers, test_layers, COMPONENTS)
        hits += any(c.verdict == wc.Verdict.BIASED for c in family.comparisons.values())
    assert hits / 400 <= 0.05 + 1.96 * np.sqrt(0.05 * 0.95 / 400), hits


def test_the_self_test_compares_alternate_passes_and_needs_four():
    rng = np.random.default_rng(13)
    ref = make_run(tile_sum_samples(rng, 8, scene_means(3, 3)), range(8))
    check = wc.selftest(ref, 0.02)
    assert check.n_ref == check.n_test == 4 and check.alpha == 0.02 and check.test == "welch"
    assert len(check.scales) == 1 and check.tile == ref.tile
    assert wc.selftest(make_run(tile_sum_samples(rng, 3, scene_means(3, 3)), range(3))) is None
