"""Statistics for detecting bias in Monte Carlo renderers with Welch's t-test.

After Jung, Hanika and Dachsbacher, "Detecting Bias in Monte Carlo Renderers using Welch's t-test", JCGT 9(2),
2020. Equation numbers in comments refer to that paper. numpy and scipy only; no bpy.
"""

from .colormap import MAP_MODES, colorize, histogram, map_values, overlay, pvalue_rgb, tonemap, upscale_tiles
from .compare import TESTS, Comparison, compare, info_differences, seed_relation
from .diagnostics import Normality, normality, split_halves
from .effect import Effect, effect_sizes
from .errors import GridMismatchError, SeedOverlapError, StatsFileError, WelchInputError
from .formats import load_stats, read_exr, read_pfm, save_stats, write_exr, write_pfm, write_tile_pfms
from .multitest import GlobalTest, bh_qvalues, combine_channels, global_test, holm, uniformity_pvalue
from .tiles import RunInfo, TileStats, tile_sums
from .ttest import (
    PVALUE_METHODS,
    Reason,
    TTestResult,
    paired_ttest,
    pvalue_as_erf,
    pvalue_exact,
    pvalue_gauss,
    two_sided_pvalue,
    welch_from_stats,
    welch_ttest,
)

__all__ = [
    "MAP_MODES",
    "PVALUE_METHODS",
    "TESTS",
    "Comparison",
    "Effect",
    "GlobalTest",
    "GridMismatchError",
    "Normality",
    "Reason",
    "RunInfo",
    "SeedOverlapError",
    "StatsFileError",
    "TTestResult",
    "TileStats",
    "WelchInputError",
    "bh_qvalues",
    "colorize",
    "combine_channels",
    "compare",
    "effect_sizes",
    "global_test",
    "histogram",
    "holm",
    "info_differences",
    "load_stats",
    "map_values",
    "normality",
    "overlay",
    "paired_ttest",
    "pvalue_as_erf",
    "pvalue_exact",
    "pvalue_gauss",
    "pvalue_rgb",
    "read_exr",
    "read_pfm",
    "save_stats",
    "seed_relation",
    "split_halves",
    "tile_sums",
    "tonemap",
    "two_sided_pvalue",
    "uniformity_pvalue",
    "upscale_tiles",
    "welch_from_stats",
    "welch_ttest",
    "write_exr",
    "write_pfm",
    "write_tile_pfms",
]
