"""General shape descriptors of a contour (Table 1 of Teutsch et al.).

The paper lists eight quick descriptors of a closed contour and says they are "an extremely fast
but also a weak indicator" of shape. This module computes them for one ordered contour, plus the
quantities they are built from (axes, area, perimeters) and the rectangularity that
:func:`labauto.vision.harmonics.classify_shape` uses to recognise rectangles.

Choices where the paper is vague (each is a documented decision, not an accident):

* **Polygon.** The points are the vertices of a polygon in the given order. For ``closed=True`` the
  last point joins the first; for ``closed=False`` the perimeter stops at the last point, while
  area, centroid and convex hull are those of the polygon closed by the chord (the ends joined),
  so a contour with a small gap still has a sensible area. Consecutive duplicate points are
  dropped.
* **Centre of gravity.** The area centroid of the polygon (the centroid of the filled shape,
  exact for any polygon and independent of how densely each part is sampled). A polygon with
  (nearly) no area (compactness ``4 pi area / perimeter^2`` at most 1e-9), such as a line traced
  forth and back, uses the length-weighted centroid of its segments instead.
* **Semi-axes a >= b.** The paper approximates them "by the shortest and longest distance of two
  points to the center of gravity". Extreme distances depend on one or two noisy points, so the
  default (``axes="moments"``) takes them from the second moments of the filled polygon: a and b
  are the semi-axes of the ellipse with the same area moments, ``a = 2 sqrt(l1)``,
  ``b = 2 sqrt(l2)`` with ``l1 >= l2`` the eigenvalues of the area covariance. This is exact for
  a filled ellipse; for an ellipse sampled as a polygon the ratio ``b/a`` (hence f0, f, eps) is
  exact when the samples are uniform in the ellipse parameter and within O(1/n^2) otherwise, and
  a, b themselves are low by the polygon's missing area, O(1/n^2). Without area (a line) the
  moments are those of the curve with uniform mass per length, scaled so a segment of length L
  has ``a = L/2`` and ``b = 0``. ``axes="extent"`` gives the paper's literal rule: a is the
  largest distance from the centroid to a vertex and b the shortest distance from the centroid to
  the polygon's edges (exact for a polygon).
* **Elongation.** Long side over short side of the minimum-area rotated bounding box of the
  convex hull (rotating calipers), so it is rotation invariant and >= 1; ``inf`` for a straight
  line. The paper's width/height of the axis-aligned box would change with rotation.
* **Rectangularity** (not in Table 1): area over the area of that same box; 1 for a rectangle,
  pi/4 for an ellipse, 1/2 for any triangle.
* **Bending energy.** ``Ec = (1/P) sum_i w_i kappa_i^2`` with ``w_i`` half the lengths of the two
  segments at vertex i and ``P = sum_i w_i``: the arc-length mean of the squared curvature, which
  equals the paper's ``(1/L) sum_p kappa(p)^2`` for equally spaced points. ``kappa_i`` is the
  Menger curvature (inverse radius of the circle through the vertex and its two neighbours),
  exact for points on a circle at any spacing: a circle of radius r gives ``1/r^2``. Before the
  curvature the coordinates are smoothed along the contour by a Gaussian of ``curvature_sigma``
  samples (pass 0 for exact analytic points). The default (None) suits pixel chains:
  ``max(2, 0.5 sqrt(P / 2 pi))`` samples, because the longest straight pixel runs of a
  digitised circle of radius r grow like ``sqrt(2 r)``; on rasterised discs of radius 10-80 px
  it gives Ec within 17 % of ``1/r^2`` (+17, +10, +7, +5 % at r = 10, 20, 40, 80) where a
  fixed 2 samples is 3 times too high at r = 80 and no smoothing 24-1400 times.
  For an open contour the two end points have no
  curvature and are left out. Ec has units px^-2 like the paper's; ``bending_energy_normalised``
  multiplies by ``(P / 2 pi)^2`` so it is 1 for a circle, scale-free and >= 1 for any closed
  curve.

Implementation: the per-contour loops (dropping repeated points, area and centroid, second
moments, perimeters, the convex hull by Andrew's monotone chain and the minimum-area box by
rotating calipers over it, all in float64) are written out in numpy in
:mod:`labauto.vision.shape_plain` (the reference); the compiled kernel
:func:`labauto.vision.kernels.shape.measure_contours` does the same for any number of contours
in one call. :func:`shape_descriptors` is a batch of one and :func:`shape_descriptors_batch`
the batch the detector uses. The same call also computes the polar series of
:mod:`labauto.vision.harmonics`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from types import ModuleType

import numpy as np

from labauto.vision import kernels, shape_plain
from labauto.vision.shape_plain import NON_FINITE, OK, ONE_POINT, TOO_FEW_POINTS, VALUE_NAMES

_AXES_METHODS = ("moments", "extent")


@dataclass(frozen=True)
class ShapeDescriptors:
    """Table 1 descriptors of one contour (see the module docstring for the definitions).

    Attributes
    ----------
    shape_factor : float
        ``f0 = b / a``, in [0, 1].
    flattening : float
        ``f = (a - b) / a``, in [0, 1].
    linear_eccentricity : float
        ``e = sqrt(a^2 - b^2)`` in pixels.
    numerical_eccentricity : float
        ``eps = e / a``, in [0, 1]; ``eps' = e / b`` is the property
        :attr:`numerical_eccentricity_minor`.
    compactness : float
        ``C = 4 pi area / perimeter^2``; 1 for a circle, pi/4 for a square.
    roundness : float
        ``R = 4 pi area / convex_perimeter^2``.
    elongation : float
        Long over short side of the minimum-area rotated bounding box (>= 1, ``inf`` for a line).
    bending_energy : float
        Arc-length mean of the squared curvature, px^-2 (``1 / r^2`` for a circle of radius r).
    semi_major, semi_minor : float
        The semi-axes ``a >= b`` in pixels the first four descriptors are built from.
    area : float
        Absolute area of the polygon (closed by its chord when open), px^2.
    perimeter : float
        Length of the contour, px (without the closing chord when open).
    convex_perimeter : float
        Perimeter of the convex hull, px.
    rectangularity : float
        ``area`` over the area of the minimum-area bounding box, in [0, 1].
    centroid : tuple of float
        Centre of gravity ``(x, y)`` the axes refer to.
    """

    shape_factor: float
    flattening: float
    linear_eccentricity: float
    numerical_eccentricity: float
    compactness: float
    roundness: float
    elongation: float
    bending_energy: float
    semi_major: float = math.nan
    semi_minor: float = math.nan
    area: float = math.nan
    perimeter: float = math.nan
    convex_perimeter: float = math.nan
    rectangularity: float = math.nan
    centroid: tuple[float, float] = (math.nan, math.nan)

    @property
    def numerical_eccentricity_minor(self) -> float:
        """``eps' = e / b`` (``inf`` when b is 0)."""
        if self.semi_minor == 0.0:
            return math.inf
        return self.linear_eccentricity / self.semi_minor

    @property
    def bending_energy_normalised(self) -> float:
        """``Ec (P / 2 pi)^2``: 1 for a circle, scale invariant, >= 1 for closed curves."""
        return self.bending_energy * (self.perimeter / (2.0 * math.pi)) ** 2

    def to_dict(self) -> dict:
        """Return the descriptors as a JSON-ready dict.

        Every field, plus ``numerical_eccentricity_minor`` and ``bending_energy_normalised``;
        ``centroid`` is a ``[x, y]`` list and non-finite values (the ``inf`` elongation of a
        line) become ``None`` so the dict is valid JSON.
        """
        out = asdict(self)
        out["centroid"] = list(self.centroid)
        out["numerical_eccentricity_minor"] = self.numerical_eccentricity_minor
        out["bending_energy_normalised"] = self.bending_energy_normalised
        for key, value in out.items():
            if key == "centroid":
                out[key] = [_json_float(v) for v in value]
            else:
                out[key] = _json_float(value)
        return out


