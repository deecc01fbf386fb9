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
    "DIFFERENCE_PALETTE",
    "DIFFERENCE_STEPS",
    "MAP_MODES",
    "colorize",
    "difference_picture",
    "exposure",
    "histogram",
    "map_values",
    "overlay",
    "pvalue_rgb",
    "shrink",
    "tonemap",
    "upscale_tiles",
]

# matplotlib's viridis (its 256-entry table, interpolated linearly) sampled at 33 evenly spaced points: linear
# interpolation between them is within 0.0065 of it (17 points were up to 0.022 off near the yellow end).
_VIRIDIS = np.array(
    [
        (0.267004, 0.004874, 0.329415),
        (0.276987, 0.050151, 0.375542),
        (0.282302, 0.094624, 0.417024),
        (0.282902, 0.135449, 0.453035),
        (0.278919, 0.174879, 0.482972),
        (0.270788, 0.213324, 0.506643),
        (0.259266, 0.250672, 0.524378),
        (0.245374, 0.286704, 0.536971),
        (0.230223, 0.321297, 0.545488),
        (0.214836, 0.354470, 0.551027),
        (0.199995, 0.386377, 0.554533),
        (0.186132, 0.417256, 0.556682),
        (0.173302, 0.447386, 0.557850),
        (0.161265, 0.477036, 0.558125),
        (0.149668, 0.506440, 0.557329),
        (0.138415, 0.535767, 0.555090),
        (0.128148, 0.565107, 0.550893),
        (0.120875, 0.594465, 0.544158),
        (0.120325, 0.623765, 0.534308),
        (0.130961, 0.652859, 0.520817),
        (0.155378, 0.681539, 0.503240),
        (0.192974, 0.709556, 0.481231),
        (0.241467, 0.736626, 0.454543),
        (0.298636, 0.762445, 0.423019),
        (0.362859, 0.786695, 0.386589),
        (0.432985, 0.809056, 0.345271),
        (0.508094, 0.829231, 0.299221),
        (0.587266, 0.846982, 0.248871),
        (0.669358, 0.862217, 0.195444),
        (0.752867, 0.875089, 0.142650),
        (0.835913, 0.886110, 0.102462),
        (0.916550, 0.896130, 0.100822),
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


def difference_picture(reference: npt.ArrayLike, test: npt.ArrayLike, share: float = 0.95):
    """The signed per-pixel difference test - reference of two mean renders (channels averaged) as a palette
    image: H×W indices into `DIFFERENCE_PALETTE`'s diverging map (blue: test darker, white: equal, red: test
    brighter; `DIFFERENCE_STEPS` steps a side), and the difference its ends stand for, relative to the reference's
    mean brightness: the `share` quantile of |difference| (so a few fireflies don't wash the rest out), for the
    scale bar. (None, 0.0) where the images can't be compared. One byte a pixel, not three: the report's picture
    is a third of the size, and is made and coded in a fraction of the time."""
    ref, tst = (np.asarray(image, dtype=np.float32)[..., :3] for image in (reference, test))
    if ref.shape != tst.shape:
        return None, 0.0
    ref, tst = (_channel_mean(image) for image in (ref, tst))
    diff = tst - ref
    diff[~np.isfinite(diff)] = 0.0
    limit = float(np.quantile(np.abs(diff), share)) if diff.size else 0.0
    finite = np.isfinite(ref)
    brightness = float(np.mean(np.abs(ref[finite]))) if finite.any() else 0.0
    if limit > 0:
        diff *= DIFFERENCE_STEPS / limit  # on the map's scale, in steps
        np.clip(diff, -DIFFERENCE_STEPS, DIFFERENCE_STEPS, out=diff)
        diff += DIFFERENCE_STEPS
        levels = np.rint(diff, out=diff).astype(np.uint8)
    else:
        levels = np.full(diff.shape, DIFFERENCE_STEPS, np.uint8)
    return levels, (limit / brightness if brightness > 0 else 0.0)


def _channel_mean(image: np.ndarray) -> np.ndarray:
    """The mean of an H×W×3 image's channels in float64 (channel by channel: 4x a sum over the short last axis)."""
    return (image[..., 0].astype(np.float64) + image[..., 1] + image[..., 2]) / 3.0


#: The difference map's steps a side of white: index DIFFERENCE_STEPS is white (equal), 0 and 2 x DIFFERENCE_STEPS
#: its ends.
DIFFERENCE_STEPS = 127


def _difference_palette() -> np.ndarray:
    brighter, darker = np.array([0.7, 0.1, 0.1], np.float32), np.array([0.1, 0.25, 0.7], np.float32)
    step = np.arange(-DIFFERENCE_STEPS, DIFFERENCE_STEPS + 1, dtype=np.float32)[:, None] / DIFFERENCE_STEPS
    return 1.0 + np.where(step > 0, brighter - 1.0, darker - 1.0) * np.abs(step)  # white to the map's ends


#: The difference map's colours, (2 x DIFFERENCE_STEPS + 1, 3) float32: red where the test is brighter, blue where
#: it is darker, white where they are equal.
DIFFERENCE_PALETTE = _difference_palette()


def map_values(pvalues: npt.ArrayLike, mode: str = "min", channel: int | None = None, qvalues=None) -> np.ndarray:
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
            raise WelchInputError(f"`channel` must be in 0..{p.shape[-1] - 1} for mode 'channel', got {channel!r}")
        p = p[..., channel]
    else:
        with np.errstate(invalid="ignore"):
            p = np.where(np.isfinite(p).any(axis=-1), np.nanmin(np.where(np.isfinite(p), p, np.inf), axis=-1), np.nan)
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
    """Repeat each tile's value over its tile×tile pixels (partial edge tiles over the pixels they have); pixels no
    tile covers (the dropped edge of a file written before partial tiles) get `fill`."""
    tiles = np.asarray(tiles)
    big = np.repeat(np.repeat(tiles, tile, axis=0), tile, axis=1)[:height, :width]
    out = np.full((height, width, *tiles.shape[2:]), fill, dtype=tiles.dtype)
    out[: big.shape[0], : big.shape[1]] = big
    return out


def exposure(image: npt.ArrayLike, key: float = 0.18) -> float:
    """The scale that brings the mean luminance of a scene-linear image to `key` (1 for a black image)."""
    img = _displayable(image)
    mean = float((img @ np.array([0.2126, 0.7152, 0.0722], np.float32)).mean()) if img.size else 0.0
    return key / mean if mean > 0 else 1.0


def _displayable(image: npt.ArrayLike) -> np.ndarray:
    """RGB as float32 with negative, NaN and infinite values as 0 (a new array)."""
    img = np.fmax(np.asarray(image, dtype=np.float32)[..., :3], np.float32(0.0))  # fmax: NaN becomes 0 too
    img[img == np.inf] = 0.0
    return img


def tonemap(image: npt.ArrayLike, key: float = 0.18, scale: float | None = None) -> np.ndarray:
    """Display an HDR scene-linear image: exposure so the mean luminance is `key` (or the given `scale`, so that
    two images compare in brightness), Reinhard, sRGB encoding."""
    img = _displayable(image)
    img *= np.float32(exposure(img, key) if scale is None else scale)
    img /= np.float32(1.0) + img  # Reinhard
    # sRGB encoding in place: the power on every value, the linear segment where it applies.
    dark = img <= np.float32(0.0031308)
    linear = img[dark] * np.float32(12.92)
    # x ** (1 / 2.4) as exp(log(x) / 2.4): numpy's float32 power has no vector loop (3x slower); within 2 ulp
    with np.errstate(divide="ignore"):  # log(0): exp(-inf) is 0, and dark pixels are replaced below anyway
        np.log(img, out=img)
    img *= np.float32(1 / 2.4)
    np.exp(img, out=img)
    img *= np.float32(1.055)
    img -= np.float32(0.055)
    img[dark] = linear
    return img


def shrink(image: npt.ArrayLike, max_side: int) -> np.ndarray:
    """Block means that bring the longer side to at most `max_side` (an integer factor; the edge that does not
    fill a block is dropped): a picture for a report, not for measurement."""
    img = np.asarray(image)
    factor = -(-max(img.shape[:2]) // max_side)
    if factor <= 1:
        return img
    h, w = img.shape[0] // factor * factor, img.shape[1] // factor * factor
    # Rows first, then columns, each as `factor` strided slices added in turn: near memory speed, unlike a mean
    # over two axes (and 3x faster than sums over a reshaped axis of `factor`).
    rows = img[0:h:factor].astype(np.float32)
    for k in range(1, factor):
        rows += img[k:h:factor]
    blocks = rows[:, 0:w:factor].copy()
    for k in range(1, factor):
        blocks += rows[:, k:w:factor]
    return blocks / np.float32(factor * factor)


def overlay(base_rgb: npt.ArrayLike, map_rgb: npt.ArrayLike, opacity: float, mask: npt.ArrayLike | None = None):
    """Blend `map_rgb` over `base_rgb` with `opacity` in [0, 1]; where `mask` is False the base shows through."""
    if not 0.0 <= opacity <= 1.0:
        raise WelchInputError(f"`opacity` must be in [0, 1], got {opacity!r}")
    base, top = np.asarray(base_rgb, dtype=np.float32), np.asarray(map_rgb, dtype=np.float32)
    if base.shape != top.shape:
        raise WelchInputError(f"`base_rgb` and `map_rgb` must have the same shape, got {base.shape} and {top.shape}")
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
