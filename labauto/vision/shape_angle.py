"""The shape angle D_alpha of Teutsch et al. (section 3.2, eq. 3) of all contours of an image.

For every contour point ``p_i`` with image gradient ``g_i`` and vector ``m_i = c - p_i`` to the
contour's centre of gravity ``c``, the deviation angle is

    alpha_i = arccos(|g_i . m_i| / (|g_i| |m_i|))

Choices (the paper is silent or ambiguous on these):

* **Polarity invariance.** The paper's eq. 3 uses ``arccos(g . m)`` whose range is [0, 180]; a
  dark object on a bright background would then read ~180 degrees instead of ~0. We take the
  absolute value of the cosine, so bright-on-dark and dark-on-bright objects give the same value
  and every alpha lies in [0, 90] degrees. This matches the paper's Table 2 (all values <= 90 and
  a line at ~90). A circle gives 0; a straight line gives 90.
* **Centre of gravity.** The area centroid of the polygon through the points (the centroid of
  the filled shape, exact for any polygon); an open contour is closed by its chord, which keeps
  the centroid of a shape with a small gap (a triangle whose tip Canny broke, a colony with 15%
  of its edge missing) where it belongs, whereas the mean of the points would move away from the
  gap. When that polygon has (almost) no area, e.g. a line or a shallow arc, the mean of the
  points is used (see :func:`polygon_centroids`).
* **Centroid inside.** Point-in-polygon (even-odd rule) against the polygon through the points;
  an open contour is closed by its chord (last point back to the first).
* **Gaps.** An open contour is a DES only if at most ``DEFAULT_MAX_GAP_FRACTION`` (0.25) of its
  outline is missing (chord between its ends over length plus chord); the paper's method works
  "even if the contour is open up to 15%".
* **Statistic.** The median (the paper's robust choice, O(n) per contour by selection) and the
  mean are both returned; a DES uses the median by default. The median of an even count is the
  mean of the two middle values.
* **Points with no direction** (zero gradient, or the point coincides with the centroid) are
  given alpha = 90 degrees (the least circular value), so they can never make a shape look rounder.

Default DES threshold: 60 degrees (median). Analytic medians from the exact geometry (uniform
arc-length sampling, see tests/vision/test_shape_angle.py): circle 0, ellipse 1:1.5 16.5,
1:2 28.3, 1:3 44.1, 1:4 53.9; square 26.6; equilateral triangle 40.9; 5-point star (inner
radius half the outer) 51.9; a thick line 85-90.
Rendered shapes read within 2 degrees of these. The paper calls typical DES "about pi/6" and puts
the limit of the method at an axis ratio of about 1:4 (its Table 2 (k), 53.72, is such a shape),
with artefacts at 70-89 degrees. So 60 degrees keeps every ellipse down to 1:4 with a 6 degree
margin for rasterisation and noise and rejects lines and ragged artefacts. Like the paper's rule
it does not reject squares, triangles or 5-point stars whose centroid is inside (D_alpha 27-52);
the harmonic shape label tells those apart (the paper: "the square itself seems to be a problem").

Implementation: numpy over all contours of an image at once (per-contour sums by
``np.add.reduceat``, medians by one sort of all angles grouped by contour); no compiled kernel,
because none saved a real share of a plate's or an image's time (``benchmarks/bench_kernels.py``
in the issue 16 note). alpha_i is evaluated as ``atan2(|g_i x m_i|, |g_i . m_i|)``, the same
angle, which unlike ``arccos`` stays accurate to rounding near 0 degrees and needs no norms.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: An open contour's chord-closed polygon gives the centroid when its area exceeds this times
#: the mean squared distance of the points from their mean; otherwise the points' mean does.
OPEN_MIN_AREA_RATIO = 0.1

#: Largest missing share of the outline (chord / (length + chord)) of a DES. The paper's method
#: "preserves its high recognition rate even if the contour is open up to 15%"; 0.25 keeps those
#: with a margin and rejects arcs such as one side of a crescent that Canny split at its tips
#: (a 230-degree arc gives 0.31, a circle missing 15% gives 0.15).
DEFAULT_MAX_GAP_FRACTION = 0.25

#: Default D_alpha threshold (degrees) under which a contour with its centroid inside is a DES.
DEFAULT_DES_THRESHOLD_DEG = 60.0


@dataclass(frozen=True)
class ShapeAngles:
    """Shape angles of K contours (arrays of length K).

    Attributes
    ----------
    centroid : np.ndarray
        (K, 2) float, centre of gravity ``(x, y)`` of each contour.
    d_alpha_mean : np.ndarray
        (K,) float, mean deviation angle in degrees, in [0, 90].
    d_alpha_median : np.ndarray
        (K,) float, median deviation angle in degrees, in [0, 90].
    centroid_inside : np.ndarray
        (K,) bool, the centroid lies inside the contour's polygon (open ones closed by the chord).
    area : np.ndarray
        (K,) float, absolute area of the polygon through the points (open ones closed by the
        chord), in square pixels.
    gap_fraction : np.ndarray
        (K,) float, the share of the closed outline that is missing: chord between the ends
        over (length along the points + chord); 0 for closed contours.
    """

    centroid: np.ndarray
    d_alpha_mean: np.ndarray
    d_alpha_median: np.ndarray
    centroid_inside: np.ndarray
    area: np.ndarray
    gap_fraction: np.ndarray

    def __len__(self) -> int:
        return int(self.d_alpha_mean.shape[0])

    def is_des(
        self,
        threshold_deg: float = DEFAULT_DES_THRESHOLD_DEG,
        statistic: str = "median",
        max_gap_fraction: float = DEFAULT_MAX_GAP_FRACTION,
    ) -> np.ndarray:
        """Return the (K,) bool DES mask: centroid inside, D_alpha below ``threshold_deg`` and
        at most ``max_gap_fraction`` of the outline missing."""
        return (
            self.centroid_inside
            & (self.statistic(statistic) < threshold_deg)
            & (self.gap_fraction <= max_gap_fraction)
        )

    def statistic(self, name: str) -> np.ndarray:
        """Return ``d_alpha_median`` for ``"median"`` or ``d_alpha_mean`` for ``"mean"``."""
        if name == "median":
            return self.d_alpha_median
        if name == "mean":
            return self.d_alpha_mean
        raise ValueError(f"statistic must be 'median' or 'mean', got {name!r}")


def _closed_from_ends(points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    first = np.rint(points[offsets[:-1]])
    last = np.rint(points[offsets[1:] - 1])
    return np.all(np.abs(first - last) <= 1, axis=1) & (np.diff(offsets) > 2)


def _points(points: object, name: str = "points") -> np.ndarray:
    """``points`` as a C-contiguous (N, 2) float64 array; ValueError naming it otherwise."""
    out = np.ascontiguousarray(points, dtype=np.float64)
    if out.ndim != 2 or out.shape[1] != 2:
        raise ValueError(f"{name} must be (N, 2), got shape {out.shape}")
    return out


def _offsets(offsets: object) -> np.ndarray:
    """``offsets`` as a C-contiguous int64 array; the kernel checks the values."""
    out = np.ascontiguousarray(offsets, dtype=np.int64)
    if out.ndim != 1 or out.shape[0] < 1:
        raise ValueError("offsets must start at 0 and end at len(points)")
    return out


def _closed(closed: np.ndarray | None, points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(K,) uint8 view of the closed flags (default: the ends are 8-neighbours)."""
    if closed is None:
        if offsets[0] != 0 or offsets[-1] != points.shape[0] or np.any(np.diff(offsets) < 1):
            return np.zeros(offsets.shape[0] - 1, np.uint8)  # the kernel rejects the offsets
        closed = _closed_from_ends(points, offsets)
    flags = np.ascontiguousarray(closed, dtype=bool)
    if flags.shape != (offsets.shape[0] - 1,):
        raise ValueError(
            f"closed must have one entry per contour ({offsets.shape[0] - 1}), got {flags.shape}"
        )
    return flags.view(np.uint8)