def shape_descriptors(
    points: np.ndarray,
    closed: bool = True,
    *,
    axes: str = "moments",
    curvature_sigma: float | None = None,
) -> ShapeDescriptors:
    """Compute the Table 1 shape descriptors of an ordered contour.

    Parameters
    ----------
    points : np.ndarray
        (n, 2) float array of ordered contour points ``(x, y)`` in pixels, n >= 3.
    closed : bool
        Whether the last point joins the first (see the module docstring for open contours).
    axes : str
        How the semi-axes a, b are estimated: ``"moments"`` (default, second moments of the
        filled polygon) or ``"extent"`` (the paper's longest/shortest distance to the centroid).
    curvature_sigma : float, optional
        Gaussian smoothing (in samples) of the coordinates before the curvature of the bending
        energy; 0 disables it; None (default) chooses ``max(2, 0.5 sqrt(P / 2 pi))``.

    Returns
    -------
    ShapeDescriptors

    Raises
    ------
    ValueError
        If ``points`` is not an (n, 2) finite array with at least 3 distinct points, or
        ``axes`` / ``curvature_sigma`` is invalid.
    """
    pts = as_contour(points, min_points=3, name="points")
    if axes not in _AXES_METHODS:
        raise ValueError(f"axes must be one of {_AXES_METHODS}, got {axes!r}")
    if curvature_sigma is not None and not (
        curvature_sigma >= 0.0 and math.isfinite(curvature_sigma)
    ):
        raise ValueError(f"curvature_sigma must be a finite number >= 0, got {curvature_sigma!r}")
    measured = measure_contours(pts, np.array([0, len(pts)], np.int64))
    raise_for_status(int(measured.status[0]), "points")
    v = {name: float(column[0]) for name, column in measured.values.items()}
    pts = drop_repeated_points(pts, closed=True)
    centroid = (v["centroid_x"], v["centroid_y"])
    if axes == "moments":
        a, b = v["semi_major"], v["semi_minor"]
    else:
        a, b = _extent_axes(pts, np.array(centroid))
    area, perimeter, convex_perimeter = v["area"], v["perimeter"], v["convex_perimeter"]
    if not closed:
        perimeter -= v["closing"]

    e = math.sqrt(max(a * a - b * b, 0.0))
    if curvature_sigma is None:
        sigma = max(2.0, 0.5 * math.sqrt(perimeter / (2.0 * math.pi)))
    else:
        sigma = float(curvature_sigma)
    return ShapeDescriptors(
        shape_factor=b / a if a > 0 else 1.0,
        flattening=(a - b) / a if a > 0 else 0.0,
        linear_eccentricity=e,
        numerical_eccentricity=e / a if a > 0 else 0.0,
        compactness=4.0 * math.pi * area / perimeter**2,
        roundness=4.0 * math.pi * area / convex_perimeter**2,
        elongation=v["elongation"],
        bending_energy=bending_energy(pts, closed=closed, sigma=sigma),
        semi_major=a,
        semi_minor=b,
        area=area,
        perimeter=perimeter,
        convex_perimeter=convex_perimeter,
        rectangularity=v["rectangularity"],
        centroid=centroid,
    )


