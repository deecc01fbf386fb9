"""Images of the result as numpy arrays (no plotting library): the p-value colour map of paper §4.4, upscaled
and blended over a tone-mapped render, and the p-value histogram counts.

Colours follow the paper: large p violet, small p yellow (viridis). Excluded tiles are grey in the map and left
transparent in overlays.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .errors import WelchInputError

__all__ = [
    "MAP_MODES",
    "colorize",
    "histogram",
    "map_values",
    "overlay",
    "pvalue_rgb",
    "tonemap",
    "upscale_tiles",
]

# matplotlib's viridis sampled at 17 evenly spaced points (linear interpolation between them is within 0.01).
_VIRIDIS = np.array(
    [
        (0.267004, 0.004874, 0.329415),
        (0.282327, 0.094955, 0.417331),
        (0.278826, 0.175490, 0.483397),
        (0.258965, 0.251537, 0.524736),
        (0.229739, 0.322361, 0.545706),
        (0.199430, 0.387607, 0.554642),
        (0.172719, 0.448791, 0.557885),
        (0.149039, 0.508051, 0.557250),
        (0.127568, 0.566949, 0.550556),
        (0.120638, 0.625828, 0.533488),
        (0.157851, 0.683765, 0.501686),
        (0.246070, 0.738910, 0.452024),
        (0.369214, 0.788888, 0.382914),
        (0.515992, 0.831158, 0.294279),
        (0.678489, 0.863742, 0.189503),
        (0.845561, 0.887322, 0.099702),
        (0.993248, 0.906157, 0.143936),
    ]
)

EXCLUDED_GREY = 0.5

#: "min": smallest p over channels (paper Fig. 7a); "channel": one channel (Fig. 7c-e); "sqrt": sqrt(p) for more
#: colour resolution at small p (Fig. 9); "log10": -log10(p) up to LOG10_TOP; "q": Benjamini-Hochberg q-values.
MAP_MODES = ("min", "channel", "sqrt", "log10", "q")

#: -log10(p) at which the "log10" map saturates (p = 1e-8).
LOG10_TOP = 8.0


def colorize(values: npt.ArrayLike) -> np.ndarray:
    """Map values in [0, 1] (0 = violet, 1 = yellow) to RGB; NaN becomes grey."""
    v = np.asarray(values, dtype=float)
    pos = np.clip(np.nan_to_num(v, nan=0.0), 0.0, 1.0) * (len(_VIRIDIS) - 1)
    lo = np.minimum(pos.astype(int), len(_VIRIDIS) - 2)
    frac = (pos - lo)[..., None]
    rgb = _VIRIDIS[lo] * (1.0 - frac) + _VIRIDIS[lo + 1] * frac
    rgb[np.isnan(v)] = EXCLUDED_GREY
    return rgb.astype(np.float32)


def map_values(
    pvalues: npt.ArrayLike, mode: str = "min", channel: int | None = None, qvalues=None
) -> np.ndarray:
    """Colour-map positions in [0, 1] per tile (NaN = excluded) from (tiles_y, tiles_x, channels) p-values."""
    if mode not in MAP_MODES:
        raise WelchInputError(f"`mode` must be one of {MAP_MODES}, got {mode!r}")
    p = np.asarray(pvalues, dtype=float)
    if mode == "q":
        if qvalues is None:
            raise WelchInputError("`qvalues` are needed for mode 'q'")
        return 1.0 - np.asarray(qvalues, dtype=float)
    if mode == "channel":
        if channel is None or not 0 <= channel < p.shape[-1]:
            raise WelchInputError(
                f"`channel` must be in 0..{p.shape[-1] - 1} for mode 'channel', got {channel!r}"
            )
        p = p[..., channel]
    else:
        with np.errstate(invalid="ignore"):
            p = np.where(
                np.isfinite(p).any(axis=-1), np.nanmin(np.where(np.isfinite(p), p, np.inf), axis=-1), np.nan
            )
    if mode == "sqrt":
        return 1.0 - np.sqrt(p)
    if mode == "log10":
        with np.errstate(divide="ignore"):
            return np.minimum(-np.log10(np.maximum(p, 1e-300)) / LOG10_TOP, 1.0)
    return 1.0 - p


def pvalue_rgb(comparison, mode: str = "min", channel: int | None = None) -> np.ndarray:
    """The colour map of a `Comparison` at tile resolution, (tiles_y, tiles_x, 3) float32."""
    return colorize(map_values(comparison.pvalues, mode, channel, comparison.qvalues))


def upscale_tiles(tiles: npt.ArrayLike, tile: int, height: int, width: int, fill: float = 0.0) -> np.ndarray:
    """Repeat each tile's value over its tile×tile pixels; the dropped edge (incomplete tiles) gets `fill`."""
    tiles = np.asarray(tiles)
    big = np.repeat(np.repeat(tiles, tile, axis=0), tile, axis=1)
    out = np.full((height, width, *tiles.shape[2:]), fill, dtype=tiles.dtype)
    out[: big.shape[0], : big.shape[1]] = big
    return out


def tonemap(image: npt.ArrayLike, key: float = 0.18) -> np.ndarray:
    """Display an HDR scene-linear image: exposure so the mean luminance is `key`, Reinhard, sRGB encoding."""
    img = np.nan_to_num(np.asarray(image, dtype=np.float64)[..., :3], nan=0.0, posinf=0.0, neginf=0.0)
    img = np.maximum(img, 0.0)
    luminance = img @ np.array([0.2126, 0.7152, 0.0722])
    mean = luminance.mean() if luminance.size else 0.0
    scaled = img * (key / mean) if mean > 0 else img
    mapped = scaled / (1.0 + scaled)
    srgb = np.where(mapped <= 0.0031308, 12.92 * mapped, 1.055 * mapped ** (1 / 2.4) - 0.055)
    return srgb.astype(np.float32)


def overlay(
    base_rgb: npt.ArrayLike, map_rgb: npt.ArrayLike, opacity: float, mask: npt.ArrayLike | None = None
):
    """Blend `map_rgb` over `base_rgb` with `opacity` in [0, 1]; where `mask` is False the base shows through."""
    if not 0.0 <= opacity <= 1.0:
        raise WelchInputError(f"`opacity` must be in [0, 1], got {opacity!r}")
    base, top = np.asarray(base_rgb, dtype=np.float32), np.asarray(map_rgb, dtype=np.float32)
    if base.shape != top.shape:
        raise WelchInputError(
            f"`base_rgb` and `map_rgb` must have the same shape, got {base.shape} and {top.shape}"
        )
    weight = np.full(base.shape[:2], opacity, dtype=np.float32)
    if mask is not None:
        weight = weight * np.asarray(mask, dtype=np.float32)
    return base + (top - base) * weight[..., None]


def histogram(pvalues: npt.ArrayLike, bins: int = 30) -> tuple[np.ndarray, np.ndarray, float]:
    """Counts of the finite p-values in `bins` equal bins over [0, 1] (paper: 30), the edges, and the count
    per bin expected if all p-values were uniform."""
    if isinstance(bins, bool) or not isinstance(bins, (int, np.integer)) or bins < 1:
        raise WelchInputError(f"`bins` must be a positive integer, got {bins!r}")
    p = np.asarray(pvalues, dtype=float)
    p = p[np.isfinite(p)]
    counts, edges = np.histogram(p, bins=bins, range=(0.0, 1.0))
    return counts, edges, p.size / bins
