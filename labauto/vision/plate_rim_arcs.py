"""Arcs along the rim: pieces of the lid's and the wall's ring lines (plate analysis, step 3).

A lid seen from above draws thin ring lines a few millimetres inside the agar's edge (its own
wall, seen with parallax), and the wall and the meniscus draw more. The opening of step 2 removes
such a line where it is thinner than ``open_mm``; where two lines lie close together, or the
image is coarse (a webcam frame resampled up), they blur into one band that survives it and
breaks into pieces along the rim. Such a piece is no colony. What tells it apart is its shape
in the dish's own polar coordinates: it runs along the rim, a colony is round. Choices made:

* **Near the rim.** Only bodies lying wholly within ``BAND_MM`` (10 mm) of the usable circle's
  edge are tested: the ring lines of the AGAR photographs lie 0-9 mm inside it.
* **A short piece** is radially thin (its points' distances from the centre span at most
  ``PIECE_RADIAL_MM``, 1.5 mm) and at least ``PIECE_RATIO`` (2) times as long along the rim.
  A round colony spans as much both ways; two colonies touching along the rim are at least
  as wide as one of them and are kept when wider than 1.5 mm.
* **A long arc** is at least ``ARC_RATIO`` (8) times as long along the rim as its mean width
  (``2 * area / perimeter``, which a parallax-tilted line keeps while it drifts in radius), with
  that mean width at most ``ARC_WIDTH_MM`` (2 mm). Seen as "stroke-shaped but as wide as a
  colony", such an arc was counted as a chain of colonies: up to 95 on one phone photo at
  4.5 px/mm, and the chain count took seconds.
* An arc is an artefact (``rejected["rim_arc"]``), never a chain of colonies.

Measured on the real plates of ``benchmarks/bench_real_plates.py`` (with the dish of
:func:`labauto.vision.dish.find_dish`), against no arc test: AGAR reported 1660 -> 1646,
matched 1579 -> 1575 (F1 0.891 -> 0.892), median count error 12.2 -> 11.1 %; phone-counts
3.3 -> 2.3 %, plates over 15 % 6 -> 4. At 7 px/mm F1 0.880 -> 0.882, phone-counts 4.8 ->
4.2 %; at 4.5 px/mm F1 0.854 -> 0.861, 4.7 -> 4.3 %. The slowest phone photo took 1.85 s
without the long-arc rule (a crescent of the meniscus counted as a chain), 0.17 s with it.
The short-piece rule is the less certain one: the pieces it drops are 2-3 times as long as
wide, as two small colonies touching along the rim are, and with ``PIECE_RATIO`` 2.5 or 3 its
gain was gone (measured with the former dish search). Without it phone-counts reads 3.3 % with
6 plates over 15 %, and the median count error at 7 px/mm 9.0 % instead of 11.1 %.
"""

from __future__ import annotations

import numpy as np

from labauto.vision.plate_params import Circle

BAND_MM = 10.0
PIECE_RADIAL_MM = 1.5
PIECE_RATIO = 2.0
ARC_RATIO = 8.0
ARC_WIDTH_MM = 2.0


def rim_arcs(
    contours: list[np.ndarray],
    index: np.ndarray,
    area: np.ndarray,
    rim: Circle,
    px_per_mm: float,
) -> np.ndarray:
    """True for every body that is an arc along the rim (see the module docstring).

    Parameters
    ----------
    contours : list of ndarray
        All contours (Nx1x2 int, ROI pixels).
    index : ndarray of int
        The contour of each body.
    area : ndarray of float
        Each body's area (pixels).
    rim : tuple of float
        The usable circle ``(cx, cy, r)`` (ROI pixels).
    px_per_mm : float
        Scale of the ROI.

    Returns
    -------
    ndarray of bool
        One entry per body.
    """
    n = len(index)
    if n == 0:
        return np.zeros(0, bool)
    cx, cy, r = (float(v) for v in rim)
    kept = [contours[k] for k in index.tolist()]
    lengths = np.array([len(c) for c in kept])
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    points = np.concatenate(kept).reshape(-1, 2).astype(np.float64)
    dx, dy = points[:, 0] - cx, points[:, 1] - cy
    rho = np.hypot(dx, dy)
    near = np.minimum.reduceat(rho, starts) >= r - BAND_MM * px_per_mm
    radial = np.maximum.reduceat(rho, starts) - np.minimum.reduceat(rho, starts)
    # the angular span round each body's mean direction (no wrap at +-pi)
    phi = np.arctan2(dy, dx)
    mean = np.arctan2(np.add.reduceat(np.sin(phi), starts), np.add.reduceat(np.cos(phi), starts))
    turn = np.angle(np.exp(1j * (phi - np.repeat(mean, lengths))))
    span = np.maximum.reduceat(turn, starts) - np.minimum.reduceat(turn, starts)
    along = span * np.add.reduceat(rho, starts) / lengths  # length along the rim, px
    # perimeter of each closed outline: every point to the next, the last to the first
    following = np.arange(len(points)) + 1
    following[starts + lengths - 1] = starts
    steps = np.hypot(*(points[following] - points).T)
    width = 2.0 * area / np.maximum(np.add.reduceat(steps, starts), 1.0)
    piece = (radial <= PIECE_RADIAL_MM * px_per_mm) & (along >= PIECE_RATIO * radial)
    arc = (width <= ARC_WIDTH_MM * px_per_mm) & (along >= ARC_RATIO * np.maximum(width, 1.0))
    return near & (piece | arc)
