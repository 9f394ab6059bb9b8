"""The compiled colour-gradient kernel against OpenCV's per-channel Sobel, pixel for pixel."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.vision.gradient import color_gradient
from labauto.vision.kernels.gradient import max_channel_sobel


def _strongest_channel_reference(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cv2.spatialGradient per channel, then the first channel of largest |dx| + |dy|."""
    grads = [cv2.spatialGradient(np.ascontiguousarray(image[..., c])) for c in range(3)]
    strength = np.stack([np.abs(dx.astype(int)) + np.abs(dy.astype(int)) for dx, dy in grads])
    best = np.argmax(strength, axis=0)  # argmax keeps the first of equal maxima
    gx = np.choose(best, [g[0] for g in grads]).astype(np.int16)
    gy = np.choose(best, [g[1] for g in grads]).astype(np.int16)
    return gx, gy


@pytest.mark.parametrize("shape", [(2, 2), (3, 3), (2, 57), (61, 2), (17, 33), (64, 129)])
def test_kernel_equals_opencv_on_every_pixel_including_borders(shape: tuple[int, int]) -> None:
    image = np.random.default_rng(sum(shape)).integers(0, 256, (*shape, 3), dtype=np.uint8)
    gx, gy = np.empty(shape, np.int16), np.empty(shape, np.int16)
    max_channel_sobel(image, gx, gy)
    rx, ry = _strongest_channel_reference(image)
    assert np.array_equal(gx, rx)
    assert np.array_equal(gy, ry)


def test_extreme_contrast_does_not_overflow() -> None:
    image = np.zeros((9, 9, 3), np.uint8)
    image[:, 5:] = 255  # a step of 255 in every channel: |dx| = 4 * 255
    gx, gy = color_gradient(image, blur_sigma=0)
    assert gx.max() == 4 * 255 and gy.min() == 0 and gy.max() == 0


def test_ties_keep_the_first_channel() -> None:
    image = np.zeros((5, 6, 3), np.uint8)
    image[:, 3:, 0] = 10  # channel 0: +x step
    image[:, :3, 2] = 10  # channel 2: -x step of the same strength
    gx, _ = color_gradient(image, blur_sigma=0)
    assert gx[2, 2] == 40 and gx[2, 3] == 40


def test_grey_image_is_opencvs_sobel() -> None:
    image = np.random.default_rng(3).integers(0, 256, (20, 30), dtype=np.uint8)
    gx, gy = color_gradient(image, blur_sigma=0)
    rx, ry = cv2.spatialGradient(image)
    assert np.array_equal(gx, rx) and np.array_equal(gy, ry)


def test_kernel_names_wrong_shapes() -> None:
    out = np.empty((4, 4), np.int16)
    with pytest.raises(ValueError, match="HxWx3"):
        max_channel_sobel(np.zeros((4, 5, 3), np.uint8), out, out)
    with pytest.raises(ValueError, match="2x2"):
        max_channel_sobel(np.zeros((1, 4, 3), np.uint8), out[:1], out[:1])
