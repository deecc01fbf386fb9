"""Statistics files (welch_core.formats): round trips, atomic checked writes, and every class of damaged or
hostile file refused in one line before anything large is allocated."""

import io
import json
import os
import re
import zipfile

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from welch_core import PixelMoments, RunInfo, StatsFileError, TileStats, WelchInputError, load_stats, save_stats
from welch_core.formats import FORMAT_NAME, FORMAT_VERSION, stats_arrays, write_arrays


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


def version1_arrays(run):
    """A file as version 1 wrote it: stored moments and a mean image instead of the pixel sum."""
    meta = {"height": run.height, "width": run.width, "tile": run.tile, "channels": run.channels}
    return {
        "format": np.array(FORMAT_NAME),
        "version": np.array(1),
        "meta": np.array(json.dumps(meta | {"info": run.info.to_json()})),
        "seeds": np.array(run.seeds, dtype=np.int64),
        "sums": np.array(run.sums),
        "mean": np.array(run.mean),
        "m2": np.array(run.m2),
        "mean_image": run.mean_image,
    }


def expect_damaged(path, arrays, message):
    np.savez(path, **arrays)
    with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} is damaged: {message}")):
        load_stats(path)


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


def test_a_checkpoints_copies_go_into_the_arrays_of_the_one_before(tmp_path):
    rng = np.random.default_rng(4)
    run = TileStats(16, 24, 8, keep_pixel_moments=True)
    for seed in range(3):
        run.add_pass(rng.random((16, 24, 3), dtype=np.float32), seed)
    first = stats_arrays(run)
    run.add_pass(rng.random((16, 24, 3), dtype=np.float32), 3)
    second = stats_arrays(run, into=first)
    assert second["pixel_m2"] is first["pixel_m2"] and second["pixel_mean"] is first["pixel_mean"]
    assert_array_equal(second["pixel_m2"], run.pixels.m2)
    assert_array_equal(second["pixel_mean"], run.pixels.mean.astype(np.float32))
    run.add_pass(rng.random((16, 24, 3), dtype=np.float32), 4)  # the copies do not change with the run
    assert not np.array_equal(second["pixel_m2"], run.pixels.m2)
    other = TileStats(8, 24, 8, keep_pixel_moments=True)  # arrays of another shape are not reused
    other.add_pass(rng.random((8, 24, 3), dtype=np.float32), 0)
    assert stats_arrays(other, into=second)["pixel_m2"] is not second["pixel_m2"]


def test_members_are_the_bytes_numpy_writes(tmp_path):
    """The arrays are written without numpy's copy of them, byte for byte as `np.lib.format.write_array` writes."""
    run = make_run()
    save_stats(tmp_path / "run.npz", run)
    with zipfile.ZipFile(tmp_path / "run.npz") as archive:
        for name in archive.namelist():
            member = io.BytesIO()
            with np.load(tmp_path / "run.npz", allow_pickle=False) as data:
                np.lib.format.write_array(member, data[name[: -len(".npy")]], allow_pickle=False)
            assert archive.read(name) == member.getvalue(), name


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

    def full_disk(member, header):  # a member's header written in part, then the disk is full
        member.write(b"partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np.lib.format, "write_array_header_1_0", full_disk)
    msg = f"can't write statistics file {str(path)!r}: No space left on device"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        save_stats(path, make_run(seed=3))
    assert path.read_bytes() == good
    assert sorted(os.listdir(tmp_path)) == ["run.npz"]


def test_a_written_file_is_read_back_unless_its_reader_checks_it(tmp_path, monkeypatch):
    run = make_run()
    path = tmp_path / "run.npz"
    monkeypatch.setattr(zipfile.ZipFile, "testzip", lambda archive: "sums.npy")  # the read-back finds a bad member
    msg = f"can't write statistics file {str(path)!r}: the written file does not read back (sums.npy)"
    with pytest.raises(WelchInputError, match=re.escape(msg)):
        write_arrays(path, stats_arrays(run))
    assert not path.exists()
    write_arrays(path, stats_arrays(run), verify=False)  # a worker's chunk: read, and checked, at once
    monkeypatch.undo()
    assert_array_equal(load_stats(path).sums, run.sums)


def test_a_failed_write_prints_nothing_afterwards(tmp_path):
    """No 'Exception ignored in ZipFile.__del__' traceback: the archive is closed on the failing path."""
    script = (
        "import numpy as np, welch_core as wc, gc\n"
        "def full(member, header): raise OSError(28, 'No space left on device')\n"
        "np.lib.format.write_array_header_1_0 = full\n"
        "run = wc.TileStats(16, 16, 8)\n"
        "try:\n"
        f"    wc.save_stats({str(tmp_path / 'x.npz')!r}, run)\n"
        "except wc.WelchInputError as exc:\n"
        "    print(exc)\n"
        "gc.collect()\n"
    )
    import subprocess
    import sys

    root = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=root)
    assert "No space left on device" in done.stdout
    assert done.stderr == ""
    assert os.listdir(tmp_path) == []


