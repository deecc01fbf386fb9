"""EXR files (welch_core.exr): the numpy reader and writer of uncompressed scanline files, checked against the
OpenEXR library as an independent oracle, and the OpenEXR path for everything else."""

import os
import re

import numpy as np
import OpenEXR
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from welch_core import WelchInputError, read_exr, write_exr
from welch_core.exr import read_exr_channels, write_exr_channels


def header(compression=OpenEXR.NO_COMPRESSION, **extra):
    """A fresh header each time: OpenEXR.File adds the data window to the dict it is given."""
    return {"compression": compression, "type": OpenEXR.scanlineimage, **extra}


def test_round_trip_top_row_first(tmp_path):
    rng = np.random.default_rng(4)
    img = rng.uniform(0, 10, size=(5, 7, 3)).astype(np.float32)
    img[0] = 100.0  # the top row is recognisable
    path = tmp_path / "pass.exr"
    write_exr(path, img)
    back = read_exr(path)
    assert back.dtype == np.float32 and back.shape == (5, 7, 3)
    assert_array_equal(back, img)
    assert sorted(os.listdir(tmp_path)) == ["pass.exr"]
    # OpenEXR's own reader agrees about everything: a valid uncompressed file, top row first
    exr = OpenEXR.File(str(path), separate_channels=True)
    assert exr.header()["compression"] == OpenEXR.NO_COMPRESSION
    assert_array_equal(exr.channels()["R"].pixels, img[..., 0])
    assert_array_equal(exr.channels()["B"].pixels[0], np.full(7, 100.0, dtype=np.float32))


def test_numpy_reader_equals_openexr_on_its_files(tmp_path):
    """Uncompressed files written by the OpenEXR library, FLOAT and HALF, any channel set: same pixels."""
    rng = np.random.default_rng(1)
    channels = {
        "ViewLayer.Combined.R": rng.normal(size=(9, 13)).astype(np.float32),
        "ViewLayer.Combined.G": rng.normal(size=(9, 13)).astype(np.float32),
        "ViewLayer.Combined.B": rng.normal(size=(9, 13)).astype(np.float32),
        "ViewLayer.Diffuse Direct.R": rng.normal(size=(9, 13)).astype(np.float16),
        "Z": rng.normal(size=(9, 13)).astype(np.float32),
    }
    path = tmp_path / "layers.exr"
    OpenEXR.File(header(), dict(channels)).write(str(path))  # it replaces the dict's arrays with its own objects
    ours = read_exr_channels(path)
    assert sorted(ours) == sorted(channels)
    for name, pixels in channels.items():
        assert ours[name].dtype == np.float32
        assert_array_equal(ours[name], pixels.astype(np.float32))


def test_rgba_and_single_channel(tmp_path):
    rng = np.random.default_rng(5)
    rgba = rng.uniform(size=(4, 6, 4)).astype(np.float32)
    write_exr(tmp_path / "rgba.exr", rgba)
    assert_array_equal(read_exr(tmp_path / "rgba.exr"), rgba[..., :3])
    pmap = rng.uniform(size=(4, 6))
    write_exr(tmp_path / "p.exr", pmap)
    channels = OpenEXR.File(str(tmp_path / "p.exr"), separate_channels=True).channels()
    assert list(channels) == ["Y"]
    assert_array_equal(channels["Y"].pixels, pmap.astype(np.float32))
    msg = "`image` must be H×W or H×W×(1, 3 or 4), got shape (4, 6, 2)"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        write_exr(tmp_path / "bad.exr", np.zeros((4, 6, 2)))


def test_long_channel_names(tmp_path):
    name = "ViewLayer." + "x" * 40 + ".R"  # more than 31 characters: the long-names flag
    write_exr_channels(tmp_path / "long.exr", {name: np.ones((2, 3), np.float32)})
    assert list(OpenEXR.File(str(tmp_path / "long.exr")).channels()) == [name]
    assert list(read_exr_channels(tmp_path / "long.exr")) == [name]


