"""PNG writing with numpy and zlib (welch_core.png), checked by Pillow's decoder as an independent oracle."""

import io

import numpy as np
import pytest

from welch_core.png import png_bytes, to_uint8, write_png

Image = pytest.importorskip("PIL.Image")


@pytest.mark.parametrize("channels", [3, 4])
@pytest.mark.parametrize("fast", [False, True])
def test_pillow_reads_back_every_pixel(channels, fast):
    image = np.random.default_rng(channels).integers(0, 256, (37, 53, channels), dtype=np.uint8)
    back = np.asarray(Image.open(io.BytesIO(png_bytes(image, fast=fast))))
    np.testing.assert_array_equal(back, image)


def test_to_uint8_rounds_and_clips():
    np.testing.assert_array_equal(to_uint8(np.array([[[-1.0, 0.5, 2.0]], [[np.nan, 1 / 255, 0.998]]])),
                                  [[[0, 128, 255]], [[0, 1, 254]]])  # fmt: skip


def test_write_png_is_atomic(tmp_path):
    write_png(tmp_path / "a.png", np.zeros((2, 3, 3), np.uint8))
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]
    assert Image.open(tmp_path / "a.png").size == (3, 2)