def test_files_get_the_users_umask(tmp_path):
    old = os.umask(0o022)
    try:
        save_stats(tmp_path / "run.npz", make_run())
    finally:
        os.umask(old)
    assert (tmp_path / "run.npz").stat().st_mode & 0o777 == 0o644


def test_long_but_legal_names(tmp_path):
    path = tmp_path / ("r" * 245 + ".npz")  # 249 characters: the temporary name must not be longer
    save_stats(path, make_run())
    assert load_stats(path).n == 4


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


def test_large_arrays_are_read_directly_and_checked(tmp_path):
    """Pixel sums of 1 MB and more are read straight into their array; a flipped bit is still found."""
    path = tmp_path / "big.npz"
    run = make_run(n=3, height=256, width=512, tile=64)
    save_stats(path, run)
    loaded = load_stats(path)
    assert_array_equal(loaded.pixel_sum, run.pixel_sum)
    assert loaded.pixel_sum.flags.c_contiguous and loaded.pixel_sum.flags.writeable
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo("pixel_sum.npy")
    data[info.header_offset + 30 + len(info.filename) + 1000] ^= 4  # inside the pixel data
    path.write_bytes(bytes(data))
    with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} is damaged: 'pixel_sum' does not match its "
                                                       "checksum")):  # fmt: skip
        load_stats(path)
    path.write_bytes(bytes(data[: info.header_offset + 30 + len(info.filename) + 5000]))
    with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} is not a readable statistics file (")):
        load_stats(path)


def test_previews_of_large_images_are_stored_and_read_alone(tmp_path):
    from welch_core import load_preview, shrink
    from welch_core.formats import PREVIEW_SIDE

    rng = np.random.default_rng(5)
    big = TileStats.from_sums(rng.normal(size=(2, 2, 4, 3)), [1, 2], 600, 1100, 300,
                              pixel_sum=rng.uniform(size=(600, 1100, 3)).astype(np.float32))  # fmt: skip
    save_stats(tmp_path / "big.npz", big)
    with zipfile.ZipFile(tmp_path / "big.npz") as archive:
        assert "preview_sum.npy" in archive.namelist()
    preview = load_preview(tmp_path / "big.npz")
    assert preview.shape == (300, 550, 3) and PREVIEW_SIDE == 1024
    assert_array_equal(preview, shrink(big.pixel_sum, PREVIEW_SIDE))
    light = load_stats(tmp_path / "big.npz", pixels=False)
    assert light.pixel_sum is None and light.seeds == [1, 2]
    assert_array_equal(light.sums, big.sums)

    small = make_run()  # no preview stored: the pixel sums are small enough to be their own
    save_stats(tmp_path / "small.npz", small)
    with zipfile.ZipFile(tmp_path / "small.npz") as archive:
        assert "preview_sum.npy" not in archive.namelist()
    assert_array_equal(load_preview(tmp_path / "small.npz"), small.pixel_sum)
    save_stats(tmp_path / "bare.npz", TileStats.from_sums(big.sums, [1, 2], 600, 1100, 300))
    assert load_preview(tmp_path / "bare.npz") is None

    arrays = dict(np.load(tmp_path / "big.npz"))
    arrays["preview_sum"] = arrays["preview_sum"][:-1]
    np.savez(tmp_path / "bad.npz", **arrays)
    message = f"{str(tmp_path / 'bad.npz')!r} is damaged: 'preview_sum' has shape (299, 550, 3), expected (300, 550, 3)"
    with pytest.raises(StatsFileError, match=re.escape(message)):
        load_preview(tmp_path / "bad.npz")


def test_layers_round_trip_and_only_files_with_layers_are_version_3(tmp_path):
    from welch_core import load_layers
    from welch_core.formats import LAYERS_VERSION

    run = make_run()
    rng = np.random.default_rng(9)
    layers = {
        name: TileStats.from_sums(
            run.sums * w + rng.normal(size=run.sums.shape),
            run.seeds,
            24,
            40,
            8,
            pixel_sum=run.pixel_sum * w,
        )  # fmt: skip
        for name, w in (("diffuse", 0.7), ("lightgroup:key light", 0.3))
    }
    save_stats(tmp_path / "plain.npz", run)
    save_stats(tmp_path / "layers.npz", run, layers)
    assert int(np.load(tmp_path / "plain.npz")["version"]) == FORMAT_VERSION == 2
    assert int(np.load(tmp_path / "layers.npz")["version"]) == LAYERS_VERSION == 3
    assert load_layers(tmp_path / "plain.npz") == {}
    back = load_layers(tmp_path / "layers.npz")
    assert list(back) == ["diffuse", "lightgroup:key light"]
    for name, layer in layers.items():
        assert_array_equal(back[name].sums, layer.sums)
        assert_array_equal(back[name].pixel_sum, layer.pixel_sum)
        assert back[name].seeds == run.seeds
    assert load_layers(tmp_path / "layers.npz", pixels=False)["diffuse"].pixel_sum is None
    assert_array_equal(load_stats(tmp_path / "layers.npz").sums, run.sums)  # the image as before
    other = make_run(seed=1, n=3)
    with pytest.raises(WelchInputError, match="layer 'x' must have the seeds, tiles and channels of the image"):
        save_stats(tmp_path / "bad.npz", run, {"x": other})
    arrays = dict(np.load(tmp_path / "layers.npz"))
    arrays["layer1_sums"] = arrays["layer1_sums"][:2]
    np.savez(tmp_path / "short.npz", **arrays)
    with pytest.raises(StatsFileError, match=re.escape("is damaged: 'layer1_sums' has shape (2, 3, 5, 3)")):
        load_layers(tmp_path / "short.npz")


def test_load_foreign_files(tmp_path):
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, image=np.zeros((4, 4)), labels=np.arange(3))
    with pytest.raises(StatsFileError, match=re.escape(f"{str(foreign)!r} is not a welch-bias-stats file")):
        load_stats(foreign)
    npy = tmp_path / "array.npy"
    np.save(npy, np.arange(5))
    msg = f"{str(npy)!r} is not a welch-bias-stats file (a single numpy array)"
    with pytest.raises(StatsFileError, match=re.escape(msg)):
        load_stats(npy)
    text = tmp_path / "notes.txt"
    text.write_text("seeds: 1, 2, 3\n")
    with pytest.raises(StatsFileError, match=re.escape(f"{str(text)!r} is not a readable statistics file (")):
        load_stats(text)


