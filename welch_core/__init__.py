"""Statistics for detecting bias in Monte Carlo renderers with Welch's t-test.

After Jung, Hanika and Dachsbacher, "Detecting Bias in Monte Carlo Renderers using Welch's t-test", JCGT 9(2),
2020. Equation numbers in comments refer to that paper. numpy and scipy only; no bpy.

Names are imported on first use (PEP 562), so code that only accumulates passes (``welch_core.tiles``,
``welch_core.formats``: numpy alone, as inside a stock Blender) never imports scipy, and a command that only
reads a file starts fast; the imports under TYPE_CHECKING show an editor where each name is defined.
"""

# ruff: noqa: F401 (the imports under TYPE_CHECKING are there for editors, not used here)
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

#: Public name -> the submodule that defines it.
_EXPORTS = {
    "MAP_MODES": "colormap",
    "colorize": "colormap",
    "difference_picture": "colormap",
    "exposure": "colormap",
    "shrink": "colormap",
    "histogram": "colormap",
    "map_values": "colormap",
    "overlay": "colormap",
    "pvalue_rgb": "colormap",
    "tonemap": "colormap",
    "upscale_tiles": "colormap",
    "Comparison": "comparison",
    "compare": "comparison",
    "selftest": "comparison",
    "Difference": "decision",
    "Outcome": "decision",
    "ScaleResult": "decision",
    "identical_passes": "decision",
    "Look": "looks",
    "information_fraction": "looks",
    "SequentialPlan": "looks",
    "look_schedule": "looks",
    "sequential_look": "looks",
    "boundaries": "sequential",
    "nominal_levels": "sequential",
    "Normality": "diagnostics",
    "normality": "diagnostics",
    "split_halves": "diagnostics",
    "Effect": "effect",
    "effect_sizes": "effect",
    "GridMismatchError": "errors",
    "RunMismatchError": "errors",
    "SeedOverlapError": "errors",
    "StatsFileError": "errors",
    "WelchInputError": "errors",
    "LayerFamily": "layers",
    "LayerResult": "layers",
    "compare_layers": "layers",
    "component_sum_error": "layers",
    "read_exr": "exr",
    "read_exr_channels": "exr",
    "read_exr_colour": "exr",
    "write_exr": "exr",
    "load_layers": "formats",
    "load_preview": "formats",
    "load_stats": "formats",
    "save_stats": "formats",
    "GlobalTest": "multitest",
    "bh_qvalues": "multitest",
    "bonferroni": "multitest",
    "bonferroni_p": "multitest",
    "combine_channels": "multitest",
    "global_test": "multitest",
    "holm": "multitest",
    "uniformity_pvalue": "multitest",
    "PIXEL_MODES": "pixels",
    "PixelMoments": "pixels",
    "PixelUse": "pixels",
    "pixel_eligibility": "pixels",
    "pixel_use": "pixels",
    "TileTest": "tile_test",
    "TileTestMethod": "tile_test",
    "TESTS": "tile_tests",
    "TILE_TESTS": "tile_tests",
    "TileTestKind": "tile_tests",
    "seed_relation": "tile_tests",
    "tile_test_of": "tile_tests",
    "RunInfo": "tiles",
    "TileStats": "tiles",
    "tile_sums": "tiles",
    "PVALUE_METHODS": "ttest",
    "Reason": "ttest",
    "TTestResult": "ttest",
    "paired_from_stats": "ttest",
    "paired_ttest": "ttest",
    "pvalue_as_erf": "ttest",
    "pvalue_exact": "ttest",
    "pvalue_gauss": "ttest",
    "two_sided_pvalue": "ttest",
    "welch_from_stats": "ttest",
    "welch_ttest": "ttest",
    "Verdict": "verdict",
    "VerdictReason": "verdict",
}

if TYPE_CHECKING:  # each name where it is defined, for editors and type checkers (at run time: `__getattr__`)
    from .colormap import (
        MAP_MODES,
        colorize,
        difference_picture,
        exposure,
        histogram,
        map_values,
        overlay,
        pvalue_rgb,
        shrink,
        tonemap,
        upscale_tiles,
    )
    from .comparison import Comparison, compare, selftest
    from .decision import Difference, Outcome, ScaleResult, identical_passes
    from .diagnostics import Normality, normality, split_halves
    from .effect import Effect, effect_sizes
    from .errors import GridMismatchError, RunMismatchError, SeedOverlapError, StatsFileError, WelchInputError
    from .exr import read_exr, read_exr_channels, read_exr_colour, write_exr
    from .formats import load_layers, load_preview, load_stats, save_stats
    from .layers import LayerFamily, LayerResult, compare_layers, component_sum_error
    from .looks import Look, SequentialPlan, information_fraction, look_schedule, sequential_look
    from .multitest import (
        GlobalTest,
        bh_qvalues,
        bonferroni,
        bonferroni_p,
        combine_channels,
        global_test,
        holm,
        uniformity_pvalue,
    )
    from .pixels import PIXEL_MODES, PixelMoments, PixelUse, pixel_eligibility, pixel_use
    from .sequential import boundaries, nominal_levels
    from .tile_test import TileTest, TileTestMethod
    from .tile_tests import TESTS, TILE_TESTS, TileTestKind, seed_relation, tile_test_of
    from .tiles import RunInfo, TileStats, tile_sums
    from .ttest import (
        PVALUE_METHODS,
        Reason,
        TTestResult,
        paired_from_stats,
        paired_ttest,
        pvalue_as_erf,
        pvalue_exact,
        pvalue_gauss,
        two_sided_pvalue,
        welch_from_stats,
        welch_ttest,
    )
    from .verdict import Verdict, VerdictReason

_SUBMODULES = frozenset(_EXPORTS.values()) | {"paired_test", "parallel", "png", "sequential", "welch_test"}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(__all__) | _SUBMODULES)
