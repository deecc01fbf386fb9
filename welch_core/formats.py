"""The statistics file, and the one way this tool writes any file (atomically, checked).

Statistics file (``.npz``, format ``welch-bias-stats`` version 2), loaded with ``allow_pickle=False``:

=============  ==============================  ===========================================================
key            dtype, shape                    meaning
=============  ==============================  ===========================================================
format         str                             "welch-bias-stats"
version        int                             2
meta           str (JSON)                      height, width, tile, channels, the RunInfo fields and the
                                               seeds of passes with non-finite tile sums (``--on-nan keep``)
seeds          int64 (n,)                      seed of each pass
sums           float64 (n, ty, tx, c)          each pass's tile sums (the Welch samples)
pixel_sum      float32 (h, w, c), optional     per-pixel sum over the passes, top row first (for display);
                                               not stored beside pixel_mean, which is the sum over n
preview_sum    float32 (h/f, w/f, c), optional the pixel sum in block means of f x f pixels, the smallest f that
                                               brings the longer side to `PREVIEW_SIDE` or less; stored where
                                               the image is larger (the report reads it alone)
pixel_mean     float32 (h, w, c), optional     each pixel's mean over the passes, and its M2 (the sum of
pixel_m2       float64 (h, w, c), optional     squared deviations): the pixel-variance test (`pixels`);
                                               checked against the sums (`pixels.moment_conflict`)
=============  ==============================  ===========================================================

The pixel moments are kept in float64 while passes are added (Welford's update of a bright pixel needs it) and
stored as their precision needs: a pixel's mean in float32, as precise as the float32 passes it averages (a
relative 6e-8, far inside the rounding (5) of `pixels.moment_conflict` allows, and below any pass-to-pass spread
a test could use); M2 in float64, exactly as accumulated, so that moments read back and merged are those of the
run. Files of earlier versions of this tool stored the mean in float64 and the pixel sum beside it; both are read.

Version 1 files (which also stored a mean and M2, and a mean image instead of the pixel sum) are still read;
their stored moments must agree with their sums. A run whose tile does not divide the image has partial tiles at
its right and bottom edges (``"edges": "partial"`` in the metadata): such files are version 4, since a reader of
an earlier version would take their grid for one without those tiles. Files of earlier versions have no edge
tiles (``edges="dropped"``: the strip no whole tile covers is untested).

A reader of an earlier version ignores the pixel moments (they add nothing it needs), so files with them keep
their version; such a reader finds no pixel sum in them either, and shows the preview where there is one, else
no picture. Loading reads only these keys, checks every header (dtype, shape, size against the metadata and
against the bytes in the file) before allocating, and checks the content against itself; any failure is a
`StatsFileError` with one line that names the file.
"""

from __future__ import annotations

import json
import os
import secrets
import struct
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .colormap import shrink
from .errors import StatsFileError, WelchInputError
from .pixels import PixelMoments, moment_conflict, summed_means
from .tiles import MAX_IMAGE_SIDE, RunInfo, TileStats

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "atomic_write",
    "atomic_write_all",
    "load_layers",
    "load_stats",
    "save_stats",
    "stats_arrays",
    "with_preview",
    "write_arrays",
]

FORMAT_NAME = "welch-bias-stats"
FORMAT_VERSION = 2
#: Files with layers (light components, light groups) are version 3; without, version 2 as before, so that a
#: tool that reads version 2 still reads every file without layers.
LAYERS_VERSION = 3
#: Files with partial edge tiles (an image the tile does not divide), with or without layers.
EDGES_VERSION = 4
READABLE_VERSIONS = (1, 2, 3, 4)

#: Seeds are non-negative and fit int64 (ingested passes of unknown seed get a 62-bit id from their content).
MAX_SEED_VALUE = 2**63 - 1


