"""Statistics files, EXR and PFM (welch_core.formats)."""

import os
import re

import numpy as np
import OpenEXR
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from welch_core import (
    RunInfo,
    StatsFileError,
    TileStats,
    WelchInputError,
    load_stats,
    read_exr,
    read_pfm,
    save_stats,
    write_exr,
    write_pfm,
    write_tile_pfms,
)
from welch_core.formats import FORMAT_NAME, FORMAT_VERSION


def make_run(seed=0, n=4, height=24, width=40, tile=8, info=None):
    rng = np.random.default_rng(seed)
    run = TileStats(height, width, tile, info=info)
    for i in range(n):
        run.add_pass(rng.exponential(size=(height, width, 4)).astype(np.float32), 1000 + 7 * i)
    return run


def good_arrays(run, directory):
    """The arrays of a valid file, to build damaged variants from."""
    path = directory / "good.npz"
    save_stats(path, run)
    with np.load(path, allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


# -- statistics files --------------------------------------------------------------------------------------


def test_save_load_round_trip(tmp_path):
    info = RunInfo(
        spp=16,
        renderer="cycles",
        renderer_version="5.0.1",
        device="CPU",
        sampling_pattern="tabulated_sobol",
        scene="corner.blend",
        settings={"max_bounces": 12, "filter": "gaussian", "clamp": [0.0, 10.0]},
        settings_hash="0123abcd",
        overrides=("max_bounces=12",),
    )
    run = make_run(info=info)
    path = tmp_path / "run.npz"
    save_stats(path, run)
    back = load_stats(path)
    assert (back.height, back.width, back.tile, back.channels) == (24, 40, 8, 3)
    assert back.info == info
    assert back.seeds == run.seeds == [1000, 1007, 1014, 1021]
    assert back.n == 4
    assert_array_equal(back.sums, run.sums)
    assert_array_equal(back.mean, run.mean)
    assert_array_equal(back.m2, run.m2)
    assert_array_equal(back.variance, run.variance)
    assert_array_equal(back.mean_image, run.mean_image)
    # the loaded run keeps accumulating and merging like the original
    rng = np.random.default_rng(1)
    img = rng.exponential(size=(24, 40, 3)).astype(np.float32)
    run.add_pass(img, 5)
    back.add_pass(img, 5)
    assert_allclose(back.mean, run.mean, rtol=1e-14)
    assert_allclose(back.m2, run.m2, rtol=1e-14)
    assert_allclose(back.mean_image, run.mean_image, rtol=1e-6)


def test_round_trip_without_mean_image_and_empty(tmp_path):
    sums = np.random.default_rng(2).normal(size=(3, 2, 3, 3))
    run = TileStats.from_sums(sums, [5, 6, 7], 16, 24, 8)
    save_stats(tmp_path / "a.npz", run)
    back = load_stats(tmp_path / "a.npz")
    assert back.mean_image is None
    assert_array_equal(back.sums, sums)
    empty = TileStats(16, 24, 8)
    save_stats(tmp_path / "b.npz", empty)
    back = load_stats(str(tmp_path / "b.npz"))
    assert back.n == 0 and back.sums.shape == (0, 2, 3, 3)


def test_file_never_holds_pickles(tmp_path):
    save_stats(tmp_path / "run.npz", make_run())
    with np.load(tmp_path / "run.npz", allow_pickle=False) as data:
        assert data["format"] == FORMAT_NAME and int(data["version"]) == FORMAT_VERSION
        for key in data.files:
            assert data[key].dtype != object


def test_atomic_write_leaves_no_temp_file(tmp_path):
    run = make_run()
    path = tmp_path / "run.npz"
    save_stats(path, run)
    save_stats(path, run)  # overwrite
    assert sorted(os.listdir(tmp_path)) == ["run.npz"]


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    run = make_run()
    path = tmp_path / "run.npz"
    save_stats(path, run)
    good = path.read_bytes()

    def broken_savez(f, **arrays):
        f.write(b"PK\x03\x04 partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", broken_savez)
    msg = f"can't write statistics file {str(path)!r}: No space left on device"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        save_stats(path, make_run(seed=3))
    assert path.read_bytes() == good
    assert sorted(os.listdir(tmp_path)) == ["run.npz"]


def test_write_into_missing_directory(tmp_path):
    path = tmp_path / "missing" / "run.npz"
    msg = f"can't write statistics file {str(path)!r}: No such file or directory"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        save_stats(path, make_run())


def test_load_truncated_file(tmp_path):
    path = tmp_path / "run.npz"
    save_stats(path, make_run())
    data = path.read_bytes()
    for keep in (len(data) // 2, len(data) - 10, 3):
        path.write_bytes(data[:keep])
        with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} is not a readable statistics file (")):
            load_stats(path)
    path.write_bytes(b"")
    with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} is not a readable statistics file (")):
        load_stats(path)


def test_load_foreign_files(tmp_path):
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, image=np.zeros((4, 4)), labels=np.arange(3))
    with pytest.raises(StatsFileError, match=re.escape(f"{str(foreign)!r} is not a welch-bias-stats file")):
        load_stats(foreign)
    npy = tmp_path / "array.npy"
    np.save(npy, np.arange(5))
    with pytest.raises(StatsFileError, match=re.escape(f"{str(npy)!r} is not a welch-bias-stats file")):
        load_stats(npy)
    text = tmp_path / "notes.txt"
    text.write_text("seeds: 1, 2, 3\n")
    with pytest.raises(StatsFileError, match=re.escape(f"{str(text)!r} is not a readable statistics file (")):
        load_stats(text)


def test_load_never_unpickles(tmp_path):
    path = tmp_path / "pickled.npz"
    np.savez(path, format=np.array(FORMAT_NAME), version=np.array(1), meta=np.array([{"x": 1}], dtype=object))
    msg = f"{str(path)!r} is not a readable statistics file (ValueError: Object arrays cannot be loaded"
    with pytest.raises(StatsFileError, match=re.escape(msg)):
        load_stats(path)
    pickle_file = tmp_path / "object.npy"
    np.save(pickle_file, np.array([{"x": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(StatsFileError, match=re.escape(f"{str(pickle_file)!r} is not a readable statistics file")):
        load_stats(pickle_file)


def test_load_wrong_version(tmp_path):
    arrays = good_arrays(make_run(), tmp_path)
    path = tmp_path / "v2.npz"
    np.savez(path, **(arrays | {"version": np.array(2)}))
    msg = f"{str(path)!r} has format version 2; this tool reads version 1"
    with pytest.raises(StatsFileError, match=re.escape(msg)):
        load_stats(path)
    del arrays["version"]
    np.savez(path, **arrays)
    with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} has format version -1;")):
        load_stats(path)


def test_load_damaged_contents(tmp_path):
    arrays = good_arrays(make_run(), tmp_path)
    path = tmp_path / "damaged.npz"
    variants = [
        {k: v for k, v in arrays.items() if k != "sums"},
        arrays | {"meta": np.array("{not json")},
        arrays | {"mean": arrays["mean"][:1]},
        arrays | {"seeds": np.array([1, 1, 2, 3])},
        arrays | {"mean_image": arrays["mean_image"][:5]},
    ]
    for variant in variants:
        np.savez(path, **variant)
        with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} is damaged: ")):
            load_stats(path)


def test_load_missing_path(tmp_path):
    path = tmp_path / "nothing.npz"
    with pytest.raises(StatsFileError, match=re.escape(f"statistics file {str(path)!r} does not exist")):
        load_stats(path)
    with pytest.raises(StatsFileError, match=re.escape(f"{str(tmp_path)!r} is not a readable statistics file")):
        load_stats(tmp_path)


# -- EXR ---------------------------------------------------------------------------------------------------


def test_exr_round_trip_top_row_first(tmp_path):
    rng = np.random.default_rng(4)
    img = rng.uniform(0, 10, size=(5, 7, 3)).astype(np.float32)
    img[0] = 100.0  # the top row is recognisable
    path = tmp_path / "pass.exr"
    write_exr(path, img)
    back = read_exr(path)
    assert back.dtype == np.float32 and back.shape == (5, 7, 3)
    assert_array_equal(back, img)
    assert (back[0] == 100.0).all() and (back[1:] < 10).all()
    assert sorted(os.listdir(tmp_path)) == ["pass.exr"]
    # OpenEXR's own reader agrees about the orientation
    channels = OpenEXR.File(str(path), separate_channels=True).channels()
    assert_array_equal(channels["R"].pixels[0], np.full(7, 100.0, dtype=np.float32))


def test_exr_rgba_and_single_channel(tmp_path):
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


def test_exr_layer_prefixed_channels(tmp_path):
    rng = np.random.default_rng(6)
    h, w = 6, 9
    rgb = rng.uniform(size=(h, w, 3)).astype(np.float32)
    ao = np.full((h, w), 7.0, dtype=np.float32)
    channels = {f"ViewLayer.Combined.{c}": np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    channels["ViewLayer.Combined.A"] = np.ones((h, w), dtype=np.float32)
    channels.update({f"ViewLayer.AO.{c}": ao for c in "RGB"})  # "AO" sorts before "Combined"
    channels["ViewLayer.Depth.Z"] = ao
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    path = tmp_path / "multilayer.exr"
    OpenEXR.File(header, channels).write(str(path))
    assert_array_equal(read_exr(path), rgb)
    # half floats are read as float32
    half = {f"layer.{c}": np.ascontiguousarray(rgb[..., i]).astype(np.float16) for i, c in enumerate("RGB")}
    OpenEXR.File(header, half).write(str(tmp_path / "half.exr"))
    back = read_exr(tmp_path / "half.exr")
    assert back.dtype == np.float32
    assert_allclose(back, rgb, rtol=1e-3)


def test_exr_without_rgb(tmp_path):
    path = tmp_path / "depth.exr"
    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    z = np.zeros((3, 3), dtype=np.float32)
    OpenEXR.File(header, {"Z": z, "ViewLayer.Combined.R": z}).write(str(path))
    msg = f"{str(path)!r} has no R, G, B channels (it has ['ViewLayer.Combined.R', 'Z'])"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        read_exr(path)


def test_exr_missing_or_not_exr(tmp_path):
    path = tmp_path / "missing.exr"
    with pytest.raises(WelchInputError, match=re.escape(f"EXR file {str(path)!r} does not exist")):
        read_exr(path)
    text = tmp_path / "text.exr"
    text.write_text("this is not an EXR file")
    with pytest.raises(WelchInputError, match=re.escape(f"{str(text)!r} is not a readable EXR file (")):
        read_exr(text)


# -- PFM ---------------------------------------------------------------------------------------------------


def test_pfm_round_trip(tmp_path):
    rng = np.random.default_rng(7)
    rgb = rng.normal(size=(5, 4, 3)).astype(np.float32)
    write_pfm(tmp_path / "a.pfm", rgb)
    assert_array_equal(read_pfm(tmp_path / "a.pfm"), rgb)
    grey = rng.normal(size=(3, 8))
    write_pfm(tmp_path / "b.pfm", grey)
    back = read_pfm(tmp_path / "b.pfm")
    assert back.shape == (3, 8) and back.dtype == np.float32
    assert_array_equal(back, grey.astype(np.float32))
    assert sorted(os.listdir(tmp_path)) == ["a.pfm", "b.pfm"]


def test_pfm_bytes_on_disk_bottom_row_first(tmp_path):
    img = np.arange(2 * 3 * 3, dtype=np.float32).reshape(2, 3, 3)  # row 0 = 0..8, row 1 = 9..17
    write_pfm(tmp_path / "a.pfm", img)
    raw = (tmp_path / "a.pfm").read_bytes()
    header = b"PF\n3 2\n-1.0\n"
    assert raw.startswith(header)
    pixels = np.frombuffer(raw[len(header) :], dtype="<f4")
    assert_array_equal(pixels, np.concatenate([np.arange(9, 18), np.arange(0, 9)]).astype(np.float32))


def test_pfm_big_endian_is_read(tmp_path):
    img = np.array([[1.5, 2.5], [3.5, 4.5]], dtype=np.float32)
    (tmp_path / "be.pfm").write_bytes(b"Pf\n2 2\n1.0\n" + img[::-1].astype(">f4").tobytes())
    assert_array_equal(read_pfm(tmp_path / "be.pfm"), img)


def test_pfm_bad_files(tmp_path):
    (tmp_path / "short.pfm").write_bytes(b"PF\n4 4\n-1.0\n" + b"\0" * 20)
    msg = f"{str(tmp_path / 'short.pfm')!r} is truncated: 20 bytes of pixel data, expected 192"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        read_pfm(tmp_path / "short.pfm")
    (tmp_path / "p6.pfm").write_bytes(b"P6\n4 4\n255\n" + b"\0" * 48)
    with pytest.raises(WelchInputError, match=re.escape("is not a PFM file (header b'P6')")):
        read_pfm(tmp_path / "p6.pfm")
    (tmp_path / "junk.pfm").write_bytes(b"PF\nfour four\n-1.0\n")
    with pytest.raises(WelchInputError, match=re.escape("is not a readable PFM file (")):
        read_pfm(tmp_path / "junk.pfm")
    with pytest.raises(WelchInputError, match=re.escape("is not a readable PFM file (")):
        read_pfm(tmp_path / "missing.pfm")
    msg = "`image` must be H×W×3 or H×W for PFM, got shape (2, 2, 4)"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        write_pfm(tmp_path / "x.pfm", np.zeros((2, 2, 4)))


def test_write_tile_pfms_sum_and_sumsq(tmp_path):
    run = make_run(seed=8, n=6)
    sum_path, sq_path = write_tile_pfms(tmp_path / "ref", run)
    assert sum_path == str(tmp_path / "ref_sum.pfm") and sq_path == str(tmp_path / "ref_sumsq.pfm")
    total, squares = read_pfm(sum_path), read_pfm(sq_path)
    assert total.shape == squares.shape == (3, 5, 3)
    assert_allclose(total, run.sums.sum(axis=0), rtol=1e-6)
    assert_allclose(squares, (run.sums**2).sum(axis=0), rtol=1e-6)
    # what the paper's welch.c computes from the two buffers: the same variance to float32 precision
    n = run.n
    var = (squares.astype(np.float64) - total.astype(np.float64) ** 2 / n) / (n - 1)
    assert_allclose(var, run.variance, rtol=1e-2)
