"""Adaptive colour segmentation against the background (eq. 1 of Teutsch et al.).

The background colour ``mu`` is estimated per channel, then every pixel gets the (weighted) sum
over channels of its squared deviation from ``mu``; pixels whose deviation exceeds ``t`` are
foreground. The paper's eq. 1 is a variance with per-channel probabilities ``P(x_i)`` that "should
be weighted differently for each channel" when the background is known: ``channel_weights`` are
those weights.

Background estimate: the per-channel **median** (default) or **mode** of the histogram, optionally
over a mask. Both are robust as long as the background covers more than half of the (masked)
pixels (median) or is the most frequent colour (mode), as on an agar plate.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np


def _check_uint8(image: np.ndarray) -> None:
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise ValueError(
            f"segmentation needs a uint8 HxW or HxWx3 image, got {image.dtype} {image.shape}"
        )


def background_mean(
    image: np.ndarray, mask: np.ndarray | None = None, method: str = "median"
) -> np.ndarray:
    """Estimate the background colour per channel from the histogram.

    Parameters
    ----------
    image : np.ndarray
        uint8 HxW or HxWx3 image.
    mask : np.ndarray, optional
        HxW mask; only nonzero pixels are used.
    method : str
        ``"median"`` or ``"mode"``.

    Returns
    -------
    np.ndarray
        (C,) float64 background value of each channel (C = 1 or 3).
    """
    _check_uint8(image)
    if method not in ("median", "mode"):
        raise ValueError(f"method must be 'median' or 'mode', got {method!r}")
    if mask is not None:
        if mask.shape != image.shape[:2]:
            raise ValueError(f"mask shape {mask.shape} does not match image {image.shape[:2]}")
        mask = (mask != 0).astype(np.uint8)
        if not mask.any():
            raise ValueError("mask selects no pixels")
    n_channels = 1 if image.ndim == 2 else image.shape[2]
    values = np.empty(n_channels)
    for c in range(n_channels):
        hist = cv2.calcHist([image], [c], mask, [256], [0, 256]).ravel()
        if method == "mode":
            values[c] = float(np.argmax(hist))
        else:
            cum = np.cumsum(hist)
            values[c] = float(np.searchsorted(cum, cum[-1] / 2.0))
    return values


def color_deviation(
    image: np.ndarray,
    mean: Sequence[float] | np.ndarray,
    channel_weights: Sequence[float] | None = None,
) -> np.ndarray:
    """Per-pixel weighted sum over channels of the squared deviation from ``mean`` (eq. 1).

    Parameters
    ----------
    image : np.ndarray
        uint8 HxW or HxWx3 image.
    mean : sequence of float
        Background value per channel.
    channel_weights : sequence of float, optional
        Weight per channel (default all 1).

    Returns
    -------
    np.ndarray
        float32 HxW map of ``sum_c w_c (x_c - mu_c)^2`` in grey levels squared.
    """
    _check_uint8(image)
    n_channels = 1 if image.ndim == 2 else image.shape[2]
    mean_arr = np.asarray(mean, dtype=np.float64).ravel()
    weights = (
        np.ones(n_channels)
        if channel_weights is None
        else np.asarray(channel_weights, dtype=np.float64).ravel()
    )
    if mean_arr.size != n_channels or weights.size != n_channels:
        raise ValueError(
            f"mean ({mean_arr.size}) and channel_weights ({weights.size}) need one value per "
            f"channel ({n_channels})"
        )
    if np.any(weights < 0):
        raise ValueError(f"channel_weights must be >= 0, got {weights.tolist()}")
    levels = np.arange(256, dtype=np.float64)[:, None]
    lut = (weights * (levels - mean_arr) ** 2).astype(np.float32)  # (256, C)
    if n_channels == 1:
        return cv2.LUT(image, lut[:, 0].reshape(256, 1))
    squared = cv2.LUT(image, lut.reshape(256, 1, n_channels))
    return cv2.transform(squared, np.ones((1, n_channels), np.float32))


def segment(
    image: np.ndarray,
    threshold: float,
    channel_weights: Sequence[float] | None = None,
    mask: np.ndarray | None = None,
    method: str = "median",
) -> tuple[np.ndarray, np.ndarray]:
    """Binarise ``image`` against its estimated background colour (eq. 1).

    Parameters
    ----------
    image : np.ndarray
        uint8 HxW or HxWx3 image.
    threshold : float
        ``t``: foreground where the deviation exceeds it (grey levels squared).
    channel_weights : sequence of float, optional
        Weight per channel.
    mask : np.ndarray, optional
        Pixels used to estimate the background (e.g. the plate area).
    method : str
        Background estimate, ``"median"`` or ``"mode"``.

    Returns
    -------
    foreground, deviation
        uint8 HxW map (255 = foreground) and the float32 deviation map.
    """
    if threshold < 0:
        raise ValueError(f"threshold must be >= 0, got {threshold}")
    mean = background_mean(image, mask, method)
    deviation = color_deviation(image, mean, channel_weights)
    foreground = cv2.compare(deviation, float(threshold), cv2.CMP_GT)
    return foreground, deviation
