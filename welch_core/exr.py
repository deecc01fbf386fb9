"""OpenEXR files: passes in, maps out.

Uncompressed single-part scanline files (what the renderer writes for every pass, and what this tool writes) are
read and written here with numpy alone: no library is needed inside a stock Blender, every write error reaches
the caller, and a pass is read at memory speed. Anything else (compressed, tiled or multi-part files from other
renderers) is read through the OpenEXR module.

The layout (OpenEXR's "Technical Introduction" and "OpenEXR File Layout"): magic and version, a header of
attributes (name, type, size, value) ended by a null byte, an offset table of one uint64 per chunk, then the
chunks. Uncompressed scanline chunks hold one line: its y (int32), its byte size (int32), then each channel's
values for the line, channels in the (alphabetical) order of the ``channels`` attribute.
"""

from __future__ import annotations

import mmap
import os
import struct
from pathlib import Path

import numpy as np
import numpy.typing as npt

from . import parallel
from .errors import WelchInputError

__all__ = ["read_exr", "read_exr_channels", "read_exr_colour", "write_exr"]

_MAGIC = 20000630
_VERSION = 2
_TILED, _LONG_NAMES, _DEEP, _MULTIPART = 0x200, 0x400, 0x800, 0x1000
_PIXEL_TYPES = {0: "<u4", 1: "<f2", 2: "<f4"}  # UINT, HALF, FLOAT
_PIXEL_NAMES = {0: "UINT", 1: "HALF", 2: "FLOAT"}
_COMPRESSION = ("NONE", "RLE", "ZIPS", "ZIP", "PIZ", "PXR24", "B44", "B44A", "DWAA", "DWAB", "HTJ2K")


class _Foreign(Exception):
    """A valid EXR this reader does not handle (compressed, tiled, multi-part): the OpenEXR module reads it."""


# -- reading -------------------------------------------------------------------------------------------------

#: Rows copied at a time where a pass's channels are interleaved into an H×W×C image: a band of a 4K image's
#: three float planes and its part of the image stay within a core's cache (a copy of the whole planes at once
#: is 2-4x slower, measured at 1920x1080).
BAND_ROWS = 32

#: Bytes read as the header before the whole file is (Blender's and this tool's headers take under 1 KiB).
HEADER_BYTES = 1 << 16


