"""Each pixel's difference per seed for a paired check (`batch.jobs.pairs`): the sides' pass images folded into the
moments of test - reference, exactly those of a look's seeds, kept across a resume and a crash, and given up (the
tile test then) where an image is missing."""

from __future__ import annotations

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
    assert sorted(p.name for p in (tmp_path / "pairs" / "test").iterdir()) == ["2.npy", "3.npy", "4.npy"]
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
    (tmp_path / "pairs" / "test" / "1.npy").unlink()
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