def test_load_never_unpickles(tmp_path):
    path = tmp_path / "pickled.npz"
    np.savez(path, format=np.array(FORMAT_NAME), version=np.array(2), meta=np.array([{"x": 1}], dtype=object))
    msg = f"{str(path)!r} is damaged: 'meta' holds Python objects, which this tool never loads"
    with pytest.raises(StatsFileError, match=re.escape(msg)):
        load_stats(path)
    pickle_file = tmp_path / "object.npy"
    np.save(pickle_file, np.array([{"x": 1}], dtype=object), allow_pickle=True)
    with pytest.raises(StatsFileError, match=re.escape(f"{str(pickle_file)!r} is not a welch-bias-stats file")):
        load_stats(pickle_file)


@pytest.mark.parametrize(
    ("version", "message"),
    [
        (np.array(5), "has format version 5; this tool reads versions 1 to 4"),
        (np.array(1.7), "has a format version that is not an integer: 1.7"),
        (np.array("abc"), "has a format version that is not an integer: 'abc'"),
        (np.array([1, 1]), "has a format version that is not an integer: [1, 1]"),
        (None, "has no format version; this tool reads versions 1 to 4"),
    ],
)
def test_load_wrong_version(tmp_path, version, message):
    arrays = good_arrays(make_run(), tmp_path)
    arrays = {k: v for k, v in arrays.items() if k != "version"} | ({} if version is None else {"version": version})
    path = tmp_path / "v.npz"
    np.savez(path, **arrays)
    with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} {message}")):
        load_stats(path)


