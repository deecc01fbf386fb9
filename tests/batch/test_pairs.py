"""Each pixel's difference per seed for a paired check (`batch.jobs.pairs`): the sides' pass images folded into the
moments of test - reference, exactly those of a look's seeds, kept across a resume and a crash, and given up (the
tile test then) where an image is missing."""

from __future__ import annotations

import errno
import os

import numpy as np

import welch_core as wc
from batch.jobs.pairs import PixelPairs, save_pass_image


def _images(tmp_path, seeds):
    rng = np.random.default_rng(0)
    out = {}
    for seed in seeds:
        ref, test = rng.random((8, 12, 4), dtype=np.float32), rng.random((8, 12, 4), dtype=np.float32)
        save_pass_image(PixelPairs.folder(tmp_path, "reference"), seed, ref)
        save_pass_image(PixelPairs.folder(tmp_path, "test"), seed, test)
        out[seed] = test[..., :3].astype(np.float64) - ref[..., :3]
    return out


def test_a_looks_seeds_are_folded_saved_and_their_images_deleted(tmp_path):
    differences = _images(tmp_path, range(5))
    pairs = PixelPairs(tmp_path)
    first = pairs.at([0, 1])
    oracle = wc.PixelMoments.of_passes(np.stack([differences[0], differences[1]]))
    np.testing.assert_allclose(first.m2, oracle.m2, rtol=1e-12)
    assert sorted(p.name for p in (tmp_path / "pairs" / "test").iterdir()) == ["2.exr", "3.exr", "4.exr"]
    again = PixelPairs(tmp_path)  # a resumed check reads them back
    assert again.seeds == [0, 1]
    moments = again.at([0, 1, 2, 3, 4])
    oracle = wc.PixelMoments.of_passes(np.stack(list(differences.values())))
    np.testing.assert_allclose(moments.mean, oracle.mean, rtol=1e-12)
    np.testing.assert_allclose(moments.m2, oracle.m2, rtol=1e-12)
    assert not any((tmp_path / "pairs" / "reference").iterdir())
    assert again.at([0, 1, 2]) is None  # a look of other seeds than those folded: the pairs can't give them


def test_a_missing_image_ends_the_pairs_and_a_new_check_starts_clean(tmp_path):
    _images(tmp_path, range(3))
    (tmp_path / "pairs" / "test" / "1.exr").unlink()
    pairs = PixelPairs(tmp_path)
    assert pairs.at([0, 1, 2]) is None and pairs.broken
    assert PixelPairs(tmp_path).at([0]) is None  # recorded: a resume does not start over from a part
    PixelPairs.clear(tmp_path)
    assert not (tmp_path / "pairs.npz").exists() and not any((tmp_path / "pairs" / "reference").iterdir())
    _images(tmp_path, range(2))
    assert PixelPairs(tmp_path).at([0, 1]).n == 2


def test_an_unreadable_pairs_file_gives_the_tile_test_not_an_error(tmp_path):
    (tmp_path / "pairs.npz").write_bytes(b"not a zip")
    assert PixelPairs(tmp_path).at([0]) is None


def test_a_passs_own_file_is_renamed_into_the_folder_not_written_again(tmp_path, monkeypatch):
    """The EXR a renderer wrote for a pass becomes its pass image: the same file (inode), moved; where it lies on
    another file system it is copied once. The check reads its colour."""
    rng = np.random.default_rng(3)
    image = rng.random((8, 12, 3), dtype=np.float32)
    source = tmp_path / "welch-pass-1-x.exr"
    wc.write_exr(source, image)
    inode = source.stat().st_ino
    folder = PixelPairs.folder(tmp_path, "test")
    save_pass_image(folder, 7, image, str(source))
    kept = tmp_path / "pairs" / "test" / "7.exr"
    assert not source.exists() and kept.stat().st_ino == inode
    np.testing.assert_array_equal(wc.read_exr(kept), image)
    other = tmp_path / "other.exr"
    wc.write_exr(other, image)
    rename = os.replace

    def across_file_systems(src, dst):
        if os.fspath(src) == str(other):
            raise OSError(errno.EXDEV, "Invalid cross-device link")
        rename(src, dst)

    monkeypatch.setattr(os, "replace", across_file_systems)
    save_pass_image(folder, 8, image, str(other))  # another file system: copied, the renderer's file left to it
    assert other.exists()
    save_pass_image(folder, 9, image)  # no file: the image is written
    for seed in (8, 9):
        np.testing.assert_array_equal(wc.read_exr(tmp_path / "pairs" / "test" / f"{seed}.exr"), image)
    assert sorted(p.name for p in (tmp_path / "pairs" / "test").iterdir()) == ["7.exr", "8.exr", "9.exr"]
