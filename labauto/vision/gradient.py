"""Colour image gradient (eq. 2 of Teutsch et al.) and image validation.

The paper measures colour edge strength as the sum of the squared channel gradients (eq. 2) and
notes that directions in different channels can disagree. We take, per pixel, the gradient
``(gx, gy)`` of the channel whose gradient is largest (L1 norm ``|gx| + |gy|``, cheaper than L2
and selecting the same channel in all but near-ties). This is the choice OpenCV's own colour Canny
makes; it keeps a true image direction (no sign ambiguity of a structure tensor) and for the
common edge between two uniform colours, where all channel gradients are parallel, its direction
equals the structure tensor's principal direction. Its magnitude is the largest channel's, which
is within a factor sqrt(3) of the eq. 2 magnitude; thresholds are given on this scale.

Derivatives are the 3x3 Sobel operator after an optional Gaussian blur (one ``cv2.GaussianBlur``
call on all channels), in integer arithmetic on 8-bit data, so the result is int16 and can go
straight into ``cv2.Canny(dx, dy, ...)``. For a colour image the three channel gradients and the
choice among them are one compiled pass (:mod:`labauto.vision.kernels.gradient`); each channel's
derivatives equal ``cv2.spatialGradient``'s.
"""

from __future__ import annotations

import cv2
import numpy as np

from labauto.vision import kernels
from labauto.vision.kernels.gradient import max_channel_sobel


def as_uint8_image(image: object, name: str = "image") -> np.ndarray:
    """Validate an image and return it as a C-contiguous uint8 HxW or HxWx3 array.

    Parameters
    ----------
    image : array-like
        HxW grey or HxWx3 colour (BGR) image; HxWx1 is taken as grey. uint8 is used as is;
        other integer types must lie in 0-255; float images are taken on a 0-255 scale when
        their maximum exceeds 1.0, else on a 0-1 scale (scaled by 255); both are rounded and
        clipped to 0-255.
    name : str
        Name used in error messages.

    Raises
    ------
    ValueError
        If the image is not a numpy array, is empty, has the wrong number of dimensions or
        channels, has an unsupported dtype, or contains NaN/inf.
    """
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name} must be a numpy array, got {type(image).__name__}")
    if image.size == 0:
        raise ValueError(f"{name} is empty (shape {image.shape})")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.ndim not in (2, 3):
        raise ValueError(
            f"{name} must be HxW (grey) or HxWx3 (BGR), got {image.ndim} dimension(s) "
            f"with shape {image.shape}"
        )
    if image.ndim == 3 and image.shape[2] != 3:
        raise ValueError(
            f"{name} must have 1 or 3 channels, got {image.shape[2]} (shape {image.shape})"
        )
    if image.shape[0] < 3 or image.shape[1] < 3:
        raise ValueError(f"{name} must be at least 3x3 pixels, got shape {image.shape}")
    dtype = image.dtype
    if dtype == np.uint8:
        return np.ascontiguousarray(image)
    if dtype == np.bool_ or not (
        np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating)
    ):
        raise ValueError(f"{name} has unsupported dtype {dtype}; use uint8 or float")
    if np.issubdtype(dtype, np.integer):
        lo, hi = int(image.min()), int(image.max())
        if lo < 0 or hi > 255:
            raise ValueError(
                f"{name} has dtype {dtype} with values {lo}..{hi}; integer images must lie "
                "in 0..255 (convert 16-bit images first)"
            )
        return np.ascontiguousarray(image, dtype=np.uint8)
    if not np.all(np.isfinite(image)):
        raise ValueError(f"{name} contains NaN or infinite values")
    scale = 255.0 if float(image.max()) <= 1.0 else 1.0
    return np.clip(np.rint(image * scale), 0, 255).astype(np.uint8)


def _blur(image: np.ndarray, blur_sigma: float) -> np.ndarray:
    if blur_sigma <= 0:
        return image
    ksize = 2 * max(1, round(2.0 * blur_sigma)) + 1  # truncated at ~2 sigma
    return cv2.GaussianBlur(image, (ksize, ksize), blur_sigma)  # all channels in one call


def color_gradient(image: np.ndarray, blur_sigma: float = 0.7) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel colour gradient: 3x3 Sobel of the channel with the largest gradient.

    Parameters
    ----------
    image : np.ndarray
        uint8 HxW or HxWx3 image (see :func:`as_uint8_image`).
    blur_sigma : float
        Standard deviation (pixels) of a Gaussian blur applied to each channel first, with a
        kernel truncated at about 2 sigma (3x3 up to sigma 0.7, 5x5 up to 1.2); 0 for none.

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
    blurred = _blur(image, blur_sigma)
    if image.ndim == 2:
        return cv2.spatialGradient(blurred)
    gx = np.empty(image.shape[:2], np.int16)
    gy = np.empty(image.shape[:2], np.int16)
    max_channel_sobel(blurred, gx, gy, kernels.threads())  # one pass, rows in parallel
    return gx, gy
