"""Contours of an image, both ways of section 3.1, in one vectorisable container.

All contours of an image live in one :class:`Contours`: the points of every contour concatenated
into an (N, 2) float array plus an offsets array, with the image gradient at every point, so the
shape angle and other per-contour statistics run over all contours at once
(``np.add.reduceat`` / ``np.bincount``).

* :func:`canny_contours`: colour gradient (eq. 2), Canny hysteresis, ordered edge linking,
  optional sub-pixel refinement. Gradients are those of the colour gradient field.
* :func:`color_contours`: adaptive colour segmentation (eq. 1) and boundary tracing in the
  8-neighbourhood. The points are the boundary pixels of the foreground regions (the inner
  boundary, so about half a pixel inside the true edge); the gradient at each point is the
  3x3 Sobel gradient of the deviation map (eq. 1), which points across the boundary.

A contour is closed when its first and last points are 8-neighbours.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.vision.edges import canny_edges, edge_contours, traces_to_chains
from labauto.vision.gradient import color_gradient
from labauto.vision.segmentation import segment


@dataclass(frozen=True)
class Contours:
    """K contours stored flat.

    Attributes
    ----------
    points : np.ndarray
        (N, 2) float64 points ``(x, y)`` of all contours, each contour in order.
    offsets : np.ndarray
        (K + 1,) int64; contour k is ``points[offsets[k]:offsets[k + 1]]``.
    gradients : np.ndarray
        (N, 2) float32 image gradient ``(gx, gy)`` at each point.
    closed : np.ndarray
        (K,) bool, ends are 8-neighbours.
    """

    points: np.ndarray
    offsets: np.ndarray
    gradients: np.ndarray
    closed: np.ndarray

    def __len__(self) -> int:
        return int(self.offsets.shape[0] - 1)

    @property
    def lengths(self) -> np.ndarray:
        """(K,) number of points of each contour."""
        return np.diff(self.offsets)

    def __getitem__(self, k: int) -> np.ndarray:
        """Points (n, 2) of contour ``k``."""
        return self.points[self.offsets[k] : self.offsets[k + 1]]

    @classmethod
    def from_list(cls, contours: Sequence[np.ndarray], gradients: Sequence[np.ndarray]) -> Contours:
        """Build from per-contour (n, 2) point and gradient arrays."""
        if len(contours) == 0:
            return cls.empty()
        pts = np.concatenate([np.asarray(c, np.float64).reshape(-1, 2) for c in contours])
        grads = np.concatenate([np.asarray(g, np.float32).reshape(-1, 2) for g in gradients])
        offsets = np.concatenate(([0], np.cumsum([len(c) for c in contours]))).astype(np.int64)
        return cls(pts, offsets, grads, ends_adjacent(pts, offsets))

    @classmethod
    def empty(cls) -> Contours:
        """No contours."""
        return cls(
            np.empty((0, 2)),
            np.zeros(1, np.int64),
            np.empty((0, 2), np.float32),
            np.empty(0, bool),
        )


def ends_adjacent(points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(K,) bool: the first and last points of each contour are 8-neighbours (or equal).

    Uses rounded coordinates, so it applies to sub-pixel points too. A 1- or 2-point contour is
    not closed.
    """
    if offsets.shape[0] < 2:
        return np.empty(0, bool)
    first = np.rint(points[offsets[:-1]])
    last = np.rint(points[offsets[1:] - 1])
    near = np.all(np.abs(first - last) <= 1, axis=1)
    return near & (np.diff(offsets) > 2)


def canny_contours(
    image: np.ndarray,
    *,
    blur_sigma: float = 0.7,
    low: float = 40.0,
    high: float = 100.0,
    min_length: int = 20,
    max_length: int | None = None,
    subpixel: bool = True,
) -> Contours:
    """Ordered contours from the colour Canny detector.

    Parameters
    ----------
    image : np.ndarray
        uint8 HxW or HxWx3 image.
    blur_sigma : float
        Gaussian blur before the 3x3 Sobel gradient (0: none).
    low, high : float
        Canny hysteresis thresholds on the gradient magnitude.
    min_length, max_length : int
        Keep contours with that many points (max None: no limit).
    subpixel : bool
        Refine the points to sub-pixel precision.

    Returns
    -------
    Contours
    """
    gx, gy = color_gradient(image, blur_sigma)
    edges = canny_edges(gx, gy, low, high)
    # linking, gradient lookup and sub-pixel refinement: one kernel pass (edges.edge_contours);
    # ``closed`` is ends_adjacent of the pixel chains
    points, offsets, grads, closed = edge_contours(edges, gx, gy, min_length, max_length, subpixel)
    if points.shape[0] == 0:
        return Contours.empty()
    return Contours(points, offsets, grads, closed)


def _sobel_at(field: np.ndarray, points: np.ndarray) -> np.ndarray:
    """3x3 Sobel gradient of a float HxW field at integer points (x, y), borders replicated."""
    h, w = field.shape
    x, y = points[:, 0].astype(np.intp), points[:, 1].astype(np.intp)
    xm, xp = np.maximum(x - 1, 0), np.minimum(x + 1, w - 1)
    ym, yp = np.maximum(y - 1, 0), np.minimum(y + 1, h - 1)
    f = field
    gx = (f[ym, xp] + 2 * f[y, xp] + f[yp, xp]) - (f[ym, xm] + 2 * f[y, xm] + f[yp, xm])
    gy = (f[yp, xm] + 2 * f[yp, x] + f[yp, xp]) - (f[ym, xm] + 2 * f[ym, x] + f[ym, xp])
    return np.column_stack((gx, gy)).astype(np.float32)


def color_contours(
    image: np.ndarray,
    *,
    threshold: float = 900.0,
    channel_weights: Sequence[float] | None = None,
    mask: np.ndarray | None = None,
    min_length: int = 20,
    max_length: int | None = None,
) -> Contours:
    """Contours of the adaptive colour segmentation (eq. 1).

    Parameters
    ----------
    image : np.ndarray
        uint8 HxW or HxWx3 image.
    threshold : float
        ``t`` of eq. 1 (grey levels squared; 900 = a deviation of 30 levels in one channel).
    channel_weights : sequence of float, optional
        Per-channel weights of eq. 1.
    mask : np.ndarray, optional
        Pixels used to estimate the background colour.
    min_length, max_length : int
        Keep contours with that many points (max None: no limit).

    Returns
    -------
    Contours
        Boundaries of the foreground regions and of their holes, traced in the
        8-neighbourhood, each pixel once per contour.
    """
    foreground, deviation = segment(image, threshold, channel_weights, mask)
    traces, _ = cv2.findContours(foreground, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    traces = [t for t in traces if len(t) >= min_length]
    pix, offsets = traces_to_chains(traces, image.shape[1], min_length, max_length)
    if pix.shape[0] == 0:
        return Contours.empty()
    grads = _sobel_at(deviation, pix)
    return Contours(pix.astype(np.float64), offsets, grads, ends_adjacent(pix, offsets))