def as_contour(points: np.ndarray, *, min_points: int, name: str = "points") -> np.ndarray:
    """Check and convert a contour to an (n, 2) float64 array.

    Also accepts OpenCV's (n, 1, 2) contour layout.

    Raises
    ------
    ValueError
        If the array has the wrong shape, fewer than ``min_points`` rows or non-finite values.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 3 and pts.shape[1] == 1 and pts.shape[2] == 2:
        pts = pts[:, 0, :]
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{name} must be an (n, 2) array of (x, y), got shape {pts.shape}")
    if len(pts) < min_points:
        raise ValueError(f"{name} needs at least {min_points} points, got {len(pts)}")
    if not np.isfinite(pts).all():
        raise ValueError(f"{name} contains NaN or infinite coordinates")
    return pts


def drop_repeated_points(points: np.ndarray, *, closed: bool) -> np.ndarray:
    """Drop points equal to their predecessor (if closed, also a last point equal to the first)."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    return _shape().drop_repeated(pts, np.array([0, len(pts)], np.int64), closed)[0]


def _shape() -> ModuleType:
    """The compiled shape kernel when it runs, else its plain twin (the same functions)."""
    return kernels.compiled("shape") or shape_plain


def polygon_area_centroid(points: np.ndarray) -> tuple[float, np.ndarray]:
    """Absolute area and area centroid of the polygon through ``points`` (implicitly closed).

    Computed about the vertex mean for precision. When the area is zero the centroid is the
    vertex mean.
    """
    area, centroid = polygon_area_centroid_batch(points, np.array([0, len(points)], np.int64))
    return float(area[0]), centroid[0]


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull (float64, in order) of ``points``.

    Andrew's monotone chain in float64, counter-clockwise in (x, y) axes (clockwise as seen in
    an image, y down), without collinear vertices: collinear points give their two ends.
    """
    return _shape().convex_hull(np.ascontiguousarray(points, dtype=np.float64))


def min_area_box(points: np.ndarray) -> tuple[float, float]:
    """Long and short side of the minimum-area rotated rectangle around ``points``.

    Rotating calipers over the convex hull (one side of the box on each hull edge in turn), in
    float64. Returns ``(0, 0)`` for a single point and ``(L, 0)`` for collinear points.
    """
    return _shape().min_area_box(np.ascontiguousarray(points, dtype=np.float64))


def bending_energy(points: np.ndarray, *, closed: bool = True, sigma: float = 0.0) -> float:
    """Arc-length mean of the squared Menger curvature along the contour, in px^-2.

    Parameters
    ----------
    points : np.ndarray
        (n, 2) ordered contour points without repeated consecutive points.
    closed : bool
        Whether the last point joins the first.
    sigma : float
        Gaussian smoothing of the coordinates along the contour, in samples (0: none).
    """
    pts = _smooth_along(points, sigma, closed=closed) if sigma > 0 else points
    if closed:
        prev, cur, nxt = np.roll(pts, 1, axis=0), pts, np.roll(pts, -1, axis=0)
    else:
        prev, cur, nxt = pts[:-2], pts[1:-1], pts[2:]
    if len(cur) == 0:
        return 0.0
    d1 = cur - prev
    d2 = nxt - cur
    l1 = np.hypot(d1[:, 0], d1[:, 1])
    l2 = np.hypot(d2[:, 0], d2[:, 1])
    chord = np.hypot(*(nxt - prev).T)
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    denom = l1 * l2 * chord
    # A reversal (chord 0 with nonzero cross is impossible) or a zero-length step: no curvature.
    kappa = np.divide(2.0 * np.abs(cross), denom, out=np.zeros_like(denom), where=denom > 0)
    weight = 0.5 * (l1 + l2)
    total = weight.sum()
    return float((weight * kappa**2).sum() / total) if total > 0 else 0.0


def _smooth_along(points: np.ndarray, sigma: float, *, closed: bool) -> np.ndarray:
    """Gaussian-smooth the coordinates along the contour (wrap-around when closed)."""
    n = len(points)
    radius = min(math.ceil(3.0 * sigma), (n - 1) // 2)
    if radius < 1:
        return points
    k = np.arange(-radius, radius + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (k / sigma) ** 2)
    kernel /= kernel.sum()
    padded = np.pad(points, ((radius, radius), (0, 0)), mode="wrap" if closed else "reflect")
    return np.column_stack([np.convolve(padded[:, i], kernel, mode="valid") for i in range(2)])


def _extent_axes(points: np.ndarray, centroid: np.ndarray) -> tuple[float, float]:
    """The paper's rule: farthest vertex and nearest edge point from the centroid."""
    p = points - centroid
    a = float(np.hypot(p[:, 0], p[:, 1]).max())
    d = np.roll(p, -1, axis=0) - p
    dd = (d * d).sum(axis=1)
    t = np.clip(np.divide(-(p * d).sum(axis=1), dd, out=np.zeros_like(dd), where=dd > 0), 0, 1)
    nearest = p + t[:, None] * d
    b = float(np.hypot(nearest[:, 0], nearest[:, 1]).min())
    return a, b


