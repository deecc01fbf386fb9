"""One rule for a pass with NaN or inf pixels, wherever passes come from (renders, EXR files)."""

from __future__ import annotations

import numpy as np

from ._siblings import welch_core as wc
from .job import ON_NAN


def add_pass(stats: wc.TileStats, image: np.ndarray, seed: int, on_nan: str, warn) -> bool:
    """Add `image` to `stats` under the `on_nan` policy; return False if it was skipped (after calling `warn`)."""
    if on_nan not in ON_NAN:
        raise wc.WelchInputError(f"`on_nan` must be one of {ON_NAN}, got {on_nan!r}")
    if on_nan == "skip" and not np.isfinite(image[..., : stats.channels]).all():
        bad = int((~np.isfinite(image[..., : stats.channels])).sum())
        warn(f"pass with seed {seed} has {bad} non-finite pixel values: skipped")
        return False
    stats.add_pass(image, seed, allow_nonfinite=on_nan == "keep")
    return True