def atomic_write(path: str | os.PathLike, write: Callable, verify: Callable[[Path], None] | None = None) -> None:
    """Call `write(file)` on a new temporary file next to `path`, `verify(temporary_path)` if given, then rename
    it over `path`. Any failure (a full disk, a failed check) removes the temporary file, leaves `path` as it was,
    and raises. The file gets the permissions of the user's umask, like any file a program creates.
    """
    path = Path(path)
    if path.is_dir():
        raise WelchInputError(f"{path} is a folder, not a file: remove it or write elsewhere")
    # A short temporary name: a long but legal target name must not make it too long for the file system.
    tmp = path.parent / f".welch-{secrets.token_hex(6)}.tmp"
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # 0o666 & ~umask
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        if verify is not None:
            verify(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_all(files: dict) -> None:
    """Write several files as one: every content (bytes) goes to a temporary file next to its path first, and only
    when all are written are they renamed over their paths, so a failure (a full disk) leaves every previous file
    as it was, and a report never has a new page beside an old summary. A path that is a folder is refused by
    name, before anything is written."""
    for path in files:
        if Path(path).is_dir():
            raise WelchInputError(f"{path} is a folder, not a file: remove it or write elsewhere")
    written = []
    try:
        for path, data in files.items():
            path = Path(path)
            tmp = path.parent / f".welch-{secrets.token_hex(6)}.tmp"
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            written.append((tmp, path))
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
        for tmp, path in written:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _path in written:
            tmp.unlink(missing_ok=True)
        raise


def save_stats(path: str | os.PathLike, stats: TileStats, layers: dict[str, TileStats] | None = None) -> None:
    """Write `stats` to `path` atomically (see the module docstring for the format), with `layers` (more images
    of the same passes: light components, light groups) where given.

    Raises WelchInputError with one line (naming the file and the reason) when the file can't be written.
    """
    write_arrays(path, with_preview(stats_arrays(stats, layers)))


def stats_arrays(
    stats: TileStats, layers: dict[str, TileStats] | None = None, into: dict[str, np.ndarray] | None = None
) -> dict[str, np.ndarray]:
    """The arrays of the statistics file of `stats` (and `layers`) but the preview (`with_preview` adds it), for
    `write_arrays`: what the run changes in place as passes are added (its pixel moments and sums) is copied, so
    the file can be written while passes go on (a checkpoint written by another thread); the rest is the run's
    own, which it never changes. `into`: the arrays of an earlier call that nothing reads any more (a checkpoint
    written); the copies go into them, as the memory of a new 50 MB array costs 5-20 times the copy on its first
    write. At 1920x1080 with pixel moments: about 7 ms (the moments' copies)."""
    layers = layers or {}
    for name, layer in layers.items():
        if not isinstance(name, str) or not name or len(name) > 200:
            raise WelchInputError(f"a layer's name must be a non-empty string, got {name!r}")
        if layer.seeds != stats.seeds or layer.grid_shape != stats.grid_shape or layer.tile != stats.tile:
            raise WelchInputError(f"layer {name!r} must have the seeds, tiles and channels of the image")
    sums = stats.sums
    nonfinite = [seed for seed, s in zip(stats.seeds, sums, strict=True) if not np.isfinite(s).all()]
    meta = {
        "height": stats.height,
        "width": stats.width,
        "tile": stats.tile,
        "channels": stats.channels,
        "info": stats.info.to_json(),
        "nonfinite_seeds": nonfinite,
    }
    if layers:
        meta["layers"] = list(layers)
    partial = stats.edges == "partial" and (stats.height % stats.tile or stats.width % stats.tile)
    if partial:
        meta["edges"] = "partial"
    version = EDGES_VERSION if partial else LAYERS_VERSION if layers else FORMAT_VERSION
    arrays = {
        "format": np.array(FORMAT_NAME),
        "version": np.array(version, dtype=np.int64),
        "meta": np.array(json.dumps(meta, sort_keys=True, allow_nan=False)),
        "seeds": np.array(stats.seeds, dtype=np.int64),
        "sums": sums,
    }
    if stats.pixels is not None:  # the mean in float32 (a copy), M2 as it is accumulated (copied: it changes)
        arrays["pixel_mean"] = _copy(stats.pixels.mean, np.float32, into, "pixel_mean")
        arrays["pixel_m2"] = _copy(stats.pixels.m2, np.float64, into, "pixel_m2")
    elif stats.pixel_sum is not None:
        arrays["pixel_sum"] = _copy(stats.pixel_sum, stats.pixel_sum.dtype, into, "pixel_sum")
    for index, layer in enumerate(layers.values()):
        arrays[f"layer{index}_sums"] = layer.sums
        if layer.pixel_sum is not None:
            key = f"layer{index}_pixel_sum"
            arrays[key] = _copy(layer.pixel_sum, layer.pixel_sum.dtype, into, key)
    return arrays


def _copy(values: np.ndarray, dtype, into: dict | None, key: str) -> np.ndarray:
    """`values` as `dtype`, a copy: into `into[key]` where that is an array of the same shape and dtype."""
    spare = (into or {}).get(key)
    if spare is None or spare.shape != values.shape or spare.dtype != dtype:
        return values.astype(dtype)
    np.copyto(spare, values, casting="same_kind")
    return spare


def with_preview(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """`arrays` (`stats_arrays`) with the preview of their pixel sum (or of n x their pixels' means) where the
    image is larger than `PREVIEW_SIDE`: what the report reads instead of the whole image."""
    pixel_sum = arrays.get("pixel_sum")
    if pixel_sum is None and "pixel_mean" in arrays:
        pixel_sum = summed_means(arrays["pixel_mean"], len(arrays["seeds"]))
    if pixel_sum is None or max(pixel_sum.shape[:2]) <= PREVIEW_SIDE:
        return arrays
    return arrays | {"preview_sum": shrink(pixel_sum, PREVIEW_SIDE)}


def write_arrays(path: str | os.PathLike, arrays: dict[str, np.ndarray], verify: bool = True) -> None:
    """Write a statistics file's `arrays` (`stats_arrays`) to `path` atomically, checked to read back (unless not
    `verify`: a file its reader checks at once, a worker's chunk); raises WelchInputError with one line (naming
    the file and the reason) when the file can't be written."""

    def write(f) -> None:
        # zipfile directly instead of np.savez: the archive is closed on every path, so a failed write raises
        # here once instead of again from a garbage-collected ZipFile.
        with zipfile.ZipFile(f, "w", zipfile.ZIP_STORED, allowZip64=True) as archive:
            for key, value in arrays.items():
                array = np.asarray(value)
                array = array if array.flags.c_contiguous else array.copy(order="C")
                with archive.open(f"{key}.npy", "w", force_zip64=True) as member:
                    # The header `np.lib.format.write_array` writes, then the array's own bytes: write_array copies
                    # them first (an 81 MB file's copy, on the cores the passes need).
                    np.lib.format.write_array_header_1_0(member, np.lib.format.header_data_from_array_1_0(array))
                    member.write(array.reshape(-1).view(np.uint8))

    def read_back(tmp: Path) -> None:
        with zipfile.ZipFile(tmp) as archive:
            bad = archive.testzip()  # reads every member back and checks its CRC
            if bad is not None or sorted(archive.namelist()) != sorted(f"{k}.npy" for k in arrays):
                raise OSError(f"the written file does not read back ({bad or 'members missing'})")

    try:
        atomic_write(path, write, read_back if verify else None)
    except (OSError, zipfile.BadZipFile) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise WelchInputError(f"can't write statistics file {os.fspath(path)!r}: {reason}") from None


def load_stats(path: str | os.PathLike, pixels: bool = True, moments: bool = True) -> TileStats:
    """Read a statistics file; anything missing, truncated, foreign, inconsistent or of another version raises
    StatsFileError with one line. Without `pixels` the pixel sums are not read (a 4K run's are 100 MB): enough
    for any test, and `load_preview` gives a picture; without `moments` neither are the pixel moments (a
    comparison without the pixel-variance test)."""
    return _read(path, lambda reader: reader.stats(pixels, moments))


def load_layers(path: str | os.PathLike, pixels: bool = True) -> dict[str, TileStats]:
    """The layers of a statistics file (light components, light groups), by name; empty for a file without.
    Checked as `load_stats` checks the image."""
    return _read(path, lambda reader: reader.layers(pixels))


def load_preview(path: str | os.PathLike) -> np.ndarray | None:
    """The per-pixel sums of a statistics file in block means, at most `PREVIEW_SIDE` pixels a side (see
    `colormap.shrink`); None if the file has no pixel sums. The format, metadata and the preview's header are
    checked; the tile sums are not read."""
    return _read(path, lambda reader: reader.preview())


def _read(path: str | os.PathLike, read: Callable[[_Reader], object]):
    name = os.fspath(path)
    try:
        archive = zipfile.ZipFile(name)
    except FileNotFoundError:
        raise StatsFileError(f"statistics file {name!r} does not exist") from None
    except (OSError, zipfile.BadZipFile, ValueError, EOFError) as exc:
        if isinstance(exc, zipfile.BadZipFile) and _is_npy(name):
            raise StatsFileError(f"{name!r} is not a {FORMAT_NAME} file (a single numpy array)") from None
        raise StatsFileError(f"{name!r} is not a readable statistics file ({type(exc).__name__}: {exc})") from None
    with archive:
        reader = _Reader(name, archive)
        try:
            return read(reader)
        except (zipfile.BadZipFile, OSError, EOFError, ValueError, KeyError) as exc:
            if isinstance(exc, StatsFileError):
                raise
            raise StatsFileError(f"{name!r} is not a readable statistics file ({type(exc).__name__}: {exc})") from None


def _is_npy(name: str) -> bool:
    try:
        with open(name, "rb") as f:
            return f.read(6) == b"\x93NUMPY"
    except OSError:
        return False


#: The longer side of a stored preview, in pixels (the report shows no more).
PREVIEW_SIDE = 1024

#: Members at least this large are read by `_Reader.read_stored`.
_DIRECT_READ_BYTES = 1 << 20


def _memory_limit() -> int:
    """Bytes an array of a file may take: half the machine's memory."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") // 2
    except (ValueError, OSError, AttributeError):
        return 8 * 2**30


class _Reader:
    """Reads the known members of one statistics archive, each checked before it is allocated."""

    def __init__(self, name: str, archive: zipfile.ZipFile):
        self.name = name
        self.archive = archive
        self.members = {info.filename.removesuffix(".npy"): info for info in archive.infolist()}

    def fail(self, reason: str) -> StatsFileError:
        return StatsFileError(f"{self.name!r} is damaged: {reason}")

    def array(self, key: str, kinds: str, shape: tuple | None, required: bool = True) -> np.ndarray | None:
        """Member `key` after checking its header: dtype kind in `kinds`, `shape` (None: any), size."""
        info = self.members.get(key)
        if info is None:
            if required:
                raise self.fail(f"it has no {key!r} array")
            return None
        with self.archive.open(info) as member:
            version = np.lib.format.read_magic(member)
            read_header = (
                np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            )
            found_shape, fortran, dtype = read_header(member)
            if dtype.hasobject:
                raise self.fail(f"{key!r} holds Python objects, which this tool never loads")
            if dtype.kind not in kinds:
                raise self.fail(f"{key!r} has dtype {dtype}, expected {_KIND_WORDS[kinds]}")
            if shape is not None and found_shape != shape:
                raise self.fail(f"{key!r} has shape {found_shape}, expected {shape}")
            size = int(np.prod(found_shape, dtype=np.float64)) * dtype.itemsize
            if size > info.file_size:
                raise self.fail(f"{key!r} claims {size} bytes but the file holds {info.file_size}")
            if size > _memory_limit():
                raise StatsFileError(f"{self.name!r}: {key!r} needs {size / 2**30:.1f} GiB, more than half of memory")
            if info.compress_type == zipfile.ZIP_STORED and size >= _DIRECT_READ_BYTES:
                return self.read_stored(info, member.tell(), found_shape, fortran, dtype, key)
            member.seek(0)
            return np.lib.format.read_array(member, allow_pickle=False)

    def read_stored(self, info, header_size: int, shape: tuple, fortran: bool, dtype, key: str) -> np.ndarray:
        """A large uncompressed member read straight into its array and checked against the archive's CRC: half
        the time of zipfile's copy through a bytes object (the pixel sums of a 4K run are 100 MB)."""
        f = self.archive.fp
        f.seek(info.header_offset)
        local = f.read(30)
        if len(local) != 30 or local[:4] != b"PK\x03\x04":
            raise zipfile.BadZipFile(f"bad local header of {info.filename!r}")
        name_size, extra_size = struct.unpack("<HH", local[26:30])
        f.seek(info.header_offset + 30 + name_size + extra_size)
        crc = zlib.crc32(f.read(header_size))
        array = np.empty(shape, dtype, order="F" if fortran else "C")
        data = memoryview(array.reshape(-1, order="A")).cast("B")
        if f.readinto(data) != len(data):
            raise self.fail(f"{key!r} is truncated")
        if zlib.crc32(data, crc) != info.CRC:
            raise self.fail(f"{key!r} does not match its checksum")
        return array

    def scalar(self, key: str, kinds: str):
        value = self.array(key, kinds, ())
        return value.item()

    def version(self) -> int:
        """The format version, after checking that this is a statistics file of a version this tool reads."""
        if "format" not in self.members or self.scalar_or_none("format", "U") != FORMAT_NAME:
            raise StatsFileError(f"{self.name!r} is not a {FORMAT_NAME} file")
        if "version" not in self.members:
            raise StatsFileError(f"{self.name!r} has no format version; this tool reads versions 1 to 4")
        version = self.array("version", "iufcUSb", None)
        if version.shape != () or version.dtype.kind not in "iu":
            raise StatsFileError(f"{self.name!r} has a format version that is not an integer: {_short(version)}")
        version = int(version)
        if version not in READABLE_VERSIONS:
            raise StatsFileError(f"{self.name!r} has format version {version}; this tool reads versions 1 to 4")
        return version

    def layers(self, pixels: bool) -> dict[str, TileStats]:
        image = self.stats(pixels=False, moments=False)  # the image's grid and passes, which its layers share
        names = self.meta().get("layers", [])
        if (
            not isinstance(names, list)
            or not all(isinstance(n, str) and n for n in names)
            or len(set(names)) < len(names)
        ):
            raise self.fail(f"metadata 'layers' must be a list of distinct names, got {_short(names)}")
        seeds = np.array(image.seeds, dtype=np.int64)
        out = {}
        for index, name in enumerate(names):
            sums = self.array(f"layer{index}_sums", "f", image.sums.shape)
            self.check_finite(sums, seeds, self.meta().get("nonfinite_seeds", []))
            pixel_sum = None
            if pixels:
                shape = (image.height, image.width, image.channels)
                pixel_sum = self.array(f"layer{index}_pixel_sum", "f", shape, required=False)
            out[name] = TileStats.from_sums(
                sums, image.seeds, image.height, image.width, image.tile, image.info, pixel_sum, image.edges
            )
        return out

    def preview(self) -> np.ndarray | None:
        if "preview_sum" not in self.members and ("pixel_sum" in self.members or "pixel_mean" not in self.members):
            run = self.stats(pixels=True)
            return None if run.pixel_sum is None else shrink(run.pixel_sum, PREVIEW_SIDE)
        self.version()
        meta = self.meta()
        height, width, channels = (meta[k] for k in ("height", "width", "channels"))
        if "preview_sum" not in self.members:  # a small image's pixel sum, from its pixels' means alone
            n = len(self.array("seeds", "iu", None))
            return summed_means(self.array("pixel_mean", "f", (height, width, channels)), n)
        factor = -(-max(height, width) // PREVIEW_SIDE)
        return self.array("preview_sum", "f", (height // factor, width // factor, channels))

    def stats(self, pixels: bool = True, moments: bool = True) -> TileStats:
        version = self.version()
        meta = self.meta()
        height, width, tile, channels = (meta[k] for k in ("height", "width", "tile", "channels"))
        edges = "partial" if version >= EDGES_VERSION else "dropped"
        if meta.get("edges", "dropped") != edges:
            raise self.fail(f"metadata 'edges' must be {edges!r} in a version {version} file")
        try:
            info = RunInfo.from_json(meta["info"])
            grid = TileStats(height, width, tile, channels, info, keep_mean_image=False, edges=edges).grid_shape
        except (WelchInputError, TypeError) as exc:
            raise self.fail(str(exc)) from None
        seeds = self.array("seeds", "iu", None)
        if seeds.ndim != 1:
            raise self.fail(f"'seeds' must be one-dimensional, got shape {seeds.shape}")
        if len(seeds) and (seeds.min() < 0 or seeds.max() > MAX_SEED_VALUE):
            raise self.fail(f"'seeds' must lie in 0..{MAX_SEED_VALUE}")
        if len(np.unique(seeds)) != len(seeds):
            raise self.fail("'seeds' repeats a seed")
        sums = self.array("sums", "f", (len(seeds), *grid))
        self.check_finite(sums, seeds, meta.get("nonfinite_seeds", []))
        pixel_sum = None
        if version == 1:
            if pixels:
                pixel_sum = self.version1_pixel_sum(len(seeds), height, width, channels)
            self.check_version1_moments(sums, grid)
        elif pixels:
            pixel_sum = self.array("pixel_sum", "f", (height, width, channels), required=False)
        kept = self.pixel_moments(len(seeds), (height, width, channels)) if moments and version > 1 else None
        run = TileStats.from_sums(sums, seeds.tolist(), height, width, tile, info, pixel_sum, edges, pixels=kept,
                                  mean_from_pixels=pixels)  # fmt: skip
        self.check_pixel_moments(run)
        return run

    def pixel_moments(self, n: int, shape: tuple) -> PixelMoments | None:
        if "pixel_mean" not in self.members and "pixel_m2" not in self.members:
            return None
        mean, m2 = (self.array(key, "f", shape) for key in ("pixel_mean", "pixel_m2"))
        try:
            return PixelMoments.of(mean, m2, n, names=("'pixel_mean'", "'pixel_m2'"))
        except WelchInputError as exc:
            raise self.fail(str(exc)) from None

    def check_pixel_moments(self, run: TileStats) -> None:
        """The pixel moments must be those of the file's passes (`pixels.moment_conflict`): moments that contradict
        the tile sums (all zeros, another run's) made `compare` report bias between unbiased passes."""
        conflict = moment_conflict(run)
        if conflict is not None:
            raise self.fail(f"{conflict[0]!r} contradicts its tile sums: {conflict[1]}")

    def scalar_or_none(self, key: str, kinds: str):
        try:
            return self.scalar(key, kinds)
        except StatsFileError:
            return None

    def meta(self) -> dict:
        text = self.scalar("meta", "U")
        try:
            meta = json.loads(text, parse_constant=_no_constants)
        except ValueError as exc:
            raise self.fail(f"its metadata is not JSON ({exc})") from None
        if not isinstance(meta, dict):
            raise self.fail("its metadata is not a JSON object")
        for key, limit in (
            ("height", MAX_IMAGE_SIDE),
            ("width", MAX_IMAGE_SIDE),
            ("tile", MAX_IMAGE_SIDE),
            ("channels", 64),
        ):
            value = meta.get(key)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= limit:
                raise self.fail(f"metadata {key!r} must be an integer in 1..{limit}, got {_short(value)}")
        if "info" not in meta:
            raise self.fail("its metadata has no run info")
        nonfinite = meta.get("nonfinite_seeds", [])
        if not isinstance(nonfinite, list) or not all(isinstance(s, int) for s in nonfinite):
            raise self.fail(f"metadata 'nonfinite_seeds' must be a list of integers, got {_short(nonfinite)}")
        return meta

    def check_finite(self, sums: np.ndarray, seeds: np.ndarray, recorded: list[int]) -> None:
        """Non-finite tile sums are legitimate only for passes the file records as such (``--on-nan keep``)."""
        finite = np.isfinite(sums).all(axis=(1, 2, 3))
        found = set(seeds[~finite].tolist())
        if found != set(recorded):
            unexpected = sorted(found - set(recorded))
            if unexpected:
                raise self.fail(f"the pass with seed {unexpected[0]} has non-finite tile sums the file does not record")
            raise self.fail("it records non-finite passes that its sums do not have")

    def version1_pixel_sum(self, n: int, height: int, width: int, channels: int) -> np.ndarray | None:
        image = self.array("mean_image", "f", (height, width, channels), required=False)
        return None if image is None else image.astype(np.float32) * np.float32(n)

    def check_version1_moments(self, sums: np.ndarray, grid: tuple) -> None:
        """Version 1 stored a mean and M2 beside the sums: they must say the same (a mismatch made `compare` report
        bias between identical passes)."""
        mean, m2 = self.array("mean", "f", grid), self.array("m2", "f", grid)
        n = len(sums)
        if n == 0:
            return
        with np.errstate(invalid="ignore", over="ignore"):
            expected_mean = sums.mean(axis=0)
            expected_m2 = ((sums - expected_mean) ** 2).sum(axis=0)
            spread = np.sqrt(expected_m2 / n)
            # Slack for the streaming update that wrote version 1 (rounding, not disagreement).
            mean_ok = np.abs(mean - expected_mean) <= 1e-8 * (np.abs(expected_mean) + spread) + 1e-300
            m2_ok = np.abs(m2 - expected_m2) <= 1e-6 * expected_m2 + 1e-12 * n * expected_mean**2 + 1e-300
        checked = np.isfinite(expected_mean) & np.isfinite(expected_m2)
        if not (mean_ok | ~checked).all() or not (m2_ok | ~checked).all():
            raise self.fail("its stored means or second moments contradict its per-pass sums")


def _no_constants(name: str):
    """JSON has no NaN or Infinity; Python's reader accepts them, and a report written from them would not be JSON."""
    raise ValueError(f"{name} is not a JSON number")


_KIND_WORDS = {"iu": "integers", "f": "floats", "U": "a string", "iufcUSb": "a number"}


def _short(value) -> str:
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    return text if len(text) <= 40 else text[:37] + "..."