def polygon_centroids(
    points: np.ndarray, offsets: np.ndarray, closed: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Centres of gravity and polygon areas of many contours.

    Parameters
    ----------
    points : np.ndarray
        (N, 2) concatenated points.
    offsets : np.ndarray
        (K + 1,) contour boundaries.
    closed : np.ndarray, optional
        (K,) bool; default: ends are 8-neighbours.

    Returns
    -------
    centroid : np.ndarray
        (K, 2): the area centroid of the polygon through the points (open contours closed by
        their chord). The mean of the points instead when the polygon is degenerate: area below
        1e-6 (closed) or ``OPEN_MIN_AREA_RATIO`` = 0.1 (open) times the mean squared distance of
        the points from their mean (a disk gives pi, a straight line 0).
    area : np.ndarray
        (K,) absolute polygon area (open contours closed by their chord).
    """
    centroid, area, _ = _geometry(points, offsets, closed)
    return centroid, area


def gap_fractions(
    points: np.ndarray, offsets: np.ndarray, closed: np.ndarray | None = None
) -> np.ndarray:
    """(K,) missing share of each outline: chord / (length along the points + chord).

    0 for closed contours; about the missing fraction of the perimeter for a convex shape with
    one gap (a chord is a little shorter than the arc it replaces).
    """
    return _geometry(points, offsets, closed)[2]


def _geometry(
    points: np.ndarray, offsets: np.ndarray, closed: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroids (K, 2), areas (K,) and gap fractions (K,) of the contours.

    Per contour, about its first point ``p0`` (for precision): the shoelace sums of the polygon
    through the points (the closing edge back to ``p0`` adds 0), the points' sums for their
    mean and spread, and, for an open contour, its length and the chord between its ends.
    """
    points = _points(points)
    offsets = _offsets(offsets)
    _check_offsets(offsets, points.shape[0])
    flags = _closed(closed, points, offsets).view(bool)
    if not np.all(np.isfinite(points)):
        raise ValueError("points must be finite")
    start, n = offsets[:-1], np.diff(offsets)
    origin = points[start]
    rel = points - np.repeat(origin, n, axis=0)
    x, y = rel[:, 0], rel[:, 1]
    # edge i -> i + 1 within a contour (the last point of each contour starts no edge)
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    last = offsets[1:] - 1
    xn[last], yn[last] = x[last], y[last]
    cross = x * yn - xn * y
    cross[last] = 0.0
    step = np.hypot(xn - x, yn - y)

    def per_contour(values: np.ndarray) -> np.ndarray:
        return np.add.reduceat(values, start)

    twice_area = per_contour(cross)
    moment_x, moment_y = per_contour((x + xn) * cross), per_contour((y + yn) * cross)
    sx, sy, ss = per_contour(x), per_contour(y), per_contour(x * x + y * y)
    spread = (ss - (sx * sx + sy * sy) / n) / n  # mean squared distance from the mean
    area = np.abs(twice_area) / 2.0
    # an open contour: the chord-closed polygon if it encloses a real area (a disk has
    # area / spread = pi, a straight line 0), else the points' mean
    min_ratio = np.where(flags, 1e-6, OPEN_MIN_AREA_RATIO)
    polygonal = area > min_ratio * spread
    with np.errstate(divide="ignore", invalid="ignore"):
        centroid = np.where(
            polygonal[:, None],
            np.column_stack((moment_x, moment_y)) / (3.0 * twice_area[:, None]),
            np.column_stack((sx, sy)) / n[:, None],
        )
        chord = np.hypot(x[last], y[last])
        total = per_contour(step) + chord
        gap = np.where(~flags & (total > 0), chord / total, 0.0)
    return origin + centroid, area, gap


def _check_offsets(offsets: np.ndarray, n_points: int) -> None:
    if offsets[0] != 0 or offsets[-1] != n_points:
        raise ValueError("offsets must start at 0 and end at len(points)")
    if np.any(np.diff(offsets) < 1):
        raise ValueError("every contour needs at least one point")


def _crossings(query: np.ndarray, points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(K,) bool even-odd test of query point k against polygon k (last point joins first)."""
    n = np.diff(offsets)
    q = np.repeat(query, n, axis=0)
    x0, y0 = points[:, 0], points[:, 1]
    # the edge into point i comes from point i - 1 (from the last point for a contour's first)
    before = np.arange(points.shape[0]) - 1
    before[offsets[:-1]] = offsets[1:] - 1
    xp, yp = x0[before], y0[before]
    with np.errstate(divide="ignore", invalid="ignore"):
        hits = ((yp > q[:, 1]) != (y0 > q[:, 1])) & (
            q[:, 0] < xp + (q[:, 1] - yp) * (x0 - xp) / (y0 - yp)
        )
    return np.add.reduceat(hits.astype(np.int64), offsets[:-1]) % 2 == 1


def points_in_polygons(query: np.ndarray, points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test of query point k against polygon k, for all k at once.

    Each polygon runs through its contour's points and closes from the last point back to the
    first (for an open contour, its chord). Points exactly on an edge may go either way.

    Parameters
    ----------
    query : np.ndarray
        (K, 2) points ``(x, y)``.
    points, offsets : np.ndarray
        Concatenated contours as in :func:`shape_angles`.

    Returns
    -------
    np.ndarray
        (K,) bool.
    """
    points = _points(points)
    offsets = _offsets(offsets)
    query = _points(query, "query")
    _check_offsets(offsets, points.shape[0])
    if query.shape[0] != offsets.shape[0] - 1:
        raise ValueError("query and inside must have one entry per contour")
    return _crossings(query, points, offsets)


def shape_angles(
    points: np.ndarray,
    gradients: np.ndarray,
    offsets: np.ndarray,
    closed: np.ndarray | None = None,
) -> ShapeAngles:
    """Compute D_alpha (mean and median), centroid and centroid-inside for many contours at once.

    Parameters
    ----------
    points : np.ndarray
        (N, 2) float, all contour points ``(x, y)`` concatenated in contour order.
    gradients : np.ndarray
        (N, 2) float, image gradient ``(gx, gy)`` at each point (any sign, any scale).
    offsets : np.ndarray
        (K + 1,) int, contour k is ``points[offsets[k]:offsets[k + 1]]``; ``offsets[0] == 0`` and
        ``offsets[-1] == N``. Every contour must have at least 1 point.
    closed : np.ndarray, optional
        (K,) bool; if omitted a contour is closed when its first and last points are 8-neighbours.

    Returns
    -------
    ShapeAngles

    Raises
    ------
    ValueError
        If points and gradients are not both (N, 2), the offsets do not split the points into
        non-empty contours, ``closed`` is not (K,), or a point or gradient is not finite.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    gradients = np.asarray(gradients)
    if gradients.dtype != np.float32:
        gradients = np.asarray(gradients, dtype=np.float64)
    gradients = np.ascontiguousarray(gradients)
    if points.ndim != 2 or points.shape[1] != 2 or gradients.shape != points.shape:
        raise ValueError(
            f"points and gradients must both be (N, 2), got {points.shape} and {gradients.shape}"
        )
    offsets = _offsets(offsets)
    _check_offsets(offsets, points.shape[0])
    if not np.all(np.isfinite(gradients)):
        raise ValueError("points and gradients must be finite")
    centroid, area, gap = _geometry(points, offsets, closed)
    alpha = deviation_angles(points, gradients, np.repeat(centroid, np.diff(offsets), axis=0))
    n = np.diff(offsets)
    mean = np.add.reduceat(alpha, offsets[:-1]) / n
    inside = _crossings(centroid, points, offsets)
    return ShapeAngles(centroid, mean, _medians(alpha, offsets), inside, area, gap)


def deviation_angles(points: np.ndarray, gradients: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Eq. 3 per point: the angle (degrees, in [0, 90]) between ``g_i`` and ``m_i = c - p_i``.

    ``atan2(|g x m|, |g . m|)``; 90 where ``g`` or ``m`` is zero (no direction).
    """
    m = centre - points
    gx, gy = gradients[:, 0].astype(np.float64), gradients[:, 1].astype(np.float64)
    dot = np.abs(gx * m[:, 0] + gy * m[:, 1])
    cross = np.abs(gx * m[:, 1] - gy * m[:, 0])
    alpha = np.degrees(np.arctan2(cross, dot))
    alpha[(dot == 0.0) & (cross == 0.0)] = 90.0
    return alpha


def _medians(values: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Median of each contour's values (mean of the two middle ones for an even count)."""
    n = np.diff(offsets)
    small = np.int16 if n.shape[0] < 2**15 else np.int64  # 16 bits: a radix sort below
    contour = np.repeat(np.arange(n.shape[0], dtype=small), n)
    by_value = np.argsort(values)
    ordered = values[by_value[np.argsort(contour[by_value], kind="stable")]]
    low = offsets[:-1] + (n - 1) // 2
    high = offsets[:-1] + n // 2
    return 0.5 * (ordered[low] + ordered[high])


def shape_angle(
    points: np.ndarray, gradients: np.ndarray, closed: bool | None = None
) -> tuple[float, float, tuple[float, float], bool]:
    """Shape angle of one contour.

    Parameters
    ----------
    points : np.ndarray
        (n, 2) float contour points ``(x, y)`` in order.
    gradients : np.ndarray
        (n, 2) float image gradient at each point.
    closed : bool, optional
        Whether the contour is closed; by default, when its ends are 8-neighbours.

    Returns
    -------
    tuple
        ``(d_alpha_median_deg, d_alpha_mean_deg, (cx, cy), centroid_inside)``.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    offsets = np.array([0, points.shape[0]], np.int64)
    flags = None if closed is None else np.array([bool(closed)])
    result = shape_angles(points, np.asarray(gradients).reshape(-1, 2), offsets, flags)
    centroid = (float(result.centroid[0, 0]), float(result.centroid[0, 1]))
    return (
        float(result.d_alpha_median[0]),
        float(result.d_alpha_mean[0]),
        centroid,
        bool(result.centroid_inside[0]),
    )