def read_exr_channels(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Every channel of an EXR file as an H×W float32 array, top row first, keyed by channel name.

    Raises WelchInputError (naming the file) for a missing, truncated or foreign file, integer channels,
    subsampled channels or a data window that is not the whole image.
    """
    name = os.fspath(path)
    lines = _mapped_lines(name)
    if lines is None:
        return _read_with_openexr(name)
    rows, names = lines
    return {c: np.ascontiguousarray(rows[f"c{i}"], dtype=np.float32) for i, c in enumerate(names)}


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read the colour of an EXR file as an H×W×3 float32 array, top row first.

    Takes channels R, G, B, else a ``Combined`` layer's ``<layer>.R/G/B`` (Blender's ``ViewLayer.Combined.R``),
    else the first layer (by name) that has R, G and B.
    """
    return read_exr_colour(path)[0]


def read_exr_colour(path: str | os.PathLike) -> tuple[np.ndarray, list[str]]:
    """The colour `read_exr` reads, and the names of every channel of the file (sorted). An uncompressed file's
    colour channels are copied straight from the file's pages into the image, a band of rows at a time: the one
    copy a pass's pixels need."""
    name = os.fspath(path)
    lines = _mapped_lines(name)
    if lines is None:
        channels = _read_with_openexr(name)
        return colour_of(channels, name), sorted(channels)
    rows, names = lines
    keys = _colour_names(names)
    if keys is None:
        raise WelchInputError(f"{name!r} has no R, G, B channels (it has {sorted(names)})")
    fields = [rows[f"c{names.index(k)}"] for k in keys]
    image = np.empty((*fields[0].shape, 3), np.float32)
    for start in range(0, len(image), BAND_ROWS):
        band = slice(start, start + BAND_ROWS)
        for c, field in enumerate(fields):
            image[band, :, c] = field[band]
    return image, sorted(names)


def colour_of(channels: dict[str, np.ndarray], path: str | os.PathLike) -> np.ndarray:
    """The colour `read_exr` takes from an EXR's `channels` (read from `path`, named in the error)."""
    keys = _colour_names(list(channels))
    if keys is None:
        raise WelchInputError(f"{os.fspath(path)!r} has no R, G, B channels (it has {sorted(channels)})")
    return np.stack([channels[k] for k in keys], axis=-1)


def _colour_names(names: list[str]) -> list[str] | None:
    """The channels that hold the colour (see `read_exr`), or None."""
    layers = sorted({k.rsplit(".", 1)[0] + "." for k in names if "." in k})
    # A "Combined" layer before any other (Blender's AO, DiffCol, ... passes sort before it by name).
    for prefix in ["", *sorted(layers, key=lambda layer: not layer.endswith("Combined."))]:
        keys = [prefix + c for c in "RGB"]
        if all(k in names for k in keys):
            return keys
    return None


def _mapped_lines(name: str) -> tuple[np.ndarray, list[str]] | None:
    """The scanlines of an uncompressed single-part file, as a structured array over the file's pages in the
    order top row first (a view, no copy: the file is mapped, not read), with the channel names in their stored
    order; None for a valid EXR this reader does not handle (the OpenEXR module reads it)."""
    try:
        with open(name, "rb") as f:
            data = _map(f)
    except FileNotFoundError:
        raise WelchInputError(f"EXR file {name!r} does not exist") from None
    except OSError as exc:
        raise WelchInputError(f"can't read {name!r}: {exc.strerror or exc}") from None
    try:
        return _parse(name, data)
    except _Foreign:
        return None


def _map(f) -> np.ndarray:
    """The bytes of open file `f` as a read-only uint8 array over its mapped pages (an empty array for an empty
    file): the pixels are copied once, from the page cache into the image, instead of twice."""
    size = os.fstat(f.fileno()).st_size
    if size == 0:
        return np.empty(0, np.uint8)
    if hasattr(mmap, "MAP_POPULATE"):  # Linux: the page table filled in one call, not one fault a page
        mapped = mmap.mmap(f.fileno(), size, flags=mmap.MAP_SHARED | mmap.MAP_POPULATE, prot=mmap.PROT_READ)
    else:
        mapped = mmap.mmap(f.fileno(), size, access=mmap.ACCESS_READ)
    return np.frombuffer(mapped, np.uint8)


def _parse(name: str, data: np.ndarray) -> tuple[np.ndarray, list[str]]:
    if len(data) < 8 or struct.unpack_from("<i", data)[0] != _MAGIC:
        raise WelchInputError(f"{name!r} is not an EXR file")
    flags = struct.unpack_from("<I", data, 4)[0]
    if flags & (_TILED | _DEEP | _MULTIPART):
        raise _Foreign
    try:
        header, pos = _read_header(name, bytes(data[:HEADER_BYTES]), 8)
    except WelchInputError:
        if len(data) <= HEADER_BYTES:
            raise
        header, pos = _read_header(name, bytes(data), 8)  # a header of more than HEADER_BYTES: rare
    try:
        channels = header["channels"]
        compression = header["compression"]
        x0, y0, x1, y1 = header["dataWindow"]
        display = header["displayWindow"]
    except KeyError as exc:
        raise WelchInputError(f"{name!r} is damaged: its header has no {exc.args[0]!r}") from None
    if compression != 0:
        raise _Foreign
    if (x0, y0, x1, y1) != display:
        raise WelchInputError(
            f"{name!r} has a data window {(x0, y0, x1, y1)} that is not the whole image {display}: "
            "passes must cover every pixel"
        )
    for channel, (kind, xs, ys) in channels.items():
        if kind == 0:
            raise WelchInputError(f"{name!r}: channel {channel!r} holds integers (UINT); a pass must be float radiance")
        if (xs, ys) != (1, 1):
            raise WelchInputError(f"{name!r}: channel {channel!r} is subsampled ({xs}x{ys}); passes need every pixel")
    width, height = x1 - x0 + 1, y1 - y0 + 1
    if width < 1 or height < 1:
        raise WelchInputError(f"{name!r} has an empty data window {(x0, y0, x1, y1)}")
    names = list(channels)  # alphabetical, as stored
    line = np.dtype(
        [("y", "<i4"), ("size", "<i4")]
        + [(f"c{i}", _PIXEL_TYPES[channels[c][0]], (width,)) for i, c in enumerate(names)]
    )
    first = pos + 8 * height  # after the offset table
    if len(data) < first:
        raise WelchInputError(f"{name!r} is truncated ({len(data)} bytes, the offset table alone ends at {first})")
    offsets = np.frombuffer(data, "<u8", height, pos)
    expected = first + line.itemsize * np.arange(height, dtype=np.uint64)
    if not np.array_equal(offsets, expected):
        # Lines stored out of order or padded: valid, but not the layout this reader expects.
        raise _Foreign
    end = first + line.itemsize * height
    if len(data) < end:
        raise WelchInputError(f"{name!r} is truncated: {len(data)} bytes, {end} expected for {width}x{height}")
    lines = np.frombuffer(data, line, height, first)
    if not (lines["size"] == line.itemsize - 8).all():
        raise WelchInputError(f"{name!r} is damaged: a line's byte count does not match its channels")
    ys = lines["y"]
    if np.array_equal(ys, np.arange(y0, y1 + 1)):  # top row first, as every writer here stores them: a view
        return lines, names
    order = np.argsort(ys, kind="stable")
    if not np.array_equal(ys[order], np.arange(y0, y1 + 1)):
        raise WelchInputError(f"{name!r} is damaged: its lines do not cover rows {y0}..{y1}")
    return lines[order], names


def _read_header(name: str, data: bytes, pos: int) -> tuple[dict, int]:
    """The attributes this reader needs, and the position after the header."""
    header: dict = {}
    try:
        while data[pos] != 0:
            attr, pos = _cstring(data, pos)
            kind, pos = _cstring(data, pos)
            (size,) = struct.unpack_from("<i", data, pos)
            pos += 4
            value = data[pos : pos + size]
            if size < 0 or len(value) != size:
                raise IndexError
            pos += size
            if kind == "chlist":
                header[attr] = _channel_list(value)
            elif kind == "compression":
                header[attr] = value[0]
            elif kind == "box2i":
                header[attr] = struct.unpack("<4i", value)
    except (IndexError, struct.error, UnicodeDecodeError):
        raise WelchInputError(f"{name!r} is truncated or damaged: its header does not parse") from None
    return header, pos + 1


def _cstring(data: bytes, pos: int) -> tuple[str, int]:
    end = data.index(b"\0", pos)
    return data[pos:end].decode("utf-8"), end + 1


def _channel_list(value: bytes) -> dict[str, tuple[int, int, int]]:
    channels, pos = {}, 0
    while value[pos] != 0:
        channel, pos = _cstring(value, pos)
        kind, _linear, xs, ys = struct.unpack_from("<iB3xii", value, pos)
        if kind not in _PIXEL_TYPES:
            raise IndexError
        channels[channel] = (kind, xs, ys)
        pos += 16
    return channels


def _read_with_openexr(name: str) -> dict[str, np.ndarray]:
    try:
        import OpenEXR
    except ImportError:
        raise WelchInputError(
            f"{name!r} is compressed, tiled or multi-part: reading it needs the OpenEXR module (pip install OpenEXR)"
        ) from None
    try:
        # Decoded on every core: a ZIP-compressed 1920x1080 pass takes 0.1 s on one (the module's default).
        parts = OpenEXR.File(name, separate_channels=True, num_threads=parallel.cores()).parts
    except Exception as exc:  # OpenEXR raises bare RuntimeError/Exception for damaged files
        raise WelchInputError(f"{name!r} is not a readable EXR file ({exc})") from None
    # The part that has colour: plain or Combined RGB before any other (a multi-part file may keep it anywhere).
    for part in sorted(parts, key=lambda p: not _has_colour(p.channels)):
        header = part.header
        window, display = header.get("dataWindow"), header.get("displayWindow")
        if (
            window is not None
            and display is not None
            and not all(np.array_equal(a, b) for a, b in zip(window, display, strict=True))
        ):
            raise WelchInputError(
                f"{name!r} has a data window that is not the whole image: passes must cover every pixel"
            )
        out = {}
        for channel, values in part.channels.items():
            pixels = np.asarray(values.pixels)
            if not np.issubdtype(pixels.dtype, np.floating):
                raise WelchInputError(f"{name!r}: channel {channel!r} holds integers; a pass must be float radiance")
            out[channel] = pixels.astype(np.float32, copy=False)
        return out
    raise WelchInputError(f"{name!r} has no parts")


def _has_colour(channels) -> bool:
    return all(c in channels for c in "RGB") or any(k.endswith("Combined.R") for k in channels)


# -- writing -------------------------------------------------------------------------------------------------


def write_exr(path: str | os.PathLike, image: npt.ArrayLike) -> None:
    """Write an H×W or H×W×C (C in 1, 3, 4) float array as an uncompressed 32-bit float EXR, atomically.

    A failed write (a full disk) raises OSError and leaves any previous file in place.
    """
    from .formats import atomic_write  # the one way files are written

    data = exr_bytes(image)
    atomic_write(Path(path), lambda f: f.write(data))


def exr_bytes(image: npt.ArrayLike) -> bytes:
    """The uncompressed 32-bit float EXR of an H×W or H×W×C (C in 1, 3, 4) float array, as bytes."""
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[2] not in (1, 3, 4) or 0 in img.shape:
        raise WelchInputError(f"`image` must be H×W or H×W×(1, 3 or 4), got shape {np.shape(image)}")
    names = ["Y"] if img.shape[2] == 1 else list("RGBA"[: img.shape[2]])
    return exr_channels_bytes({n: img[..., i] for i, n in enumerate(names)})


def write_exr_channels(path: str | os.PathLike, channels: dict[str, np.ndarray]) -> None:
    """Write named H×W channels as an uncompressed 32-bit float scanline EXR, atomically."""
    from .formats import atomic_write  # the one way files are written

    data = exr_channels_bytes(channels)
    atomic_write(Path(path), lambda f: f.write(data))


def exr_channels_bytes(channels: dict[str, np.ndarray]) -> bytes:
    """Named H×W channels as an uncompressed 32-bit float scanline EXR, as bytes."""
    names = sorted(channels)
    planes = [np.asarray(channels[n], dtype="<f4") for n in names]
    height, width = planes[0].shape
    chlist = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for n in names) + b"\0"
    window = struct.pack("<4i", 0, 0, width - 1, height - 1)
    attributes = [
        ("channels", "chlist", chlist),
        ("compression", "compression", b"\0"),
        ("dataWindow", "box2i", window),
        ("displayWindow", "box2i", window),
        ("lineOrder", "lineOrder", b"\0"),
        ("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        ("screenWindowCenter", "v2f", struct.pack("<2f", 0.0, 0.0)),
        ("screenWindowWidth", "float", struct.pack("<f", 1.0)),
    ]
    flags = _LONG_NAMES if any(len(n) > 31 for n in names) else 0
    header = struct.pack("<iI", _MAGIC, _VERSION | flags)
    header += b"".join(
        a.encode() + b"\0" + t.encode() + b"\0" + struct.pack("<i", len(v)) + v for a, t, v in attributes
    )
    header += b"\0"
    line = np.dtype([("y", "<i4"), ("size", "<i4")] + [(f"c{i}", "<f4", (width,)) for i in range(len(names))])
    lines = np.empty(height, line)
    lines["y"] = np.arange(height)
    lines["size"] = line.itemsize - 8
    for i, plane in enumerate(planes):
        lines[f"c{i}"] = plane
    first = len(header) + 8 * height
    offsets = (first + line.itemsize * np.arange(height)).astype("<u8")
    return header + offsets.tobytes() + lines.tobytes()
