"""Exceptions raised for bad input. Each message is one line that names the parameter and the bad value."""

from __future__ import annotations

import numpy as np


class WelchInputError(ValueError):
    """An argument, an image or a file that the statistics can't use."""


class GridMismatchError(WelchInputError):
    """Two statistics whose tile grids (image size, tile size, channels) differ can't be compared or merged."""


class RunMismatchError(WelchInputError):
    """Two runs that are not one configuration (scene, renderer, device, spp, settings...) can't be merged."""


class SeedOverlapError(WelchInputError):
    """The seed lists of two runs don't fit the test: unpaired needs disjoint seeds, paired identical ones."""


class StatsFileError(WelchInputError):
    """A statistics file that is missing, truncated, foreign, inconsistent or of an unknown format version."""


def check_int(name: str, value, minimum: int = 1, maximum: int | None = None) -> int:
    """Return `value` as an int, or raise if it isn't an integer in [`minimum`, `maximum`]."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise WelchInputError(f"`{name}` must be an integer >= {minimum}, got {value!r}")
    if maximum is not None and value > maximum:
        raise WelchInputError(f"`{name}` must be an integer <= {maximum}, got {value!r}")
    return int(value)


def check_alpha(alpha) -> float:
    """Return `alpha` as a float in (0, 1), or raise."""
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float, np.floating)) or not 0.0 < alpha < 1.0:
        raise WelchInputError(f"`alpha` must be a number in (0, 1), got {alpha!r}")
    return float(alpha)
