"""Colour image gradient (eq. 2 of Teutsch et al.).

The paper measures colour edge strength as the sum of the squared channel gradients (eq. 2) and
notes that directions in different channels can disagree. We take, per pixel, the gradient
``(gx, gy)`` of the channel whose gradient is largest (L1 norm ``|gx| + |gy|``, cheaper than L2
and selecting the same channel in all but near-ties). This is the choice OpenCV's own colour Canny
makes; it keeps a true image direction (no sign ambiguity of a structure tensor) and for the
common edge between two uniform colours, where all channel gradients are parallel, its direction
equals the structure tensor's principal direction. Its magnitude is the largest channel's, which
is within a factor sqrt(3) of the eq. 2 magnitude; thresholds are given on this scale.

Derivatives are the 3x3 Sobel operator after an optional Gaussian blur (``cv2.GaussianBlur`` on
all channels), in integer arithmetic on 8-bit data, so the result is int16 and can go straight
into ``cv2.Canny(dx, dy, ...)``. The plain path (:func:`strongest_channel_gradient`) is
``cv2.GaussianBlur``, ``cv2.spatialGradient`` per channel and the per-pixel choice in numpy.
With the compiled kernel (:mod:`labauto.vision.kernels.gradient`) the three channel gradients
and the choice among them are one pass with the same result; the 3x3 blur (``blur_sigma`` below
0.75, the default 0.7 included) is done in that same pass, bit for bit as ``cv2.GaussianBlur``
does it (see :func:`gaussian_3x3_tap`), without writing the blurred image to memory; larger
blurs and grey images call OpenCV.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from labauto.vision import kernels


def _blur_size(blur_sigma: float) -> int:
    """Side of the Gaussian kernel for ``blur_sigma`` > 0: truncated at about 2 sigma."""
    return 2 * max(1, round(2.0 * blur_sigma)) + 1


def _blur(image: np.ndarray, blur_sigma: float) -> np.ndarray:
    if blur_sigma <= 0:
        return image
    ksize = _blur_size(blur_sigma)
    return cv2.GaussianBlur(image, (ksize, ksize), blur_sigma)  # all channels in one call


def gaussian_3x3_tap(sigma: float) -> int:
    """Outer tap, in 1/256, of the 3x3 Gaussian that ``cv2.GaussianBlur`` applies to 8-bit images.

    For 8-bit images OpenCV (its bit-exact fixed-point path) filters with a separable kernel
    ``[t, 256 - 2 t, t] / 256`` in each direction, exact in integers and rounded once at the end
    (``(v + 32768) >> 16``), the border mirrored without repeating the edge pixel. ``t`` is the
    outer value of the normalised Gaussian, ``e / (1 + 2 e)`` with ``e = exp(-1 / (2 sigma^2))``
    (in OpenCV's order of operations), times 256 and rounded half to even; the centre takes the
    rest, so the taps sum to exactly 256. This matched OpenCV 5.0 on 200 001 sigmas in (0, 0.75)
    and matches it in tests/vision/test_gradient.py (3001 sigmas; blurred random images); it
    could only differ where ``256 e / (1 + 2 e)`` is within a rounding error of OpenCV's own
    ``exp`` from a half-integer. ``t`` is 0 (no blur) below sigma 0.2832, 54 at 0.7 and 58 at
    the top of the 3x3 range.

    Parameters
    ----------
    sigma : float
        Standard deviation of the Gaussian, > 0.

    Returns
    -------
    int
        ``t``, 0-64.
    """
    if not sigma > 0:
        raise ValueError(f"sigma must be > 0, got {sigma}")
    scale = -0.125 / (sigma * sigma)  # as OpenCV: exp(scale * x^2), x in half pixels (x = 2)
    outer = math.exp(4.0 * scale)
    return round(outer * (1.0 / (2.0 * outer + 1.0)) * 256.0)  # round half to even, as cvRound


def color_gradient(image: np.ndarray, blur_sigma: float = 0.7) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel colour gradient: 3x3 Sobel of the channel with the largest gradient.

    Parameters
    ----------
    image : np.ndarray
        uint8 HxW or HxWx3 image (see :func:`labauto.vision.image.as_image`).
    blur_sigma : float
        Standard deviation (pixels) of a Gaussian blur applied to each channel first, with a
        kernel truncated at about 2 sigma (3x3 below sigma 0.75, 5x5 up to 1.25); 0 for none.
        The blurred image is bit for bit ``cv2.GaussianBlur(image, (k, k), blur_sigma)``.

    Returns
    -------
    gx, gy : np.ndarray
        int16 HxW derivatives along x (right) and y (down), on the scale of the 3x3 Sobel
        operator (a step of contrast C gives a peak of about 4 C before blurring). At the image
        border the image is mirrored without repeating the edge pixel (as ``cv2.spatialGradient``
        does), so the derivative across the border is 0.
    """
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise ValueError(f"color_gradient needs a uint8 HxW or HxWx3 image, got {image.dtype}")
    kernel = kernels.compiled("gradient")
    if image.ndim == 2 or kernel is None:
        return strongest_channel_gradient(_blur(image, blur_sigma))
    if blur_sigma <= 0:
        tap = 0  # no blur
    elif _blur_size(blur_sigma) == 3:
        tap = gaussian_3x3_tap(blur_sigma)  # the kernel blurs
    else:
        tap, image = 0, _blur(image, blur_sigma)
    gx = np.empty(image.shape[:2], np.int16)
    gy = np.empty(image.shape[:2], np.int16)
    # one pass (blur, derivatives, choice of channel), rows in parallel
    kernel.max_channel_sobel(np.ascontiguousarray(image), gx, gy, kernels.threads(), tap)
    return gx, gy


def strongest_channel_gradient(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 3x3 Sobel gradient of the channel with the largest ``|gx| + |gy|``, per pixel.

    ``cv2.spatialGradient`` of each channel (the image mirrored at its border without repeating
    the edge pixel), then per pixel the first channel of largest L1 norm. A grey image is its
    own strongest channel.

    Parameters
    ----------
    image : np.ndarray
        uint8 HxW or HxWx3.

    Returns
    -------
    gx, gy : np.ndarray
        int16 HxW.
    """
    if image.ndim == 2:
        return cv2.spatialGradient(image)
    channels = cv2.split(image)
    gx, gy = cv2.spatialGradient(channels[0])
    strength = cv2.add(np.abs(gx), np.abs(gy))  # at most 2040: no overflow in int16
    for channel in channels[1:]:
        cx, cy = cv2.spatialGradient(channel)
        norm = cv2.add(np.abs(cx), np.abs(cy))
        stronger = cv2.compare(norm, strength, cv2.CMP_GT)  # ties keep the earlier channel
        for chosen, candidate in ((gx, cx), (gy, cy), (strength, norm)):
            cv2.copyTo(candidate, stronger, chosen)
    return gx, gy