def test_load_damaged_contents(tmp_path):
    arrays = good_arrays(make_run(), tmp_path)
    path = tmp_path / "damaged.npz"
    grid = arrays["sums"].shape
    variants = [
        ({k: v for k, v in arrays.items() if k != "sums"}, "it has no 'sums' array"),
        (arrays | {"meta": np.array("{not json")}, "its metadata is not JSON ("),
        (arrays | {"seeds": np.array([1, 1, 2, 3])}, "'seeds' repeats a seed"),
        (arrays | {"seeds": np.array([[1, 2], [3, 4]])}, "'seeds' must be one-dimensional, got shape (2, 2)"),
        (arrays | {"seeds": np.array([-1, 2, 3, 4])}, "'seeds' must lie in 0..9223372036854775807"),
        (arrays | {"pixel_sum": arrays["pixel_sum"][:5]}, "'pixel_sum' has shape (5, 40, 3), expected (24, 40, 3)"),
        (arrays | {"sums": arrays["sums"][:, :2]}, f"'sums' has shape (4, 2, 5, 3), expected {grid}"),
    ]
    for variant, message in variants:
        expect_damaged(path, variant, message)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("sums", lambda a: a.astype(np.complex128), "'sums' has dtype complex128, expected floats"),
        ("sums", lambda a: a > 0, "'sums' has dtype bool, expected floats"),
        ("sums", lambda a: a.astype(str), "'sums' has dtype <U32, expected floats"),
        ("seeds", lambda a: a.astype(float), "'seeds' has dtype float64, expected integers"),
        ("meta", lambda a: np.array(3), "'meta' has dtype int64, expected a string"),
    ],
)
def test_load_refuses_arrays_of_the_wrong_type(tmp_path, key, value, message):
    arrays = good_arrays(make_run(), tmp_path)
    expect_damaged(tmp_path / "typed.npz", arrays | {key: value(arrays[key])}, message)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"height": "24"}, "metadata 'height' must be an integer in 1..65536, got '24'"),
        ({"tile": True}, "metadata 'tile' must be an integer in 1..65536, got True"),
        ({"width": 10**9}, "metadata 'width' must be an integer in 1..65536, got 1000000000"),
        ({"tile": 100}, "`tile` must not exceed the image size 40x24, got 100"),
        ({"info": {"spp": "4"}}, "`spp` must be an integer >= 1, got '4'"),
        ({"info": {"renderer": ["Cycles"]}}, "`renderer` must be a string, got list ['Cycles']"),
        ({"info": [1, 2]}, "run info must be a JSON object, got list"),
        ({"nonfinite_seeds": "all"}, "metadata 'nonfinite_seeds' must be a list of integers, got 'all'"),
    ],
)
def test_load_refuses_metadata_of_the_wrong_type(tmp_path, change, message):
    arrays = good_arrays(make_run(), tmp_path)
    meta = json.loads(str(arrays["meta"])) | change
    expect_damaged(tmp_path / "meta.npz", arrays | {"meta": np.array(json.dumps(meta))}, message)


