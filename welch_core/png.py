"""PNG images with numpy and zlib alone: the report's pictures, without an imaging library on the path.

An 8-bit RGB or RGBA image, or an image of indices into a palette of colours, is written as the PNG
specification's simplest valid file: signature, IHDR, PLTE for a palette image, one IDAT with every row filtered
by the "none" filter, IEND (W3C PNG, 2nd edition, sections 5, 11.2.3 and 11).
"""

from __future__ import annotations

import base64
import os
import struct
import zlib

import numpy as np
import numpy.typing as npt

from .errors import WelchInputError

__all__ = ["data_url", "png_bytes", "to_uint8", "write_png"]

_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def to_uint8(rgb: npt.ArrayLike) -> np.ndarray:
    """Display values in [0, 1] (NaN as 0) to 8-bit, rounded."""
    scaled = np.asarray(rgb, dtype=np.float32) * np.float32(255.0)
    scaled += np.float32(0.5)
    # clip(values, 0, 1) x 255 + 0.5, NaN as 0: the same numbers in three passes over the image, not six
    np.fmax(scaled, np.float32(0.5), out=scaled)  # fmax: NaN becomes 0.5, which rounds to 0
    np.minimum(scaled, np.float32(255.5), out=scaled)
    return scaled.astype(np.uint8)


#: `fast`: Huffman coding (about 15 ns a byte) is worth its time where it saves at least this share of the bytes;
#: with the "none" filter it codes each byte alone, so the bytes' entropy says what it can save.
FAST_MIN_SAVING = 0.25


def png_bytes(image: npt.ArrayLike, fast: bool = False, palette: npt.ArrayLike | None = None) -> bytes:
    """The PNG file of an H×W×3 or H×W×4 uint8 image (top row first), or, with a `palette` (N×3 colours in [0, 1],
    N <= 256), of an H×W uint8 image of indices into it. `fast` skips zlib's search for repeated strings (a third
    of the time, and on noisy renders, with little to repeat, as small: measured within 1 %), and stores the bytes
    uncompressed where Huffman coding alone would save less than `FAST_MIN_SAVING` of them (a render's mean: 9-16 %
    at 1024x576, for 27-35 ms a picture)."""
    img = np.asarray(image)
    if palette is not None:
        colours = to_uint8(palette)
        if colours.ndim != 2 or colours.shape[1] != 3 or not 0 < len(colours) <= 256:
            raise WelchInputError(f"`palette` must be N×3 colours, 1 <= N <= 256, got shape {colours.shape}")
        if img.dtype != np.uint8 or img.ndim != 2 or 0 in img.shape:
            raise WelchInputError(
                f"`image` must be a non-empty H×W uint8 array of indices, got {img.dtype} {img.shape}"
            )
        if int(img.max()) >= len(colours):
            raise WelchInputError(f"`image` holds index {int(img.max())}, beyond the palette's {len(colours)} colours")
        img = img[..., None]
    elif img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (3, 4) or 0 in img.shape:
        raise WelchInputError(f"`image` must be a non-empty H×W×3 or H×W×4 uint8 array, got {img.dtype} {img.shape}")
    height, width, channels = img.shape
    rows = np.empty((height, 1 + width * channels), np.uint8)
    rows[:, 0] = 0  # filter type "none" for every scanline
    rows[:, 1:] = img.reshape(height, width * channels)
    colour_type = 3 if palette is not None else 6 if channels == 4 else 2
    header = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    if not fast:
        packer = zlib.compressobj(6)
    elif _huffman_saving(rows) >= FAST_MIN_SAVING:
        packer = zlib.compressobj(1, strategy=zlib.Z_HUFFMAN_ONLY)
    else:
        packer = zlib.compressobj(0)  # stored: a copy
    data = packer.compress(rows.tobytes()) + packer.flush()
    chunks = [_chunk(b"IHDR", header)] + ([_chunk(b"PLTE", colours.tobytes())] if palette is not None else [])
    return b"".join((_SIGNATURE, *chunks, _chunk(b"IDAT", data), _chunk(b"IEND", b"")))


def data_url(image: npt.ArrayLike, palette: npt.ArrayLike | None = None) -> str:
    """A picture for a page: the `fast` PNG of `image` (display values in [0, 1], H×W×3; or, with a `palette`, its
    uint8 indices) as a base64 data URL."""
    data = png_bytes(image if palette is not None else to_uint8(image), fast=True, palette=palette)
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def write_png(path: str | os.PathLike, image: npt.ArrayLike) -> None:
    """Write `image` (see `png_bytes`) atomically."""
    from .formats import atomic_write  # the one way files are written

    data = png_bytes(image)
    atomic_write(path, lambda f: f.write(data))


def _huffman_saving(rows: np.ndarray) -> float:
    """The share of the bytes a code of each byte alone saves at best: 1 - entropy / 8 bits, estimated on every
    `_SAMPLED_ROWS`-th row (a count of every byte took 10 ms at 1024x576)."""
    sample = rows[::_SAMPLED_ROWS].reshape(-1)
    counts = np.bincount(sample, minlength=256)
    p = counts[counts > 0] / sample.size
    return float(1.0 + (p * np.log2(p)).sum() / 8.0)


_SAMPLED_ROWS = 4


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
