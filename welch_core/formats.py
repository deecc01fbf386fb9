"""Files: the statistics file, render passes and maps as EXR, and tile sums as PFM for other tools.

Statistics file (``.npz``, format ``welch-bias-stats`` version 1), loaded with ``allow_pickle=False``:

=============  ==============================  ===========================================================
key            dtype, shape                    meaning
=============  ==============================  ===========================================================
format         str                             "welch-bias-stats"
version        int                             1
meta           str (JSON)                      height, width, tile, channels and the RunInfo fields
seeds          int64 (n,)                      seed of each pass
sums           float64 (n, ty, tx, c)          each pass's tile sums (the Welch samples)
mean, m2       float64 (ty, tx, c)             Welford mean and second moment about the mean
mean_image     float32 (h, w, c), optional     per-pixel mean, top row first
=============  ==============================  ===========================================================

Writes are atomic (a temporary file renamed over the target), so a crash never leaves a partial file in place of
a good one.
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .errors import StatsFileError, WelchInputError
from .tiles import RunInfo, TileStats

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "load_stats",
    "read_exr",
    "read_pfm",
    "save_stats",
    "write_exr",
    "write_pfm",
    "write_tile_pfms",
]

FORMAT_NAME = "welch-bias-stats"
FORMAT_VERSION = 1


def _atomic_write(path: str | os.PathLike, write) -> None:
    """Call `write(file)` on a temporary file next to `path`, then rename it over `path`."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_stats(path: str | os.PathLike, stats: TileStats) -> None:
    """Write `stats` to `path` atomically (see the module docstring for the format)."""
    meta = {
        "height": stats.height,
        "width": stats.width,
        "tile": stats.tile,
        "channels": stats.channels,
        "info": stats.info.to_json(),
    }
    arrays = {
        "format": np.array(FORMAT_NAME),
        "version": np.array(FORMAT_VERSION),
        "meta": np.array(json.dumps(meta, sort_keys=True)),
        "seeds": np.array(stats.seeds, dtype=np.int64),
        "sums": stats.sums,
        "mean": stats.mean,
        "m2": stats.m2,
    }
    if stats.mean_image is not None:
        arrays["mean_image"] = stats.mean_image
    try:
        _atomic_write(path, lambda f: np.savez(f, **arrays))
    except OSError as exc:
        raise WelchInputError(f"can't write statistics file {os.fspath(path)!r}: {exc.strerror or exc}") from None


def load_stats(path: str | os.PathLike) -> TileStats:
    """Read a statistics file; anything missing, truncated, foreign or of another version raises StatsFileError."""
    name = os.fspath(path)
    try:
        loaded = np.load(name, allow_pickle=False)
        if isinstance(loaded, np.ndarray):  # a plain .npy array, not an archive: rejected below
            arrays = None
        else:
            with loaded as data:
                arrays = {key: data[key] for key in data.files}
    except FileNotFoundError:
        raise StatsFileError(f"statistics file {name!r} does not exist") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise StatsFileError(f"{name!r} is not a readable statistics file ({type(exc).__name__}: {exc})") from None
    if not isinstance(arrays, dict) or str(arrays.get("format", "")) != FORMAT_NAME:
        raise StatsFileError(f"{name!r} is not a {FORMAT_NAME} file")
    version = int(arrays.get("version", -1))
    if version != FORMAT_VERSION:
        raise StatsFileError(f"{name!r} has format version {version}; this tool reads version {FORMAT_VERSION}")
    try:
        return _stats_from_arrays(arrays)
    except (KeyError, ValueError, TypeError) as exc:
        raise StatsFileError(f"{name!r} is damaged: {exc}") from None


def _stats_from_arrays(arrays: dict) -> TileStats:
    meta = json.loads(str(arrays["meta"]))
    stats = TileStats(
        meta["height"], meta["width"], meta["tile"], meta["channels"], RunInfo.from_json(meta["info"]), False
    )
    seeds, sums = arrays["seeds"], arrays["sums"]
    shape = stats.grid_shape
    if sums.shape != (len(seeds), *shape) or arrays["mean"].shape != shape or arrays["m2"].shape != shape:
        raise ValueError(f"array shapes {sums.shape}, {arrays['mean'].shape} don't fit the grid {shape}")
    stats.seeds = stats._check_new_seeds(seeds.tolist())
    stats.count = len(seeds)
    stats._sums = list(sums.astype(np.float64))
    stats.mean = arrays["mean"].astype(np.float64)
    stats.m2 = arrays["m2"].astype(np.float64)
    if "mean_image" in arrays:
        image = arrays["mean_image"]
        if image.shape != (stats.height, stats.width, stats.channels):
            raise ValueError(f"mean image of shape {image.shape} doesn't fit {stats.height}x{stats.width}")
        stats._pixel_sum = image.astype(np.float32) * np.float32(stats.count)
    return stats