def test_load_refuses_non_finite_sums_the_file_does_not_record(tmp_path):
    arrays = good_arrays(make_run(), tmp_path)
    sums = arrays["sums"].copy()
    sums[2, 0, 0, 1] = np.inf
    message = "the pass with seed 1014 has non-finite tile sums the file does not record"
    expect_damaged(tmp_path / "inf.npz", arrays | {"sums": sums}, message)
    # --on-nan keep records them: such a file loads, and the tile is excluded from the test later
    run = make_run()
    kept = TileStats.from_sums(sums, run.seeds, 24, 40, 8)
    save_stats(tmp_path / "kept.npz", kept)
    back = load_stats(tmp_path / "kept.npz")
    assert np.isinf(back.sums[2, 0, 0, 1])


def test_load_refuses_a_header_that_claims_more_than_the_file_holds(tmp_path):
    """A header claiming 4.5 * 10^7 elements is refused from the header alone, without allocating."""
    arrays = good_arrays(make_run(), tmp_path) | {"seeds": np.arange(10**6)}
    path = tmp_path / "huge.npz"
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (10**6, 3, 5, 3)})
    with zipfile.ZipFile(path, "w") as archive:
        for key, value in arrays.items():
            if key != "sums":
                with archive.open(f"{key}.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, value)
        archive.writestr("sums.npy", header.getvalue() + b"\0" * 64)
    message = "'sums' claims 360000000 bytes but the file holds 192"
    with pytest.raises(StatsFileError, match=re.escape(f"{str(path)!r} is damaged: {message}")):
        load_stats(path)


def test_load_reads_only_the_known_arrays(tmp_path, monkeypatch):
    arrays = good_arrays(make_run(), tmp_path)
    path = tmp_path / "extra.npz"
    np.savez(path, **arrays, unused=np.zeros(100_000))
    read = []
    original = np.lib.format.read_array
    monkeypatch.setattr(np.lib.format, "read_array", lambda f, **kw: read.append(f.name) or original(f, **kw))
    assert load_stats(path).n == 4
    assert "unused.npy" not in read and "sums.npy" in read


def test_version1_files_are_read_and_checked(tmp_path):
    run = make_run()
    arrays = version1_arrays(run)
    path = tmp_path / "v1.npz"
    np.savez(path, **arrays)
    back = load_stats(path)
    assert_array_equal(back.sums, run.sums)
    assert_allclose(back.mean_image, run.mean_image, rtol=1e-6)
    mean = arrays["mean"].copy()
    mean[0, 0, 0] *= 1.01  # a stored mean that contradicts the sums: `compare` once called identical passes biased
    contradiction = "its stored means or second moments contradict its per-pass sums"
    expect_damaged(path, arrays | {"mean": mean}, contradiction)
    expect_damaged(path, arrays | {"mean": np.full_like(mean, np.nan)}, contradiction)
    expect_damaged(path, arrays | {"m2": -arrays["m2"]}, contradiction)


def moments_run(seed=0, n=8, offset=0.0):
    """A run that keeps its pixel moments, of float32 passes (the tile sums add float32 rows)."""
    rng = np.random.default_rng(seed)
    run = TileStats(24, 40, 8, keep_pixel_moments=True)
    for i in range(n):
        run.add_pass((offset + rng.gamma(2.0, 0.5, (24, 40, 3))).astype(np.float32), 2000 + 100 * seed + i)
    return run


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("pixel_mean", np.nan, "'pixel_mean' must be finite, got nan (pixel x 7, y 5, channel 1)"),
        ("pixel_mean", -np.inf, "'pixel_mean' must be finite, got -inf (pixel x 7, y 5, channel 1)"),
        ("pixel_m2", np.inf, "'pixel_m2' must be finite and >= 0, got inf (pixel x 7, y 5, channel 1)"),
        ("pixel_m2", -1.0, "'pixel_m2' must be finite and >= 0, got -1.0 (pixel x 7, y 5, channel 1)"),
    ],
)
def test_load_refuses_pixel_moments_that_are_not_finite_naming_the_array(tmp_path, key, value, message):
    """A NaN or inf pixel mean was refused only when the moments were merged, as 'pixel M2', without the file."""
    arrays = good_arrays(moments_run(), tmp_path)
    damaged = arrays[key].copy()
    damaged[5, 7, 1] = value
    expect_damaged(tmp_path / "moments.npz", arrays | {key: damaged}, message)
    with pytest.raises(WelchInputError, match=re.escape(message.replace(f"'{key}'", f"`{key[6:]}`"))):
        PixelMoments.of(*(damaged if k == key else arrays[k] for k in ("pixel_mean", "pixel_m2")), 8)
    damaged[0, 0, 0] = value  # more than one: the first, and how many more
    first = message.split(" (")[0] + " (pixel x 0, y 0, channel 0, and 1 more)"
    expect_damaged(tmp_path / "moments.npz", arrays | {key: damaged}, first)