def _json_float(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


# ------------------------------------------------------------------------- many contours


@dataclass(frozen=True)
class DescriptorArrays:
    """The descriptors of K contours that :func:`labauto.vision.harmonics.classify_shapes`
    needs (arrays of length K; definitions as in :class:`ShapeDescriptors`).

    Attributes
    ----------
    valid : np.ndarray
        (K,) bool; False where :func:`shape_descriptors` would raise (fewer than 3 points,
        a non-finite one, fewer than 2 distinct ones, or a self-intersecting polygon with a
        negative second moment). The other arrays hold NaN there.
    area : np.ndarray
        (K,) absolute polygon area (closed by the chord), 0 for a polygon without area.
    centroid : np.ndarray
        (K, 2) centre of gravity (area centroid, or the curve centroid without area).
    semi_major, semi_minor : np.ndarray
        (K,) semi-axes ``a >= b`` from the second moments (``axes="moments"``).
    elongation : np.ndarray
        (K,) long over short side of the minimum-area box (``inf`` for a line).
    rectangularity : np.ndarray
        (K,) area over the minimum-area box's area.
    """

    valid: np.ndarray
    area: np.ndarray
    centroid: np.ndarray
    semi_major: np.ndarray
    semi_minor: np.ndarray
    elongation: np.ndarray
    rectangularity: np.ndarray


@dataclass(frozen=True)
class MeasuredContours:
    """Raw output of the shape kernel for K contours (:func:`measure_contours`).

    Attributes
    ----------
    status : np.ndarray
        (K,) int8 descriptor status, ``labauto.vision.shape_plain.OK`` where the descriptors
        exist (see :func:`raise_for_status` for the others).
    series_status : np.ndarray
        (K,) int8, ``SERIES_OK`` where the polar series was computed.
    values : dict of str to np.ndarray
        (K,) arrays named as ``labauto.vision.shape_plain.VALUE_NAMES``: area, centroid_x/y,
        semi_major/minor, perimeter (closed), closing (its last segment), convex_perimeter,
        elongation, rectangularity (NaN unless status is OK); centre_x/y, star_shapedness,
        winding of the polar series.
    r, rho : np.ndarray
        (K, n_r + 1) and (K, n_rho + 1) complex coefficients of ``r`` and ``r^-2`` (NaN unless
        the series status is ``SERIES_OK``).
    """

    status: np.ndarray
    series_status: np.ndarray
    values: dict[str, np.ndarray]
    r: np.ndarray
    rho: np.ndarray


def as_contour_set(points: object, offsets: object) -> tuple[np.ndarray, np.ndarray]:
    """Concatenated contours as the kernels take them: (N, 2) float64 points, int64 offsets.

    Raises
    ------
    ValueError
        If ``points`` is not (N, 2) or ``offsets`` do not rise from 0 to N.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    off = np.ascontiguousarray(offsets, dtype=np.int64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must be an (N, 2) array of (x, y), got shape {pts.shape}")
    if (
        off.ndim != 1
        or len(off) < 1
        or off[0] != 0
        or off[-1] != len(pts)
        or np.any(off[1:] < off[:-1])
    ):
        raise ValueError("offsets must rise from 0 to len(points)")
    return pts, off


def measure_contours(
    points: np.ndarray,
    offsets: np.ndarray,
    *,
    min_points: int = 3,
    series: np.ndarray | None = None,
    centroids: np.ndarray | None = None,
    max_elongation: float = math.inf,
    n_r: int = -1,
    n_rho: int = -1,
) -> MeasuredContours:
    """Run the shape kernel on K concatenated contours (one compiled call).

    Parameters
    ----------
    points : np.ndarray
        (N, 2) points of all contours, contour k is ``points[offsets[k]:offsets[k + 1]]``.
    offsets : np.ndarray
        (K + 1,) int offsets rising from 0 to N.
    min_points : int
        Contours with fewer points get status ``TOO_FEW_POINTS``.
    series : np.ndarray, optional
        (K,) bool: where to compute the polar series (default: everywhere, if any harmonic is
        asked for).
    centroids : np.ndarray, optional
        (K, 2) centres of the polar series; by default the area centroids.
    max_elongation : float
        No series where the elongation is at least this (lines need none); ``inf``: no limit.
    n_r, n_rho : int
        Highest harmonic of ``r`` and of ``r^-2`` (-1: none).

    Raises
    ------
    ValueError
        If ``points`` is not (N, 2) or ``offsets`` do not rise from 0 to N.
    """
    pts, off = as_contour_set(points, offsets)
    k = len(off) - 1
    want = np.ones(k, np.uint8) if series is None else np.ascontiguousarray(series, np.uint8)
    if centroids is None:
        centres, given = np.zeros((k, 2)), False
    else:
        centres = np.ascontiguousarray(centroids, dtype=np.float64).reshape(k, 2)
        given = True
    arguments = (pts, off, min_points, want.reshape(k), centres, given, max_elongation, n_r, n_rho)
    kernel = kernels.compiled("shape")
    if kernel is None:
        measured = shape_plain.measure_contours(*arguments)
    else:
        measured = kernel.measure_contours(*arguments, kernels.threads())
    status, series_status, values, r, rho = measured
    return MeasuredContours(
        status, series_status, dict(zip(VALUE_NAMES, values.T, strict=True)), r, rho
    )


def raise_for_status(status: int, name: str = "points") -> None:
    """Raise the ValueError of a descriptor status of :func:`measure_contours` (not OK)."""
    if status == OK:
        return
    if status == TOO_FEW_POINTS:
        raise ValueError(f"{name} has too few points")
    if status == NON_FINITE:
        raise ValueError(f"{name} contains NaN or infinite coordinates")
    if status == ONE_POINT:
        raise ValueError(f"{name}: all points are identical; a shape needs at least 2 distinct")
    raise ValueError(
        f"{name}: the polygon crosses itself so that a second moment is negative; "
        "it has no semi-axes"
    )


def drop_repeated_points_batch(
    points: np.ndarray, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`drop_repeated_points` (``closed=True``) of K concatenated contours at once.

    Parameters
    ----------
    points : np.ndarray
        (N, 2) float points of all contours, contour k is ``points[offsets[k]:offsets[k + 1]]``.
    offsets : np.ndarray
        (K + 1,) int offsets, every contour with at least one point.

    Returns
    -------
    points, offsets
        The contours without points equal to their predecessor and without a last point equal
        to the first.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    return _shape().drop_repeated(pts, np.ascontiguousarray(offsets, dtype=np.int64), True)


def shape_descriptors_batch(
    points: np.ndarray, offsets: np.ndarray, *, min_points: int = 3
) -> DescriptorArrays:
    """The label descriptors of :func:`shape_descriptors` for K contours at once.

    One call of the shape kernel (:func:`measure_contours`) for all contours; the values are
    those of :func:`shape_descriptors`. Perimeter, compactness, roundness and bending energy
    are left out (the shape label does not use them).

    Parameters
    ----------
    points : np.ndarray
        (N, 2) finite float points of all contours, in order.
    offsets : np.ndarray
        (K + 1,) int; contour k is ``points[offsets[k]:offsets[k + 1]]``.
    min_points : int
        Contours with fewer points are not valid: 3 as :func:`shape_descriptors`; 2 for
        contours already checked and passed through :func:`drop_repeated_points_batch`.

    Returns
    -------
    DescriptorArrays
    """
    measured = measure_contours(points, offsets, min_points=min_points)
    v = measured.values
    return DescriptorArrays(
        valid=measured.status == OK,
        area=v["area"],
        centroid=np.column_stack((v["centroid_x"], v["centroid_y"])),
        semi_major=v["semi_major"],
        semi_minor=v["semi_minor"],
        elongation=v["elongation"],
        rectangularity=v["rectangularity"],
    )


def polygon_area_centroid_batch(
    points: np.ndarray, offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`polygon_area_centroid` of K concatenated polygons at once.

    Parameters
    ----------
    points : np.ndarray
        (N, 2) float vertices; polygon k is ``points[offsets[k]:offsets[k + 1]]`` (implicitly
        closed), each with at least one vertex.
    offsets : np.ndarray
        (K + 1,) int offsets.

    Returns
    -------
    area : np.ndarray
        (K,) absolute areas.
    centroid : np.ndarray
        (K, 2) area centroids (the vertex mean where the area is zero).
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    return _shape().area_centroids(pts, np.ascontiguousarray(offsets, dtype=np.int64))
