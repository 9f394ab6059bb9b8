"""The one image validator (labauto.vision.image.as_image) and its users."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.imageio import read_image
from labauto.vision.image import as_image

RNG = np.random.default_rng(16)
EIGHT = RNG.integers(0, 256, (40, 50, 3), dtype=np.uint8)


@pytest.mark.parametrize(
    ("image", "kwargs"),
    [
        (EIGHT, {}),
        (EIGHT.astype(np.float32), {}),
        (EIGHT.astype(np.float64) / 255.0, {}),
        (EIGHT.astype(np.uint16), {}),
        (EIGHT.astype(np.int32), {}),
        (np.rint(EIGHT * (4095 / 255)).astype(np.uint16), {"significant_bits": 12}),
        (np.dstack([EIGHT, np.full(EIGHT.shape[:2], 7, np.uint8)]), {}),
        (EIGHT[:, ::-1], {}),  # not contiguous
    ],
)
def test_every_accepted_form_gives_the_same_uint8_bgr(image: np.ndarray, kwargs: dict) -> None:
    out = as_image(image, **kwargs)
    assert out.dtype == np.uint8 and out.flags.c_contiguous
    expected = EIGHT[:, ::-1] if image.strides[1] < 0 else EIGHT
    np.testing.assert_array_equal(out, expected)


def test_grey_stays_grey_or_becomes_bgr() -> None:
    grey = EIGHT[..., 0]
    assert as_image(grey).shape == grey.shape
    assert as_image(grey[..., None]).shape == grey.shape
    bgr = as_image(grey, color=True)
    assert bgr.shape == (*grey.shape, 3)
    np.testing.assert_array_equal(bgr[..., 2], grey)


@pytest.mark.parametrize(
    ("image", "kwargs", "words"),
    [
        (EIGHT.tolist(), {}, "numpy array"),
        (np.zeros((0, 4), np.uint8), {}, "empty"),
        (np.zeros(9, np.uint8), {}, "dimension"),
        (np.zeros((9, 9, 2), np.uint8), {}, "channels"),
        (np.zeros((9, 9), bool), {}, "dtype"),
        (np.zeros((9, 9), np.complex64), {}, "dtype"),
        (np.full((9, 9), 300, np.uint16), {}, "0..255"),
        (np.full((9, 9), -1, np.int16), {}, "negative"),
        (np.full((9, 9), 256.0), {}, "0-1 or 0-255"),
        (np.full((9, 9), np.inf), {}, "NaN or infinite"),
        (np.zeros((9, 9), np.uint8), {"min_side": 64}, "64x64"),
    ],
)
def test_refused_images_name_what_is_wrong(image: object, kwargs: dict, words: str) -> None:
    with pytest.raises(ValueError, match=words):
        as_image(image, name="plate 7", **kwargs)
    with pytest.raises(ValueError, match="plate 7"):
        as_image(image, name="plate 7", **kwargs)


def test_a_file_and_its_array_give_the_same_image(tmp_path) -> None:
    twelve = np.rint(EIGHT * (4095 / 255)).astype(np.uint16)
    path = tmp_path / "twelve.png"
    assert cv2.imwrite(str(path), twelve)
    np.testing.assert_array_equal(read_image(path), as_image(twelve, significant_bits=12))
    np.testing.assert_array_equal(read_image(path), EIGHT)
