"""The one image validator: what every vision entry point accepts, as a ``uint8`` array.

:func:`as_image` is called by :func:`labauto.vision.detector.detect`,
:func:`labauto.vision.plate.analyze_plate` (through the dish finder) and the file reader
:func:`labauto.imageio.read_image`, so an image given as an array or as a file is read by the
same rules:

Shape
    ``HxW`` grey, ``HxWx1`` (taken as grey), ``HxWx3`` BGR or ``HxWx4`` BGRA (the alpha channel
    is dropped). With ``color=True`` a grey image is expanded to BGR.
Samples
    * ``uint8``: as stored.
    * other integers: with ``significant_bits`` (a file's bit depth, e.g. 12-bit camera data in
      a 16-bit PNG) the range ``0 .. 2**bits - 1`` is scaled to 0-255; without it (an array
      given directly) the values must lie in 0-255 and are kept.
    * floating point: values in [0, 1] are scaled by 255, values in [0, 255] are kept (an image
      whose largest value is at most 1 is taken on the 0-1 scale); other ranges, NaN and
      infinities are refused.
    * anything else (bool, complex, objects) is refused.

Values are rounded to the nearest integer. The result is C-contiguous.
"""

from __future__ import annotations

import cv2
import numpy as np


def as_image(
    image: object,
    *,
    color: bool = False,
    min_side: int = 3,
    significant_bits: int | None = None,
    name: str = "image",
) -> np.ndarray:
    """Validate an image and return it as a C-contiguous ``uint8`` array (rules: module doc).

    Parameters
    ----------
    image : numpy.ndarray
        The image.
    color : bool
        Return ``HxWx3`` BGR always (grey expanded); otherwise grey stays ``HxW``.
    min_side : int
        Smallest accepted height and width, in pixels.
    significant_bits : int, optional
        Bit depth of integer samples (scaled to 0-255); without it, integers must lie in 0-255.
    name : str
        What the image is called in error messages (e.g. its file name).

    Returns
    -------
    numpy.ndarray
        ``uint8``, ``HxW`` or ``HxWx3``.

    Raises
    ------
    ValueError
        Not an array, empty, a wrong number of dimensions or channels, smaller than
        ``min_side``, an unsupported dtype, or sample values outside the accepted ranges; the
        message names what is wrong.
    """
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name} must be a numpy array, got {type(image).__name__}")
    if image.size == 0:
        raise ValueError(f"{name} is empty (shape {image.shape})")
    if image.ndim not in (2, 3):
        raise ValueError(
            f"{name} must be HxW (grey) or HxWx3 (BGR), got {image.ndim} dimension(s) "
            f"with shape {image.shape}"
        )
    if image.ndim == 3 and image.shape[2] not in (1, 3, 4):
        raise ValueError(
            f"{name} must have 1, 3 or 4 channels, got {image.shape[2]} (shape {image.shape})"
        )
    if min(image.shape[:2]) < min_side:
        raise ValueError(
            f"{name} must be at least {min_side}x{min_side} pixels, got shape {image.shape}"
        )
    image = _uint8_samples(image, significant_bits, name)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    elif image.ndim == 3 and image.shape[2] == 4:
        image = image[..., :3]
    if color and image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return np.ascontiguousarray(image)


def _uint8_samples(image: np.ndarray, significant_bits: int | None, name: str) -> np.ndarray:
    """The samples mapped to ``uint8`` by the rules of the module docstring."""
    dtype = image.dtype
    if dtype == np.uint8:
        return image
    if dtype == np.bool_ or dtype.kind not in "uif":
        raise ValueError(f"{name} has unsupported dtype {dtype}; use uint8, uint16 or float")
    if dtype.kind == "f" and not np.all(np.isfinite(image)):
        raise ValueError(f"{name} has NaN or infinite sample values")
    low, high = image.min(), image.max()
    if low < 0:
        raise ValueError(f"{name} has negative sample values ({low:g}) in a {dtype} image")
    if dtype.kind == "f":
        if high > 255.0:
            raise ValueError(
                f"{name} has floating-point samples from {low:g} to {high:g}; expected 0-1 or 0-255"
            )
        scale = 255.0 if high <= 1.0 else 1.0
    elif significant_bits is None:
        if high > 255:
            raise ValueError(
                f"{name} has dtype {dtype} with values {low}..{high}; integer images must lie "
                "in 0..255 (give significant_bits, or pass the file path to labauto.detect)"
            )
        return image.astype(np.uint8)
    else:
        scale = 255.0 / (2**significant_bits - 1)
    return np.clip(np.rint(image * scale), 0, 255).astype(np.uint8)


def as_grey(image: object, *, min_side: int = 3) -> np.ndarray:
    """:func:`as_image` as a ``uint8`` HxW grey image (BGR converted by ``cv2.cvtColor``)."""
    img = as_image(image, min_side=min_side)
    return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