def test_compressed_files_go_through_openexr(tmp_path):
    rng = np.random.default_rng(6)
    h, w = 6, 9
    rgb = rng.uniform(size=(h, w, 3)).astype(np.float32)
    ao = np.full((h, w), 7.0, dtype=np.float32)
    channels = {f"ViewLayer.Combined.{c}": np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    channels["ViewLayer.Combined.A"] = np.ones((h, w), dtype=np.float32)
    channels.update({f"ViewLayer.AO.{c}": ao for c in "RGB"})  # "AO" sorts before "Combined"
    path = tmp_path / "multilayer.exr"
    OpenEXR.File(header(OpenEXR.ZIP_COMPRESSION), channels).write(str(path))
    assert_array_equal(read_exr(path), rgb)
    half = {f"layer.{c}": np.ascontiguousarray(rgb[..., i]).astype(np.float16) for i, c in enumerate("RGB")}
    OpenEXR.File(header(OpenEXR.ZIP_COMPRESSION), half).write(str(tmp_path / "half.exr"))
    back = read_exr(tmp_path / "half.exr")
    assert back.dtype == np.float32
    assert_allclose(back, rgb, rtol=1e-3)


def test_multipart_file_with_the_colour_in_another_part(tmp_path):
    z = np.zeros((3, 4), np.float32)
    depth = OpenEXR.Part(header(name="depth"), {"Z": z}, "depth")
    beauty = OpenEXR.Part(header(name="beauty"), {"R": z + 1, "G": z + 2, "B": z + 3}, "beauty")
    OpenEXR.File([depth, beauty]).write(str(tmp_path / "parts.exr"))
    assert_array_equal(read_exr(tmp_path / "parts.exr")[0, 0], [1, 2, 3])


def test_without_rgb(tmp_path):
    path = tmp_path / "depth.exr"
    z = np.zeros((3, 3), dtype=np.float32)
    OpenEXR.File(header(), {"Z": z, "ViewLayer.Combined.R": z}).write(str(path))
    msg = f"{str(path)!r} has no R, G, B channels (it has ['ViewLayer.Combined.R', 'Z'])"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        read_exr(path)


def test_offset_data_window_is_refused_with_the_reason(tmp_path):
    z = np.zeros((3, 4), np.float32)
    window = header(dataWindow=(np.array([2, 1], np.int32), np.array([5, 3], np.int32)))
    window["displayWindow"] = (np.array([0, 0], np.int32), np.array([9, 9], np.int32))
    path = tmp_path / "window.exr"
    OpenEXR.File(window, {"R": z, "G": z, "B": z}).write(str(path))
    msg = f"{str(path)!r} has a data window (2, 1, 5, 3) that is not the whole image (0, 0, 9, 9): passes must cover"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        read_exr(path)


def test_integer_channels_are_refused(tmp_path):
    u = np.zeros((3, 4), np.uint32)
    path = tmp_path / "uint.exr"
    OpenEXR.File(header(), {"R": u, "G": u, "B": u}).write(str(path))
    msg = f"{str(path)!r}: channel 'B' holds integers (UINT); a pass must be float radiance"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        read_exr(path)


def test_truncated_missing_or_not_exr(tmp_path):
    path = tmp_path / "missing.exr"
    with pytest.raises(WelchInputError, match=re.escape(f"EXR file {str(path)!r} does not exist")):
        read_exr(path)
    text = tmp_path / "text.exr"
    text.write_text("this is not an EXR file")
    with pytest.raises(WelchInputError, match=re.escape(f"{str(text)!r} is not an EXR file")):
        read_exr(text)
    good = tmp_path / "good.exr"
    write_exr(good, np.ones((16, 16, 3), np.float32))
    data = good.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[:-100])  # a pass written to a full disk
    with pytest.raises(WelchInputError, match=re.escape(f"{str(cut)!r} is truncated: {len(data) - 100} bytes,")):
        read_exr(cut)
    cut.write_bytes(data[:40])
    with pytest.raises(WelchInputError, match=re.escape(f"{str(cut)!r} is truncated or damaged")):
        read_exr(cut)
    cut.write_bytes(b"")
    with pytest.raises(WelchInputError, match=re.escape(f"{str(cut)!r} is not an EXR file")):
        read_exr(cut)


def test_a_failed_write_keeps_the_previous_file(tmp_path, monkeypatch):
    path = tmp_path / "map.exr"
    write_exr(path, np.ones((4, 4, 3)))
    good = path.read_bytes()

    def full_disk(*_args, **_kw):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(OSError, match="No space left on device"):
        write_exr(path, np.zeros((4, 4, 3)))
    assert path.read_bytes() == good and os.listdir(tmp_path) == ["map.exr"]


def test_the_colour_is_read_in_any_line_order_and_half_channels_too(tmp_path):
    """`read_exr` copies the colour straight from the file's pages a band of rows at a time: HALF channels, one
    row and more rows than a band give OpenEXR's pixels, top row first; lines stored bottom row first too (the
    OpenEXR module reads those)."""
    from welch_core.exr import BAND_ROWS, read_exr_colour

    rng = np.random.default_rng(8)
    for height, order in ((BAND_ROWS * 2 + 5, OpenEXR.DECREASING_Y), (1, OpenEXR.INCREASING_Y)):
        rgb = rng.uniform(size=(height, 11, 3)).astype(np.float32)
        channels = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
        channels["A"] = np.ones((height, 11), np.float16)
        path = tmp_path / f"order{height}.exr"
        OpenEXR.File(header(lineOrder=order), channels).write(str(path))
        image, names = read_exr_colour(path)
        assert_array_equal(image, rgb)
        assert names == ["A", "B", "G", "R"] and image.flags.c_contiguous and image.flags.writeable
    half = {f"ViewLayer.Combined.{c}": rng.uniform(size=(40, 9)).astype(np.float16) for c in "RGB"}
    OpenEXR.File(header(), dict(half)).write(str(tmp_path / "half.exr"))
    expected = np.stack([half[f"ViewLayer.Combined.{c}"] for c in "RGB"], axis=-1).astype(np.float32)
    assert_array_equal(read_exr(tmp_path / "half.exr"), expected)