def test_load_refuses_pixel_moments_that_contradict_the_tile_sums(tmp_path):
    """All-zero pixel M2s beside tile sums that vary made `compare --pixel-variance on` call 8 v 8 unbiased passes
    `biased`: moments must be those of the file's passes, (5) and (6) of `welch_core.pixels.moment_conflict`."""
    run = moments_run()
    arrays = good_arrays(run, tmp_path)
    path = tmp_path / "moments.npz"
    spread = "'pixel_m2' contradicts its tile sums: in {} of 45 tile-channels the tile sums vary more than their pixels"
    expect_damaged(path, arrays | {"pixel_m2": np.zeros_like(arrays["pixel_m2"])}, spread.format(45))
    expect_damaged(path, arrays | {"pixel_m2": arrays["pixel_m2"] * 1e-3}, spread.format(45))
    one = arrays["pixel_m2"].copy()
    one[8:16, 16:24, 2] = 0  # one tile-channel's pixels never vary
    expect_damaged(path, arrays | {"pixel_m2": one}, spread.format(1))
    means = "'pixel_mean' contradicts its tile sums: in {} of 45 tile-channels the pixels' means do not add up to the"
    expect_damaged(path, arrays | {"pixel_mean": moments_run(seed=1).pixels.mean}, means.format(45))
    shifted = arrays["pixel_mean"].copy()
    shifted[0, 0, 0] += 0.05  # of a tile sum of about 64, whose passes spread by about 6
    expect_damaged(path, arrays | {"pixel_mean": shifted}, means.format(1))
    sums = arrays["sums"].copy()
    sums[3, 1, 1, 0] = np.nan  # recorded as a non-finite pass, which keeps no moments
    meta = json.loads(str(arrays["meta"])) | {"nonfinite_seeds": [run.seeds[3]]}
    damaged = arrays | {"sums": sums, "meta": np.array(json.dumps(meta))}
    expect_damaged(path, damaged, means.format(1))
    # moments of the same passes agree within rounding: a bright offset, passes added one by one and merged
    bright = moments_run(seed=2, n=5, offset=1e4).merge(moments_run(seed=3, n=3, offset=1e4))
    for good in (run, bright, moments_run(seed=4, n=2).merge(moments_run(seed=5, n=9))):
        save_stats(tmp_path / "good.npz", good)
        assert_allclose(load_stats(tmp_path / "good.npz").pixels.m2, good.pixels.m2, rtol=0)


def test_load_missing_path(tmp_path):
    path = tmp_path / "nothing.npz"
    with pytest.raises(StatsFileError, match=re.escape(f"statistics file {str(path)!r} does not exist")):
        load_stats(path)
    with pytest.raises(StatsFileError, match=re.escape(f"{str(tmp_path)!r} is not a readable statistics file")):
        load_stats(tmp_path)


def test_json_of_the_run_info_is_strict(tmp_path):
    run = make_run(info=RunInfo(settings={"x": float("nan")}))
    with pytest.raises(ValueError, match="Out of range float values are not JSON compliant"):
        save_stats(tmp_path / "nan.npz", run)
    assert os.listdir(tmp_path) == []


def test_metadata_with_nan_is_refused(tmp_path):
    arrays = good_arrays(make_run(), tmp_path)
    meta = str(arrays["meta"]).replace('"settings": {}', '"settings": {"cycles.film_exposure": NaN}')
    assert "NaN" in meta
    expect_damaged(tmp_path / "nan.npz", arrays | {"meta": np.array(meta)}, "its metadata is not JSON (NaN is not")
