"""PNG writing with numpy and zlib (welch_core.png), checked by Pillow's decoder as an independent oracle."""

import base64
import io

import numpy as np
import pytest

from welch_core.errors import WelchInputError
from welch_core.png import data_url, png_bytes, to_uint8, write_png

Image = pytest.importorskip("PIL.Image")


@pytest.mark.parametrize("channels", [3, 4])
@pytest.mark.parametrize("fast", [False, True])
def test_pillow_reads_back_every_pixel(channels, fast):
    image = np.random.default_rng(channels).integers(0, 256, (37, 53, channels), dtype=np.uint8)
    back = np.asarray(Image.open(io.BytesIO(png_bytes(image, fast=fast))))
    np.testing.assert_array_equal(back, image)


@pytest.mark.parametrize("fast", [False, True])
def test_pillow_reads_back_a_palette_image(fast):
    palette = np.random.default_rng(5).uniform(0.0, 1.0, (200, 3))
    indices = np.random.default_rng(6).integers(0, 200, (29, 41), dtype=np.uint8)
    back = Image.open(io.BytesIO(png_bytes(indices, fast=fast, palette=palette)))
    assert back.mode == "P"
    np.testing.assert_array_equal(np.asarray(back), indices)
    np.testing.assert_array_equal(np.asarray(back.convert("RGB")), to_uint8(palette)[indices])


NO_PALETTE = "`palette` must be N×3 colours, 1 <= N <= 256, got shape"


@pytest.mark.parametrize(
    ("indices", "palette", "message"),
    [
        (np.zeros((2, 2), np.uint8), np.zeros((257, 3)), f"{NO_PALETTE} (257, 3)"),
        (np.zeros((2, 2), np.uint8), np.zeros((4, 4)), f"{NO_PALETTE} (4, 4)"),
        (np.zeros((2, 2, 3), np.uint8), np.zeros((4, 3)),
         "`image` must be a non-empty H×W uint8 array of indices, got uint8 (2, 2, 3)"),
        (np.full((2, 2), 4, np.uint8), np.zeros((4, 3)), "`image` holds index 4, beyond the palette's 4 colours"),
    ],
)  # fmt: skip
def test_palette_image_errors(indices, palette, message):
    with pytest.raises(WelchInputError) as info:
        png_bytes(indices, palette=palette)
    assert str(info.value) == message


def test_data_url_holds_the_fast_png():
    rgb = np.random.default_rng(7).uniform(0.0, 1.0, (9, 11, 3))
    url = data_url(rgb)
    assert url.startswith("data:image/png;base64,")
    back = Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1])))
    np.testing.assert_array_equal(np.asarray(back), to_uint8(rgb))


def test_to_uint8_rounds_and_clips():
    np.testing.assert_array_equal(to_uint8(np.array([[[-1.0, 0.5, 2.0]], [[np.nan, 1 / 255, 0.998]]])),
                                  [[[0, 128, 255]], [[0, 1, 254]]])  # fmt: skip


def test_write_png_is_atomic(tmp_path):
    write_png(tmp_path / "a.png", np.zeros((2, 3, 3), np.uint8))
    assert [p.name for p in tmp_path.iterdir()] == ["a.png"]
    assert Image.open(tmp_path / "a.png").size == (3, 2)