# -- EXR ---------------------------------------------------------------------------------------------------


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read the colour of an EXR file as an H×W×3 float32 array, top row first.

    Takes channels R, G, B, else a ``Combined`` layer's ``<layer>.R/G/B`` (Blender's ``ViewLayer.Combined.R``),
    else the first layer (by name) that has R, G and B.
    """
    import OpenEXR  # imported here: only file-reading code needs it

    name = os.fspath(path)
    if not os.path.exists(name):
        raise WelchInputError(f"EXR file {name!r} does not exist")
    try:
        channels = OpenEXR.File(name).channels()  # plain R, G, B (A) come interleaved: the fast path for passes
        for interleaved in ("RGB", "RGBA"):
            if interleaved in channels:
                return channels[interleaved].pixels[..., :3].astype(np.float32, copy=False)
        channels = OpenEXR.File(name, separate_channels=True).channels()
    except Exception as exc:  # OpenEXR raises bare RuntimeError/Exception for damaged files
        raise WelchInputError(f"{name!r} is not a readable EXR file ({exc})") from None
    layers = sorted({k.rsplit(".", 1)[0] + "." for k in channels if "." in k})
    # A "Combined" layer before any other (Blender's AO, DiffCol, ... passes sort before it by name).
    for prefix in [""] + sorted(layers, key=lambda layer: not layer.endswith("Combined.")):
        keys = [prefix + c for c in "RGB"]
        if all(k in channels for k in keys):
            return np.stack([channels[k].pixels.astype(np.float32) for k in keys], axis=-1)
    raise WelchInputError(f"{name!r} has no R, G, B channels (it has {sorted(channels)})")


def write_exr(path: str | os.PathLike, image: npt.ArrayLike) -> None:
    """Write an H×W or H×W×C float array as an uncompressed 32-bit float EXR (atomically)."""
    import OpenEXR

    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        channels = {"Y": img}
    elif img.ndim == 3 and img.shape[2] in (1, 3, 4):
        channels = {name: np.ascontiguousarray(img[..., i]) for i, name in enumerate("RGBA"[: img.shape[2]])}
        if img.shape[2] == 1:
            channels = {"Y": channels.pop("R")}
    else:
        raise WelchInputError(f"`image` must be H×W or H×W×(1, 3 or 4), got shape {img.shape}")
    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    path = Path(path)
    with tempfile.TemporaryDirectory(dir=path.parent) as tmp:
        tmp_file = os.path.join(tmp, path.name)
        OpenEXR.File(header, channels).write(tmp_file)
        os.replace(tmp_file, path)


# -- PFM (the format of the paper's welch.c and its ports) ---------------------------------------------------


def write_pfm(path: str | os.PathLike, image: npt.ArrayLike) -> None:
    """Write an H×W×3 (or H×W) array as little-endian float32 PFM; PFM stores the bottom row first."""
    img = np.asarray(image, dtype="<f4")
    if img.ndim == 3 and img.shape[2] == 3:
        kind = b"PF"
    elif img.ndim == 2:
        kind = b"Pf"
    else:
        raise WelchInputError(f"`image` must be H×W×3 or H×W for PFM, got shape {img.shape}")
    header = kind + b"\n%d %d\n-1.0\n" % (img.shape[1], img.shape[0])
    _atomic_write(path, lambda f: f.write(header + np.ascontiguousarray(img[::-1]).tobytes()))


def read_pfm(path: str | os.PathLike) -> np.ndarray:
    """Read a PFM file as an H×W×3 (or H×W) float32 array, top row first."""
    name = os.fspath(path)
    try:
        with open(name, "rb") as f:
            kind = f.readline().strip()
            size = f.readline().split()
            scale = float(f.readline())
            data = f.read()
        width, height = int(size[0]), int(size[1])
    except (OSError, ValueError, IndexError) as exc:
        raise WelchInputError(f"{name!r} is not a readable PFM file ({exc})") from None
    if kind not in (b"PF", b"Pf"):
        raise WelchInputError(f"{name!r} is not a PFM file (header {kind[:8]!r})")
    depth = 3 if kind == b"PF" else 1
    dtype = "<f4" if scale < 0 else ">f4"  # negative scale = little-endian
    count = width * height * depth
    if len(data) < 4 * count:
        raise WelchInputError(f"{name!r} is truncated: {len(data)} bytes of pixel data, expected {4 * count}")
    img = np.frombuffer(data, dtype=dtype, count=count).astype(np.float32)
    img = img.reshape((height, width, depth) if depth == 3 else (height, width))
    return np.ascontiguousarray(img[::-1])


def write_tile_pfms(prefix: str | os.PathLike, stats: TileStats) -> tuple[str, str]:
    """Write the sum and the sum of squares of the Welch samples as tile-resolution PFMs (``PREFIX_sum.pfm``,
    ``PREFIX_sumsq.pfm``), the buffers the paper's implementation keeps (§4.2), for cross-checks with its tools.

    float32 loses precision in the sum of squares: use these files for comparison, not as the primary store.
    """
    sum_path, sq_path = f"{os.fspath(prefix)}_sum.pfm", f"{os.fspath(prefix)}_sumsq.pfm"
    total = stats.mean * stats.n
    write_pfm(sum_path, total)
    write_pfm(sq_path, stats.m2 + total * stats.mean)  # sum of squares = M2 + n * mean²
    return sum_path, sq_path
