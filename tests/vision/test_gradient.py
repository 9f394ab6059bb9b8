"""The compiled colour-gradient kernel against OpenCV (blur, per-channel Sobel), pixel for pixel."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.vision.gradient import color_gradient, gaussian_3x3_tap
from labauto.vision.kernels.gradient import max_channel_sobel

# sigmas of the 3x3 blur (below 0.75): no blur (tap 0), both sides of the first rounding step
# (tap 0 -> 1 at 0.28320), the default, and the largest taps (57 -> 58 at 0.74661)
SIGMAS_3X3 = [0.1, 0.2831, 0.2833, 0.45, 0.5, 0.6, 0.7, 0.709, 0.74, 0.7466, 0.7467, 0.7499]
# sizes: the smallest, single rows and columns of blocks, odd sizes (threads get unequal blocks),
# and rows of many SIMD vectors with a ragged end (301 pixels: 903 bytes)
SHAPES = [(2, 2), (3, 3), (2, 57), (57, 2), (3, 40), (5, 7), (17, 33), (64, 129), (101, 31)]
SHAPES += [(6, 301)]


def _strongest_channel_reference(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cv2.spatialGradient per channel, then the first channel of largest |dx| + |dy|."""
    grads = [cv2.spatialGradient(np.ascontiguousarray(image[..., c])) for c in range(3)]
    strength = np.stack([np.abs(dx.astype(int)) + np.abs(dy.astype(int)) for dx, dy in grads])
    best = np.argmax(strength, axis=0)  # argmax keeps the first of equal maxima
    gx = np.choose(best, [g[0] for g in grads]).astype(np.int16)
    gy = np.choose(best, [g[1] for g in grads]).astype(np.int16)
    return gx, gy


def _blurred_reference(image: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """cv2.GaussianBlur (3x3), then the strongest channel of cv2.spatialGradient."""
    return _strongest_channel_reference(cv2.GaussianBlur(image, (3, 3), sigma))


def _opencv_tap(sigma: float) -> int:
    """The outer tap of cv2.GaussianBlur's 8-bit 3x3 kernel, read off a blurred vertical line.

    A column of 255 next to zeros blurs to round(255 t / 256) beside it: t itself for t < 128.
    """
    line = np.zeros((3, 3), np.uint8)
    line[:, 0] = 255
    return int(cv2.GaussianBlur(line, (3, 3), sigma)[1, 1])


def test_gaussian_3x3_tap_is_opencvs_for_every_sigma_of_the_3x3_range() -> None:
    sigmas = np.linspace(0.001, 0.7499, 3001)
    taps = [gaussian_3x3_tap(float(s)) for s in sigmas]
    assert taps == [_opencv_tap(float(s)) for s in sigmas]
    assert taps[0] == 0 and gaussian_3x3_tap(0.7) == 54 and taps[-1] == 58
    for sigma in SIGMAS_3X3:  # on both sides of each rounding step tested below
        assert gaussian_3x3_tap(sigma) == _opencv_tap(sigma)
    with pytest.raises(ValueError, match="sigma"):
        gaussian_3x3_tap(0.0)


@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize("shape", SHAPES)
def test_blurred_kernel_is_opencvs_blur_then_sobel_bit_for_bit(
    shape: tuple[int, int], threads: int
) -> None:
    rng = np.random.default_rng(100 * shape[0] + shape[1])
    noise = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
    steps = (rng.random((*shape, 3)) < 0.5).astype(np.uint8) * 255  # extreme values, ties
    for image in (noise, steps):
        for sigma in SIGMAS_3X3:
            gx, gy = np.full(shape, 7, np.int16), np.full(shape, 7, np.int16)
            max_channel_sobel(image, gx, gy, threads, gaussian_3x3_tap(sigma))
            rx, ry = _blurred_reference(image, sigma)
            assert np.array_equal(gx, rx), sigma
            assert np.array_equal(gy, ry), sigma


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_unblurred_kernel_on_any_thread_count(threads: int) -> None:
    for shape in SHAPES:
        image = np.random.default_rng(shape[0]).integers(0, 256, (*shape, 3), dtype=np.uint8)
        gx, gy = np.full(shape, 7, np.int16), np.full(shape, 7, np.int16)
        max_channel_sobel(image, gx, gy, threads)
        rx, ry = _strongest_channel_reference(image)
        assert np.array_equal(gx, rx) and np.array_equal(gy, ry)


@pytest.mark.parametrize("sigma", [0.0, 0.3, 0.7, 0.75, 1.0, 1.6])
def test_color_gradient_is_opencvs_blur_then_sobel(sigma: float) -> None:
    """The 3x3 blur inside the kernel, larger ones by cv2.GaussianBlur: the same either way."""
    image = np.random.default_rng(11).integers(0, 256, (45, 67, 3), dtype=np.uint8)
    if sigma > 0:
        ksize = 2 * max(1, round(2 * sigma)) + 1
        expected = _strongest_channel_reference(cv2.GaussianBlur(image, (ksize, ksize), sigma))
    else:
        expected = _strongest_channel_reference(image)
    gx, gy = color_gradient(image, blur_sigma=sigma)
    assert np.array_equal(gx, expected[0]) and np.array_equal(gy, expected[1])
    strided = np.zeros((45, 67, 4), np.uint8)
    strided[..., :3] = image  # not contiguous: copied, same result
    gx2, gy2 = color_gradient(strided[..., :3], blur_sigma=sigma)
    assert np.array_equal(gx2, gx) and np.array_equal(gy2, gy)


@pytest.mark.parametrize("shape", SHAPES)
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
    with pytest.raises(ValueError, match="blur_tap"):
        max_channel_sobel(np.zeros((4, 4, 3), np.uint8), out, out, 1, 65)
