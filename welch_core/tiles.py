"""Welch samples from render passes: per-tile sums, kept per pass, per tile and colour channel (paper §4.1–4.2).

A *pass* is one independent render of the image (its own seed), an H×W×C float array, top row first. The Welch
sample of a tile is the sum of the pass's pixel values over the tile (§4.1: one MC sample per pixel, summed; the
constant 1/tile² normalisation is skipped as in the paper). Where the tile does not divide the image, the tiles at
the right and bottom edges are partial (the paper drops them, §4.1): a partial tile's sum is as good a Welch sample
as any, and dropping it would leave a strip of the image untested without a word. Runs of files written before
partial tiles (``edges="dropped"``) keep their dropped strip, and say how many pixels it holds.

`TileStats` keeps every pass's tile sums, and they are its one source of truth: the paired test, the normality
diagnostics, re-tiling, subsetting and merging need them anyway, and they are small (1080p at 32×32 tiles is
2040×3 numbers a pass). The mean and the second moment about the mean (M2) are derived from them when asked for,
by a two-pass sum shifted by the first pass: exact to rounding in float64, no sum-of-squares cancellation, and
merging runs is a concatenation, so merged equals accumulated exactly.

numpy only: this module runs inside a stock Blender.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from . import parallel
from .errors import GridMismatchError, RunMismatchError, WelchInputError, check_int
from .pixels import PixelMoments, summed_means

__all__ = ["EDGES", "MAX_IMAGE_SIDE", "MAX_SPP", "RunInfo", "TileStats", "grid_size", "tile_row_blocks", "tile_sums"]

#: Cycles' largest render side (it clamps larger resolutions to this) and largest sample count (2**24).
MAX_IMAGE_SIDE = 65536
MAX_SPP = 2**24

#: Bytes of per-pass sums a computation over all passes takes at a time: work on the whole grid at once would
#: need several copies of every pass's sums (6.9 GB for 1-pixel tiles of a 1024² image at 32 passes a side).
BLOCK_BYTES = 1 << 26

#: Fields of RunInfo that say which configuration made the passes: runs merge (and resume) only when all agree.
IDENTITY_FIELDS = (
    "scene",
    "scene_id",
    "renderer",
    "renderer_version",
    "build_hash",
    "device",
    "sampling_pattern",
    "spp",
    "settings_hash",
    "overrides",
)


@dataclass(frozen=True)
class RunInfo:
    """What produced the passes: travels with the statistics so runs can be told apart and differences named.

    `scene` is a name for people (a file name, a built-in scene); `scene_id` is what fixes the scene's content
    (``sha256:<hex>`` of a .blend, ``builtin:<name>:<builder version>``); `settings` are the render settings that
    change the converged image, `settings_hash` their hash together with the overrides; `fixed` the settings the
    passes fix whatever the scene had (samples, denoiser, ...), by the same paths: [the scene's value, the passes'].
    """

    spp: int = 1
    renderer: str = "unknown"
    renderer_version: str = ""
    build_hash: str = ""
    device: str = ""
    sampling_pattern: str = ""
    scene: str = ""
    scene_id: str = ""
    settings: dict[str, Any] = field(default_factory=dict)
    settings_hash: str = ""
    overrides: tuple[str, ...] = ()
    fixed: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        check_int("spp", self.spp, maximum=MAX_SPP)
        for name in ("renderer", "renderer_version", "build_hash", "device", "sampling_pattern", "scene", "scene_id"):
            value = getattr(self, name)
            if not isinstance(value, str):
                raise WelchInputError(f"`{name}` must be a string, got {type(value).__name__} {value!r:.40}")
        for name in ("settings", "fixed"):
            value = getattr(self, name)
            if not isinstance(value, dict):
                raise WelchInputError(f"`{name}` must be a dict, got {type(value).__name__}")
        if isinstance(self.overrides, str) or not all(isinstance(o, str) for o in self.overrides):
            raise WelchInputError(f"`overrides` must be a list of strings, got {self.overrides!r:.60}")
        object.__setattr__(self, "overrides", tuple(self.overrides))

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self) | {"overrides": list(self.overrides)}

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunInfo:
        """The inverse of `to_json`; keys this version does not know are ignored (files of later versions)."""
        if not isinstance(data, dict):
            raise WelchInputError(f"run info must be a JSON object, got {type(data).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        values = {k: v for k, v in data.items() if k in known}
        if isinstance(values.get("overrides"), list):
            values["overrides"] = tuple(values["overrides"])
        return cls(**values)

    def identity(self) -> dict[str, Any]:
        """What must agree for two runs to be one configuration."""
        return {name: getattr(self, name) for name in IDENTITY_FIELDS}


#: How the tiles meet the right and bottom edges of an image the tile does not divide: "partial" tiles cover the
#: whole image; "dropped" (statistics files of earlier versions) leaves the incomplete tiles out.
EDGES = ("partial", "dropped")


def grid_size(height: int, width: int, tile: int, edges: str = "partial") -> tuple[int, int]:
    """Tiles down and across an image of `height` x `width` pixels."""
    if edges == "partial":
        return -(-height // tile), -(-width // tile)
    return height // tile, width // tile


def tile_sums(image: npt.ArrayLike, tile: int, channels: int = 3, edges: str = "partial") -> np.ndarray:
    """Sum an H×W×C image over `tile`×`tile` blocks: the Welch samples of one pass (§4.1).

    Returns a float64 array of shape (ceil(H / tile), ceil(W / tile), channels): the last row and column of
    tiles are partial where `tile` does not divide the image (``edges="dropped"``: left out, as the paper does,
    shape (H // tile, W // tile, channels)). Extra channels (alpha) are ignored.
    """
    tile, channels = check_int("tile", tile), check_int("channels", channels)
    image = _check_image(image, channels)
    if tile > min(image.shape[:2]):
        raise WelchInputError(f"`tile` must not exceed the image size {image.shape[1]}x{image.shape[0]}, got {tile}")
    if edges not in EDGES:
        raise WelchInputError(f"`edges` must be one of {EDGES}, got {edges!r}")
    height, width = image.shape[:2]
    ty, tx = height // tile, width // tile
    full = _full_tile_sums(image, tile, channels, ty, tx)
    if edges == "dropped" or (height % tile == 0 and width % tile == 0):
        return full
    out = np.zeros((*grid_size(height, width, tile), channels))
    out[:ty, :tx] = full
    if width % tile:  # the partial column, then the partial row (with the corner)
        right = image[: ty * tile, tx * tile :, :channels].reshape(ty, tile, -1, channels)
        out[:ty, tx] = right.sum(axis=(1, 2), dtype=np.float64)
    if height % tile:
        bottom = image[ty * tile :, :, :channels]
        padded = np.zeros((bottom.shape[0], out.shape[1] * tile, channels), bottom.dtype)
        padded[:, :width] = bottom
        out[ty] = padded.reshape(bottom.shape[0], out.shape[1], tile, channels).sum(axis=(0, 2), dtype=np.float64)
    return out


def _full_tile_sums(image: np.ndarray, tile: int, channels: int, ty: int, tx: int) -> np.ndarray:
    """The sums of the complete tiles, (ty, tx, channels): rows of tiles on every core (`welch_core.parallel`)."""
    width = image.shape[1]
    out = np.empty((ty, tx, channels))

    def tile_rows(rows: slice) -> None:
        part = image[rows.start * tile : rows.stop * tile].reshape(-1, tile, width * image.shape[2])
        # Sum the tile's rows first with a contiguous inner axis (near memory speed), then the columns in float64.
        # For float32 input the row partial sums of `tile` values stay in float32: their rounding error (~1e-7
        # relative, measured) is far below the pass-to-pass spread of a tile sum and has no systematic sign.
        row_sums = part.sum(axis=1).reshape(-1, width, image.shape[2])[:, : tx * tile, :channels]
        row_sums.reshape(-1, tx, tile, channels).sum(axis=2, dtype=np.float64, out=out[rows])

    parallel.by_rows(tile_rows, ty, 1, ty * tile * width * channels)
    return out


def tile_row_blocks(sums: np.ndarray, budget: int | None = None):
    """Slices of tile rows (axis 1 of per-pass sums) such that each block of all passes fits in `budget` bytes
    (default `BLOCK_BYTES`, at least one row): computations over the passes go block by block and their
    temporaries stay small."""
    budget = budget or BLOCK_BYTES
    n, rows = sums.shape[0], sums.shape[1]
    row_bytes = max(n * int(np.prod(sums.shape[2:], dtype=np.int64)) * 8, 1)
    step = max(1, budget // row_bytes)
    return [slice(start, min(start + step, rows)) for start in range(0, rows, step)] or [slice(0, 0)]


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


def _check_seeds(seeds, taken=()) -> list[int]:
    """`seeds` as ints; raise unless they are integers, distinct, and not in `taken`."""
    checked = []
    for seed in seeds:
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise WelchInputError(f"`seed` must be an integer, got {seed!r}")
        checked.append(int(seed))
    seen = set(taken)
    for seed in checked:
        if seed in seen:
            raise WelchInputError(f"seed {seed} is already in this run: passes must have distinct seeds")
        seen.add(seed)
    return checked


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
        Also keep the per-pixel mean image (for display over the p-value map): the pixel sum, or with
        `keep_pixel_moments` the moments' mean (no sum to update a pass).
    keep_pixel_moments : bool
        Also keep each pixel's mean and M2 over the passes (`pixels`), for the pixel-variance test.
    """

    def __init__(
        self,
        height: int,
        width: int,
        tile: int = 32,
        channels: int = 3,
        info: RunInfo | None = None,
        keep_mean_image: bool = True,
        edges: str = "partial",
        covered: tuple[int, int] | None = None,
        keep_pixel_moments: bool = False,
    ):
        self.height = check_int("height", height, maximum=MAX_IMAGE_SIDE)
        self.width = check_int("width", width, maximum=MAX_IMAGE_SIDE)
        self.tile = check_int("tile", tile)
        self.channels = check_int("channels", channels)
        if covered is None and self.tile > min(self.height, self.width):  # a derived coarser scale may be larger
            raise WelchInputError(f"`tile` must not exceed the image size {self.width}x{self.height}, got {self.tile}")
        if info is not None and not isinstance(info, RunInfo):
            raise WelchInputError(f"`info` must be a RunInfo, got {type(info).__name__}")
        if edges not in EDGES:
            raise WelchInputError(f"`edges` must be one of {EDGES}, got {edges!r}")
        self.edges = edges
        if covered is None:  # the pixels the tiles cover, (rows, columns) from the top left
            ty, tx = grid_size(self.height, self.width, self.tile, edges)
            covered = (min(ty * self.tile, self.height), min(tx * self.tile, self.width))
        self.covered = (int(covered[0]), int(covered[1]))
        self.info = info if info is not None else RunInfo()
        self.seeds: list[int] = []
        # Tile sums of the passes in the first `_count` rows; the capacity doubles as passes arrive.
        self._buffer = np.empty((0, *self.grid_shape))
        self._count = 0
        self._moments: tuple[int, np.ndarray, np.ndarray] | None = None  # (count, mean, m2), derived from sums
        # float32 is enough for an image that is only displayed, and keeps add_pass near memory speed. A run that
        # keeps pixel moments keeps no sum: its mean image is the moments' mean (`pixel_sum`), one array less to
        # update a pass, to hold and to save.
        summed = keep_mean_image and not keep_pixel_moments
        self._pixel_sum = np.zeros((self.height, self.width, self.channels), np.float32) if summed else None
        self._mean_from_pixels = keep_mean_image and keep_pixel_moments
        self._pixels_sum: tuple | None = None  # (the moments, their n, n x their mean in float32): `pixel_sum`
        self._pixels = PixelMoments(self.height, self.width, self.channels) if keep_pixel_moments else None

    @classmethod
    def from_sums(
        cls,
        sums: npt.ArrayLike,
        seeds,
        height: int,
        width: int,
        tile: int,
        info: RunInfo | None = None,
        pixel_sum: np.ndarray | None = None,
        edges: str = "partial",
        covered: tuple[int, int] | None = None,
        pixels: PixelMoments | None = None,
        mean_from_pixels: bool = False,
    ) -> TileStats:
        """Statistics built from per-pass tile sums of shape (n, tiles_y, tiles_x, channels): the constructor for
        loaders and derived runs. A C-contiguous float64 array is used as it is (not copied): don't change it
        afterwards.

        `pixel_sum`, if given, is the per-pixel sum over the passes (H×W×channels), from which the mean image is
        shown. `edges` and `covered` say how the tiles meet the image's edges (see `TileStats`); `pixels` are the
        passes' per-pixel moments (checked to be of these passes' count and image); `mean_from_pixels`: without a
        `pixel_sum`, the mean image is theirs (a statistics file that stores the moments and no sum).
        """
        sums = np.asarray(sums, dtype=np.float64)
        if sums.ndim != 4:
            raise WelchInputError(f"`sums` must have 4 dimensions (n, tiles_y, tiles_x, channels), got {sums.shape}")
        out = cls(height, width, tile, sums.shape[-1], info, keep_mean_image=False, edges=edges, covered=covered)
        seeds = _check_seeds(seeds)
        if sums.shape[1:] != out.grid_shape or len(sums) != len(seeds):
            raise WelchInputError(f"`sums` must have shape (n_seeds, {out.grid_shape}), got {sums.shape}")
        out._append(sums, seeds)
        if pixel_sum is not None:
            adopt = isinstance(pixel_sum, np.ndarray) and pixel_sum.dtype == np.float32 and pixel_sum.flags.c_contiguous
            pixel_sum = np.asarray(pixel_sum, dtype=np.float32)
            if pixel_sum.shape != (height, width, out.channels):
                raise WelchInputError(
                    f"`pixel_sum` must have shape {(height, width, out.channels)}, got {pixel_sum.shape}"
                )
            out._pixel_sum = pixel_sum if adopt else pixel_sum.copy()  # adopted like the sums: one copy in memory
        if pixels is not None:
            if pixels.shape != (height, width, out.channels) or pixels.n != out.n:
                raise WelchInputError(
                    f"`pixels` must be the moments of {out.n} passes of {(height, width, out.channels)}, got "
                    f"{pixels.n} of {pixels.shape}"
                )
            out.pixels = pixels
            out._mean_from_pixels = mean_from_pixels and out._pixel_sum is None
        return out

    # -- shape of the grid ---------------------------------------------------------------------------------

    @property
    def tiles_y(self) -> int:
        return -(-self.covered[0] // self.tile)

    @property
    def tiles_x(self) -> int:
        return -(-self.covered[1] // self.tile)

    @property
    def grid_shape(self) -> tuple[int, int, int]:
        return (self.tiles_y, self.tiles_x, self.channels)

    @property
    def dropped_pixels(self) -> int:
        """Pixels no tile covers, which are not tested: the incomplete edge tiles of a file written before partial
        tiles (0 for every run made now)."""
        return self.height * self.width - self.covered[0] * self.covered[1]

    def tile_box(self, row: int, col: int) -> tuple[int, int, int, int]:
        """The pixels of tile (`row`, `col`): x, y, width, height (smaller at a partial edge)."""
        x, y = int(col) * self.tile, int(row) * self.tile
        return x, y, min(self.tile, self.covered[1] - x), min(self.tile, self.covered[0] - y)

    # -- the data and what derives from it -----------------------------------------------------------------

    @property
    def n(self) -> int:
        return self._count

    count = n

    @property
    def sums(self) -> np.ndarray:
        """Every pass's tile sums, shape (n, tiles_y, tiles_x, channels), in the order of `seeds` (read-only)."""
        view = self._buffer[: self._count]
        view.flags.writeable = False
        return view

    @property
    def mean(self) -> np.ndarray:
        """Mean of the Welch samples per tile and channel (zeros while there are no passes)."""
        return self._derived_moments()[0]

    @property
    def m2(self) -> np.ndarray:
        """Second moment about the mean, sum of (x - mean)², per tile and channel."""
        return self._derived_moments()[1]

    @property
    def variance(self) -> np.ndarray:
        """Unbiased sample variance of the Welch samples (NaN where n < 2)."""
        if self._count < 2:
            return np.full(self.grid_shape, np.nan)
        with np.errstate(invalid="ignore"):
            return self.m2 / (self._count - 1)

    @property
    def pixels(self) -> PixelMoments | None:
        """Each pixel's moments over the passes (`welch_core.pixels`), where kept: a run of other passes (a subset,
        the whole image's channel sum) has none."""
        return self._pixels

    @pixels.setter
    def pixels(self, moments: PixelMoments | None) -> None:
        if moments is None and self._mean_from_pixels and self._pixels is not None:
            self._pixel_sum = self.pixel_sum.copy()  # the mean image outlives the moments: a sum of its own again
            self._mean_from_pixels = False
        self._pixels = moments

    @property
    def pixel_sum(self) -> np.ndarray | None:
        """Per-pixel sum over the passes (H×W×channels float32), if kept: n x the pixels' means in a run that keeps
        pixel moments (computed once per n; don't change it)."""
        if self._mean_from_pixels and self._pixels is not None:
            pixels = self._pixels
            if self._pixels_sum is None or self._pixels_sum[0] is not pixels or self._pixels_sum[1] != pixels.n:
                self._pixels_sum = (pixels, pixels.n, summed_means(pixels.mean, pixels.n))
            return self._pixels_sum[2]
        if self._pixel_sum is None:
            return None
        return self._pixel_sum[..., : self.channels]

    def _keeps_mean_image(self) -> bool:
        return self._pixel_sum is not None or (self._mean_from_pixels and self._pixels is not None)

    @property
    def mean_image(self) -> np.ndarray | None:
        """Per-pixel mean over the passes (H×W×channels float32, top row first), if kept."""
        if not self._keeps_mean_image() or self._count == 0:
            return None
        return self.pixel_sum / np.float32(self._count)

    def pixel_terms(self) -> tuple[np.ndarray, np.ndarray]:
        """V = sum_p s_p² and Q = sum_p (s_p²)² per tile-channel from the pixel moments (`welch_core.pixels`)."""
        if self.pixels is None:
            raise WelchInputError("this run keeps no pixel moments")
        return self.pixels.terms(self.tile, (self.tiles_y, self.tiles_x), self.covered)

    def _derived_moments(self) -> tuple[np.ndarray, np.ndarray]:
        if self._moments is None or self._moments[0] != self._count:
            sums = self.sums
            mean, m2 = np.zeros(self.grid_shape), np.zeros(self.grid_shape)
            for rows in tile_row_blocks(sums) if self._count else ():
                # Two-pass moments shifted by the first pass: a constant tile gets exactly its value and m2 = 0
                # (an unshifted mean can be an ulp off), and no sum-of-squares cancellation at a large offset.
                block = sums[:, rows]
                with np.errstate(invalid="ignore"):
                    shifted = block - block[0]
                    offset = shifted.mean(axis=0)
                    mean[rows] = block[0] + offset
                    m2[rows] = ((shifted - offset) ** 2).sum(axis=0)
            mean.flags.writeable = m2.flags.writeable = False
            self._moments = (self._count, mean, m2)
        return self._moments[1], self._moments[2]

    # -- checks --------------------------------------------------------------------------------------------

    def same_grid(self, other: TileStats) -> None:
        """Raise GridMismatchError unless `other` has the same image size, tile size and channels."""
        mine = (self.width, self.height, self.tile, self.channels)
        theirs = (other.width, other.height, other.tile, other.channels)
        if mine != theirs:
            raise GridMismatchError(
                f"statistics have different grids (width, height, tile, channels): {mine} against {theirs}"
            )
        if self.covered != other.covered:
            raise GridMismatchError(
                f"statistics cover different parts of the image: {self.covered[1]}x{self.covered[0]} pixels against "
                f"{other.covered[1]}x{other.covered[0]} (a file written before partial edge tiles: render it again)"
            )

    def same_run(self, other: TileStats, action: str = "merge") -> None:
        """Raise unless `other` is the same configuration (grid and every identity field of RunInfo)."""
        self.same_grid(other)
        mine, theirs = self.info.identity(), other.info.identity()
        for name in IDENTITY_FIELDS:
            if mine[name] != theirs[name]:
                a, b = mine[name], theirs[name]
                if name == "settings_hash":  # name the setting, not the hash
                    ours, yours = self.info.settings, other.info.settings
                    key = next((k for k in sorted(set(ours) | set(yours)) if ours.get(k) != yours.get(k)), None)
                    if key is not None:
                        name, a, b = f"the setting {key}", ours.get(key), yours.get(key)
                raise RunMismatchError(f"can't {action} runs that differ in {name}: {_short(a)} and {_short(b)}")

    # -- accumulation --------------------------------------------------------------------------------------

    def add_pass(self, image: npt.ArrayLike, seed: int, allow_nonfinite: bool = False) -> None:
        """Add one pass rendered with `seed`. A rejected pass leaves the statistics unchanged.

        Non-finite pixel values raise unless `allow_nonfinite`; then the affected tiles carry NaN/inf and are
        excluded from the test with the reason ``non_finite`` (never turned into a p-value).
        """
        seed = _check_seeds([seed], self.seeds)[0]
        image = _check_image(image, self.channels)
        if image.shape[:2] != (self.height, self.width):
            raise WelchInputError(
                f"`image` must be {self.height}x{self.width} (height x width) like the run, "
                f"got {image.shape[0]}x{image.shape[1]}"
            )
        sums = tile_sums(image, self.tile, self.channels, self.edges)
        if not allow_nonfinite and not np.isfinite(sums).all():
            bad = int((~np.isfinite(image[..., : self.channels])).sum())
            raise WelchInputError(f"pass with seed {seed} has {bad} non-finite pixel values")
        self._append(sums[None], [seed])
        if self.pixels is not None and np.isfinite(sums).all():
            self.pixels.add(image)
        else:  # a kept pass with NaN or inf pixels: its pixels have no variance to speak of, the run keeps none
            self.pixels = None
        if self._pixel_sum is not None and not self._mean_from_pixels:
            if self._count == 1 and self._pixel_sum.shape != image.shape:
                # Sum all of the pass's channels (alpha too): a contiguous add is 5x faster than a strided one.
                self._pixel_sum = np.zeros(image.shape, np.float32)
            if self._pixel_sum.shape == image.shape:
                np.add(self._pixel_sum, image, out=self._pixel_sum)
            else:
                self._pixel_sum[..., : self.channels] += image[..., : self.channels]

    def add_sums(
        self, sums: npt.ArrayLike, seeds, pixel_sum: np.ndarray | None = None, pixels: PixelMoments | None = None
    ) -> None:
        """Add passes given as tile sums (n, tiles_y, tiles_x, channels), e.g. from a worker process, with the
        per-pixel sum over those passes when the mean image is kept, and their pixel moments where this run keeps
        them (without, the run keeps none from now on). All or nothing."""
        sums = np.asarray(sums, dtype=np.float64)
        seeds = _check_seeds(seeds, self.seeds)
        if sums.shape != (len(seeds), *self.grid_shape):
            raise WelchInputError(f"`sums` must have shape {(len(seeds), *self.grid_shape)}, got {sums.shape}")
        # The mean image needs the passes' pixel sum, unless it is the moments' mean and they come with theirs.
        summed = self._keeps_mean_image() and not (self._mean_from_pixels and pixels is not None)
        if summed:
            if pixel_sum is None:
                raise WelchInputError("`pixel_sum` is needed: this run keeps the mean image")
            pixel_sum = np.asarray(pixel_sum, dtype=np.float32)
            if pixel_sum.shape[:2] != (self.height, self.width) or pixel_sum.shape[2] < self.channels:
                raise WelchInputError(f"`pixel_sum` must be {self.height}x{self.width}, got {pixel_sum.shape}")
        if self.pixels is not None and pixels is not None and pixels.n != len(seeds):
            raise WelchInputError(f"`pixels` must be the moments of {len(seeds)} passes, got {pixels.n}")
        if pixels is None:
            self.pixels = None  # passes without moments: the run keeps none from now on
        if summed:
            self._pixel_sum[..., : self.channels] += pixel_sum[..., : self.channels]
        if self.pixels is not None:
            self.pixels.absorb(pixels)
        self._append(sums, seeds)

    def _append(self, sums: np.ndarray, seeds: list[int]) -> None:
        needed = self._count + len(sums)
        if self._count == 0 and sums.dtype == np.float64 and sums.flags.c_contiguous and len(sums) > 1:
            self._buffer, self._count = sums, needed  # adopt a whole run's sums: no second copy in memory
            self.seeds.extend(seeds)
            return
        if needed > len(self._buffer):
            grown = np.empty((max(needed, 2 * len(self._buffer), 8), *self.grid_shape))
            grown[: self._count] = self._buffer[: self._count]
            self._buffer = grown
        self._buffer[self._count : needed] = sums
        self._count = needed
        self.seeds.extend(seeds)

    def merge(self, other: TileStats) -> TileStats:
        """Return the statistics of both runs together; neither input changes.

        Runs merge when they are one configuration (`same_run`) and have disjoint seeds.
        """
        self.same_run(other, "merge")
        _check_seeds(other.seeds, self.seeds)
        both = self.pixels is not None and other.pixels is not None
        pixels = self.pixels.merged(other.pixels) if both else None
        keep = self._keeps_mean_image() and other._keeps_mean_image()
        pixel_sum = self.pixel_sum + other.pixel_sum if keep and pixels is None else None
        return TileStats.from_sums(
            np.concatenate([self.sums, other.sums]),
            self.seeds + other.seeds,
            self.height,
            self.width,
            self.tile,
            self.info,
            pixel_sum,
            self.edges,
            self.covered,
            pixels,
            mean_from_pixels=keep,
        )

    # -- derived runs --------------------------------------------------------------------------------------

    def subset(self, indices: npt.ArrayLike) -> TileStats:
        """The statistics of the passes at `indices` (positions in `seeds`); the mean image is not kept."""
        indices = np.asarray(indices, dtype=np.intp)
        if len(np.unique(indices)) != len(indices) or (
            len(indices) and not 0 <= indices.min() <= indices.max() < self._count
        ):
            raise WelchInputError(f"`indices` must be distinct positions in 0..{self._count - 1}")
        seeds = [self.seeds[i] for i in indices]
        return TileStats.from_sums(
            self.sums[indices],
            seeds,
            self.height,
            self.width,
            self.tile,
            self.info,
            edges=self.edges,
            covered=self.covered,
        )

    def retile(self, factor: int) -> TileStats:
        """The statistics at tile size `tile * factor`, from the stored per-pass sums (no re-rendering); the mean
        image is not kept, the pixel moments are (they are the same passes' pixels)."""
        factor = check_int("factor", factor)
        tile = self.tile * factor
        if factor > 1 and max(self.tiles_y, self.tiles_x) <= factor // 2:  # half the factor covers it all already
            raise WelchInputError(f"`factor` {factor} makes tiles larger than the image")
        # Blocks of factor x factor stored tiles; the last row and column of blocks are partial where the factor
        # does not divide the grid: they sum the stored tiles there are, so the coarse grid covers what the stored
        # one does.
        n, f, c = self._count, factor, self.channels
        ty, tx = self.tiles_y // f, self.tiles_x // f  # complete blocks
        sums = np.zeros((n, -(-self.tiles_y // f), -(-self.tiles_x // f), c))
        stored = self.sums
        sums[:, :ty, :tx] = stored[:, : ty * f, : tx * f].reshape(n, ty, f, tx, f, c).sum(axis=(2, 4))
        if self.tiles_x % f and ty:  # the partial column of blocks
            sums[:, :ty, tx] = stored[:, : ty * f, tx * f :].reshape(n, ty, f, -1, c).sum(axis=(2, 3))
        if self.tiles_y % f:  # the partial row of blocks, the corner with it
            strip = stored[:, ty * f :].sum(axis=1)  # (n, tiles_x, c)
            columns = np.zeros((n, sums.shape[2] * f, c))
            columns[:, : self.tiles_x] = strip
            sums[:, ty] = columns.reshape(n, sums.shape[2], f, c).sum(axis=2)
        return TileStats.from_sums(
            sums, self.seeds, self.height, self.width, tile, self.info, edges=self.edges, covered=self.covered,
            pixels=self.pixels,
        )  # fmt: skip

    def whole(self) -> TileStats:
        """The whole image as one Welch sample a pass: every tile and channel summed (one tile, one channel)."""
        sums = self.sums.sum(axis=(1, 2, 3)).reshape(self._count, 1, 1, 1)
        tile = max(self.covered)
        return TileStats.from_sums(
            sums, self.seeds, self.height, self.width, tile, self.info, edges=self.edges, covered=self.covered
        )

    def __repr__(self) -> str:
        return (
            f"TileStats({self.width}x{self.height}, tile={self.tile}, grid={self.tiles_x}x{self.tiles_y}, "
            f"n={self._count}, spp={self.info.spp}, renderer={self.info.renderer!r})"
        )


def _short(value) -> str:
    text = repr(list(value)) if isinstance(value, tuple) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
