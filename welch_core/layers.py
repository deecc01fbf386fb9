"""The layers of a render (light components, light groups) tested as a family of their own beside the image.

Hypotheses: for each layer l with light in either run, H0_l: the layer converges to the same image in both runs.
Each is tested as the image is (`compare`), at `bonferroni(alpha, L)` for the L lit layers, so the chance that any
unbiased layer is called `biased` is at most alpha (a union-intersection family over the layers, apart from the
image's own verdict). Which components are biased on their own says where the image's difference is
(`attribution`); the components must add up to the image in each run, or one is missing or counted twice.
After a check's looks the layers are tested once on the final passes: a description of where a difference is,
not a decision under the stopping rule.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .comparison import Comparison, compare
from .multitest import bonferroni
from .tiles import TileStats
from .verdict import Verdict

__all__ = ["SUM_TOLERANCE", "LayerFamily", "LayerResult", "compare_layers", "component_sum_error"]

#: Relative difference between the image and the sum of its components beyond which a component is missing or
#: counted twice (float32 passes agree to about 1e-7; a missing lobe is a visible share of the light).
SUM_TOLERANCE = 1e-4


@dataclass(frozen=True)
class LayerResult:
    """One layer: its comparison (None when neither run has light in it) and its share of the reference's
    light (None when the reference is black)."""

    name: str
    comparison: Comparison | None
    share: float | None


@dataclass(frozen=True)
class LayerFamily:
    """The layers both runs have, tested at `alpha` each (the family's share), and what they say together."""

    layers: tuple[LayerResult, ...]
    alpha: float
    after_looks: bool
    #: components found `biased` on their own
    explained_by: tuple[str, ...]
    #: where the image's difference is: "components" (in `explained_by`), "spread" (the image is biased and no
    #: component is on its own), or None (nothing to attribute)
    attribution: str | None
    #: per side ("reference", "test"): the relative error of the components' sum against the image, or None
    #: where the run lacks a component
    component_sum: dict[str, float | None]
    #: per side: the layers only that run has (not tested)
    untested: dict[str, tuple[str, ...]]

    @property
    def comparisons(self) -> dict[str, Comparison]:
        """Each tested layer's comparison, by name."""
        return {layer.name: layer.comparison for layer in self.layers if layer.comparison is not None}


def component_sum_error(combined: np.ndarray, components: list[np.ndarray]) -> float:
    """The largest relative difference, over tiles and channels, between the image's tile sums and the sum of the
    components' (arrays of per-pass tile sums of the same shape); 0 where they agree."""
    total = np.sum(components, axis=0)
    scale = np.maximum(np.abs(combined), np.abs(combined).mean() + 1e-30)
    return float(np.max(np.abs(total - combined) / scale))


def compare_layers(
    image: Comparison,
    ref: TileStats,
    test: TileStats,
    ref_layers: dict[str, TileStats],
    test_layers: dict[str, TileStats],
    components: tuple[str, ...] = (),
    after_looks: bool = False,
) -> LayerFamily | None:
    """Test every layer both runs have as `image` was tested (its test and p-value method), at alpha / L. The
    `components` (names of layers that add up to the image) attribute a difference and are checked to add up in
    each run. None when neither run has a layer."""
    names = [name for name in ref_layers if name in test_layers]
    # Layers only one run has: not tested, and said so (a light group renamed on one side, --lobes on one side).
    untested = {"reference": tuple(n for n in ref_layers if n not in test_layers),
                "test": tuple(n for n in test_layers if n not in ref_layers)}  # fmt: skip
    if not names and not any(untested.values()):
        return None
    lit = [n for n in names if np.any(ref_layers[n].sums) or np.any(test_layers[n].sums)]
    alpha = bonferroni(image.alpha, len(lit))
    total = float(ref.sums.sum())
    layers = []
    for name in names:
        tested = compare(ref_layers[name], test_layers[name], alpha, image.test, image.pvalue_method) if (
            name in lit) else None  # fmt: skip
        share = float(ref_layers[name].sums.sum() / total) if total and tested is not None else None
        layers.append(LayerResult(name, tested, share))
    biased = tuple(r.name for r in layers if r.comparison is not None and r.comparison.verdict == Verdict.BIASED
                   and r.name in components)  # fmt: skip
    sums = {}
    for side, run, own in (("reference", ref, ref_layers), ("test", test, test_layers)):
        complete = components and all(name in own for name in components)
        sums[side] = component_sum_error(run.sums, [own[n].sums for n in components]) if complete else None
    if image.verdict != Verdict.BIASED and not after_looks:
        attribution = None
    elif biased:
        attribution = "components"
    elif image.verdict == Verdict.BIASED:
        attribution = "spread"
    else:
        attribution = None
    return LayerFamily(tuple(layers), alpha, after_looks, biased, attribution, sums, untested)
