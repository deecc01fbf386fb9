"""Welch samples from render passes: per-tile sums, accumulated per tile and colour channel (paper §4.1–4.2).

A *pass* is one independent render of the image (its own seed), an H×W×C float array, top row first. The Welch
sample of a tile is the sum of the pass's pixel values over the tile (§4.1: one MC sample per pixel, summed; the
constant 1/tile² normalisation is skipped as in the paper). Incomplete tiles at the right and bottom edges are
dropped.

`TileStats` keeps, per tile and channel, the count, the mean and the second moment about the mean (Welford's update,
Chan's merge: exact to rounding in float64, no sum-of-squares cancellation) and also every pass's tile sums: the
paired test, the normality diagnostics, re-tiling and subsetting need them, and they are small (1080p at 32×32
tiles is 2040×3 numbers a pass).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from .errors import GridMismatchError, WelchInputError, check_int

__all__ = ["RunInfo", "TileStats", "tile_sums"]


@dataclass(frozen=True)
class RunInfo:
    """What produced the passes: travels with the statistics so `compare` can say what differs."""

    spp: int = 1
    renderer: str = "unknown"
    renderer_version: str = ""
    device: str = ""
    sampling_pattern: str = ""
    scene: str = ""
    settings: dict[str, Any] = field(default_factory=dict)
    settings_hash: str = ""
    overrides: tuple[str, ...] = ()

    def __post_init__(self):
        check_int("spp", self.spp)
        object.__setattr__(self, "overrides", tuple(self.overrides))

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self) | {"overrides": list(self.overrides)}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunInfo:
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in known})


def tile_sums(image: npt.ArrayLike, tile: int, channels: int = 3) -> np.ndarray:
    """Sum an H×W×C image over complete `tile`×`tile` blocks: the Welch samples of one pass (§4.1).

    Returns a float64 array of shape (H // tile, W // tile, channels). Extra channels (alpha) are ignored.
    """
    tile, channels = check_int("tile", tile), check_int("channels", channels)
    image = _check_image(image, channels)
    if tile > min(image.shape[:2]):
        raise WelchInputError(f"`tile` must not exceed the image size {image.shape[1]}x{image.shape[0]}, got {tile}")
    ty, tx = image.shape[0] // tile, image.shape[1] // tile
    width = image.shape[1]
    rows = image[: ty * tile].reshape(ty, tile, width * image.shape[2])
    # Sum the tile's rows first with a contiguous inner axis (near memory speed), then the columns in float64.
    # For float32 input the row partial sums of `tile` values stay in float32: their rounding error (~1e-7
    # relative, measured) is far below the pass-to-pass spread of a tile sum and has no systematic sign.
    row_sums = rows.sum(axis=1)
    row_sums = row_sums.reshape(ty, width, image.shape[2])[:, : tx * tile, :channels]
    return row_sums.reshape(ty, tx, tile, channels).sum(axis=2, dtype=np.float64)


def _check_image(image, channels: int) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise WelchInputError(f"`image` must be a numpy array, got {type(image).__name__}")
    if image.ndim != 3:
        raise WelchInputError(f"`image` must have shape (height, width, channels), got shape {image.shape}")
    if not np.issubdtype(image.dtype, np.floating):
        raise WelchInputError(f"`image` must hold floating-point values, got dtype {image.dtype}")
    if image.shape[2] < channels:
        raise WelchInputError(f"`image` must have at least {channels} channels, got {image.shape[2]}")
    return np.ascontiguousarray(image)


class TileStats:
    """Per-tile, per-channel statistics of the Welch samples of one run (one renderer and setting, many seeds).

    Parameters
    ----------
    height, width : int
        Image size in pixels.
    tile : int
        Tile edge in pixels (the paper uses 32).
    channels : int
        Colour channels tested (3: alpha is dropped).
    info : RunInfo
        What produced the passes.
    keep_mean_image : bool
        Also keep the per-pixel mean image (for display over the p-value map).
    """

    def __init__(
        self,
        height: int,
        width: int,
        tile: int = 32,
        channels: int = 3,
        info: RunInfo | None = None,
        keep_mean_image: bool = True,
    ):
        self.height = check_int("height", height)
        self.width = check_int("width", width)
        self.tile = check_int("tile", tile)
        self.channels = check_int("channels", channels)
        if self.tile > min(self.height, self.width):
            raise WelchInputError(f"`tile` must not exceed the image size {self.width}x{self.height}, got {self.tile}")
        self.info = info if info is not None else RunInfo()
        shape = self.grid_shape
        self.count = 0
        self.mean = np.zeros(shape)
        self.m2 = np.zeros(shape)
        self.seeds: list[int] = []
        self._sums: list[np.ndarray] = []  # one (tiles_y, tiles_x, channels) array per pass
        self._stacked: np.ndarray | None = None
        # float32 is enough for an image that is only displayed, and keeps add_pass near memory speed.
        self._pixel_sum = np.zeros((self.height, self.width, self.channels), np.float32) if keep_mean_image else None

    # -- shape of the grid ---------------------------------------------------------------------------------

    @property
    def tiles_y(self) -> int:
        return self.height // self.tile

    @property
    def tiles_x(self) -> int:
        return self.width // self.tile

    @property
    def grid_shape(self) -> tuple[int, int, int]:
        return (self.tiles_y, self.tiles_x, self.channels)

    @property
    def dropped_pixels(self) -> int:
        """Pixels in the incomplete right and bottom tiles, which are not tested."""
        return self.height * self.width - self.tiles_y * self.tiles_x * self.tile**2

    @property
    def n(self) -> int:
        return self.count

    @property
    def sums(self) -> np.ndarray:
        """Every pass's tile sums, shape (n, tiles_y, tiles_x, channels), in the order of `seeds`."""
        if self._stacked is None or len(self._stacked) != len(self._sums):
            self._stacked = np.stack(self._sums) if self._sums else np.empty((0, *self.grid_shape))
        return self._stacked

    @property
    def variance(self) -> np.ndarray:
        """Unbiased sample variance of the Welch samples (NaN where n < 2)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.m2 / (self.count - 1) if self.count > 1 else np.full(self.grid_shape, np.nan)

    @property
    def mean_image(self) -> np.ndarray | None:
        """Per-pixel mean over the passes (H×W×channels float32, top row first), if kept."""
        if self._pixel_sum is None or self.count == 0:
            return None
        return self._pixel_sum[..., : self.channels] / np.float32(self.count)

    def same_grid(self, other: TileStats) -> None:
        """Raise GridMismatchError unless `other` has the same image size, tile size and channels."""
        mine = (self.width, self.height, self.tile, self.channels)
        theirs = (other.width, other.height, other.tile, other.channels)
        if mine != theirs:
            raise GridMismatchError(
                f"statistics have different grids (width, height, tile, channels): {mine} against {theirs}"
            )

    # -- accumulation --------------------------------------------------------------------------------------

    def add_pass(self, image: npt.ArrayLike, seed: int, allow_nonfinite: bool = False) -> None:
        """Add one pass rendered with `seed`. A rejected pass leaves the statistics unchanged.

        Non-finite pixel values raise unless `allow_nonfinite`; then the affected tiles carry NaN/inf and are
        excluded from the test with the reason ``non_finite`` (never turned into a p-value).
        """
        seed = self._check_new_seeds([seed])[0]
        image = _check_image(image, self.channels)
        if image.shape[:2] != (self.height, self.width):
            raise WelchInputError(
                f"`image` must be {self.height}x{self.width} (height x width) like the run, "
                f"got {image.shape[0]}x{image.shape[1]}"
            )
        sums = tile_sums(image, self.tile, self.channels)
        if not allow_nonfinite and not np.isfinite(sums).all():
            bad = int((~np.isfinite(image[..., : self.channels])).sum())
            raise WelchInputError(f"pass with seed {seed} has {bad} non-finite pixel values")
        # Welford's update of mean and M2 (the second moment about the mean), in float64.
        self.count += 1
        with np.errstate(invalid="ignore"):
            delta = sums - self.mean
            self.mean += delta / self.count
            self.m2 += delta * (sums - self.mean)
        self.seeds.append(seed)
        self._sums.append(sums)
        if self._pixel_sum is not None:
            if self.count == 1 and self._pixel_sum.shape != image.shape:
                # Sum all of the pass's channels (alpha too): a contiguous add is 5x faster than a strided one.
                self._pixel_sum = np.zeros(image.shape, np.float32)
            if self._pixel_sum.shape == image.shape:
                np.add(self._pixel_sum, image, out=self._pixel_sum)
            else:
                self._pixel_sum[..., : self.channels] += image[..., : self.channels]

    def merge(self, other: TileStats) -> TileStats:
        """Return the statistics of both runs together (Chan et al.'s parallel merge); neither input changes.

        Runs merge when they share the grid, spp and scene settings and have disjoint seeds.
        """
        self.same_grid(other)
        if self.info.spp != other.info.spp:
            raise WelchInputError(f"can't merge runs of different spp: {self.info.spp} and {other.info.spp}")
        if self.info.settings_hash and other.info.settings_hash and self.info.settings_hash != other.info.settings_hash:
            raise WelchInputError("can't merge runs whose scene settings differ (settings_hash)")
        self._check_new_seeds(other.seeds)
        merged = self._empty_like(keep_mean_image=self._pixel_sum is not None and other._pixel_sum is not None)
        na, nb = self.count, other.count
        n = na + nb
        merged.count = n
        if n:
            with np.errstate(invalid="ignore"):
                delta = other.mean - self.mean
                merged.mean = self.mean + delta * (nb / n)
                merged.m2 = self.m2 + other.m2 + delta**2 * (na * nb / n)
        merged.seeds = self.seeds + other.seeds
        merged._sums = self._sums + other._sums
        if merged._pixel_sum is not None:
            channels = slice(0, self.channels)
            merged._pixel_sum = self._pixel_sum[..., channels] + other._pixel_sum[..., channels]
        return merged

    # -- derived runs --------------------------------------------------------------------------------------

    def subset(self, indices: npt.ArrayLike) -> TileStats:
        """The statistics of the passes at `indices` (positions in `seeds`); the mean image is not kept."""
        indices = np.asarray(indices, dtype=np.intp)
        if len(np.unique(indices)) != len(indices) or (
            len(indices) and not 0 <= indices.min() <= indices.max() < self.count
        ):
            raise WelchInputError(f"`indices` must be distinct positions in 0..{self.count - 1}")
        return TileStats.from_sums(
            self.sums[indices],
            [self.seeds[i] for i in indices],
            self.height,
            self.width,
            self.tile,
            self.info,
        )

    def retile(self, factor: int) -> TileStats:
        """The statistics at tile size `tile * factor`, from the stored per-pass sums (no re-rendering)."""
        factor = check_int("factor", factor)
        tile = self.tile * factor
        if tile > min(self.height, self.width):
            raise WelchInputError(f"`factor` {factor} makes tiles larger than the image")
        ty, tx = self.height // tile, self.width // tile
        sums = self.sums[:, : ty * factor, : tx * factor]
        sums = sums.reshape(self.count, ty, factor, tx, factor, self.channels).sum(axis=(2, 4))
        return TileStats.from_sums(sums, self.seeds, self.height, self.width, tile, self.info)

    @classmethod
    def from_sums(
        cls, sums: np.ndarray, seeds, height: int, width: int, tile: int, info: RunInfo | None = None
    ) -> TileStats:
        """Statistics built from per-pass tile sums of shape (n, tiles_y, tiles_x, channels)."""
        sums = np.asarray(sums, dtype=np.float64)
        out = cls(height, width, tile, sums.shape[-1], info, keep_mean_image=False)
        if sums.shape[1:] != out.grid_shape or len(sums) != len(seeds):
            raise WelchInputError(f"`sums` must have shape (n_seeds, {out.grid_shape}), got {sums.shape}")
        out.seeds = out._check_new_seeds(seeds)
        out.count = len(out.seeds)
        out._sums = list(sums)
        out._stacked = sums
        if out.count:
            # Two-pass moments from the stored sums, shifted by the first pass: as exact as the streaming update,
            # and a constant tile gets exactly its value and m2 = 0 (an unshifted mean can be off by an ulp).
            shifted = sums - sums[0]
            offset = shifted.mean(axis=0)
            out.mean = sums[0] + offset
            out.m2 = ((shifted - offset) ** 2).sum(axis=0)
        return out

    def _empty_like(self, keep_mean_image: bool) -> TileStats:
        return TileStats(self.height, self.width, self.tile, self.channels, self.info, keep_mean_image)

    def _check_new_seeds(self, seeds) -> list[int]:
        checked = []
        for seed in seeds:
            if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
                raise WelchInputError(f"`seed` must be an integer, got {seed!r}")
            checked.append(int(seed))
        repeated = sorted(set(checked) & set(self.seeds)) or sorted(s for s in set(checked) if checked.count(s) > 1)
        if repeated:
            raise WelchInputError(f"seed {repeated[0]} is already in this run: passes must have distinct seeds")
        return checked

    def __repr__(self) -> str:
        return (
            f"TileStats({self.width}x{self.height}, tile={self.tile}, grid={self.tiles_x}x{self.tiles_y}, "
            f"n={self.count}, spp={self.info.spp}, renderer={self.info.renderer!r})"
        )
