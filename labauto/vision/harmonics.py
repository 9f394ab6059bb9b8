"""Polar harmonic analysis of contours (section 3.2, eq. 4 of Teutsch et al.) and shape labels.

The paper changes to polar coordinates about the centre of gravity and takes the Fourier series
(eq. 4) of the contour, ``F(theta) = a0/2 + sum_n a_n cos(n theta) + b_n sin(n theta)``: "the 1st
two harmonics determine the deviation from circle and ellipse and the third from a triangle and
so on". It works on nearly convex contours.

How the series is computed (a documented choice): **exactly, over the polygon itself**. The
points are the vertices of a polygon (an open contour is closed by its chord). Along a straight
edge at distance ``d`` from the centroid whose foot point lies in direction ``phi`` the radius is
``r(theta) = d / cos(theta - phi)``, so every coefficient integral
``(1/pi) int r(theta) cos(n theta) d theta`` has a closed form per edge
(``int cos(nu)/cos(u) du`` by the recurrence ``K_n = 2 int e^{i(n-1)u} du - K_{n-2}``). The result
is exact for any polygon, whatever its sampling: a triangle given by its 3 corners has the same
harmonics as one given by 3000 edge points, and there is no theta grid or interpolation. On a
contour that is not star-shaped about the centroid the angle runs backwards in places and those
stretches count negatively (the line integral of ``r`` over ``d theta``), which is why the method
needs nearly convex contours; :attr:`ShapeFeatures.star_shapedness` measures this.

The same machinery gives the series of ``rho = r^-2`` (``power=-2``). An ellipse centred on the
centroid has ``rho(theta) = (1/a^2 + 1/b^2)/2 - (1/b^2 - 1/a^2)/2 cos 2(theta - psi)`` **exactly**:
harmonics 0 and 2 only. So in ``rho`` the 2nd harmonic *is* the ellipse (its ratio to the 0th
gives the axis ratio ``b/a`` exactly) and every other harmonic is deviation from an ellipse. In
``r`` itself an ellipse also has harmonics 4, 6, 8 (a 1:4 ellipse: 0.29, 0.15, 0.08 of the mean
radius), which would hide a small deformation; the classifier therefore measures ellipse-ness in
``rho`` and triangles, squares and stars in ``r``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from labauto.vision.descriptors import (
    ShapeDescriptors,
    as_contour,
    drop_repeated_points,
    drop_repeated_points_batch,
    polygon_area_centroid,
    polygon_area_centroid_batch,
    shape_descriptors,
    shape_descriptors_batch,
)

SHAPE_LABELS = ("circle", "ellipse", "des", "triangle", "rectangle", "line", "other")


@dataclass(frozen=True)
class ClassifierThresholds:
    """Thresholds of :func:`classify_shape` (defaults tuned on exact and rendered shapes).

    Attributes
    ----------
    line_elongation : float
        Minimum-area box long/short side ratio at or above which a contour is a line (6: an
        ellipse 1:4 still counts as an ellipse, a 1:6 bar is a line).
    min_star_shapedness : float
        Below this the contour turns back on itself as seen from the centroid: "other".
    ellipse_max_deviation : float
        Largest ellipse deviation (RMS of the ``r^-2`` harmonics other than 0 and 2, relative to
        the 0th) of an ellipse or circle, before the raster allowance. Exact ellipses give 0; a
        DES with 3-5 % low-order radius modulation 0.1-0.16.
    raster_allowance_px : float
        Pixel-grid allowance added to both deviation limits as ``raster_allowance_px / b``
        (b: semi-minor axis in px). Pixel-chain contours of ellipses read about ``0.5 / b``
        (the grid's octagonal bias: r is off by ~0.25 px, and ``r^-2`` doubles the relative
        error where r is smallest); the worst of 20 rendered ellipses per size was 0.12 at
        b = 5 px, 0.087 at 8, 0.056 at 12, 0.032 at 20 and 0.024 at 30.
    circle_min_axis_ratio : float
        An ellipse whose axis ratio ``b/a`` is at least this is a circle.
    triangle_min_h3 : float
        Smallest 3rd harmonic of ``r`` (relative to the mean radius) of a triangle; an
        equilateral triangle has 0.275.
    triangle_max_rectangularity : float
        A triangle fills exactly half of its minimum-area box; a DES about pi/4.
    rectangle_min_rectangularity : float
        A rectangle fills its minimum-area box (1.0; rendered ones > 0.93); an ellipse pi/4.
    des_max_deviation : float
        Largest ellipse deviation of a DES ("moderate deformation"), before the raster
        allowance; stars, triangles and ragged shapes have 0.45-1.
    """

    line_elongation: float = 6.0
    min_star_shapedness: float = 0.9
    ellipse_max_deviation: float = 0.02
    raster_allowance_px: float = 0.7
    circle_min_axis_ratio: float = 0.9
    triangle_min_h3: float = 0.1
    triangle_max_rectangularity: float = 0.65
    rectangle_min_rectangularity: float = 0.9
    des_max_deviation: float = 0.4


@dataclass(frozen=True)
class ShapeFeatures:
    """Everything :func:`classify_shape` decides on.

    Attributes
    ----------
    harmonics : np.ndarray
        Amplitudes of harmonics 0..n of ``r(theta)`` divided by the mean radius (index 0 is 1).
    axis_ratio : float
        ``b/a`` of the ellipse that explains the 0th and 2nd harmonics of ``r^-2`` (exact for an
        ellipse centred on the centroid).
    ellipse_angle : float
        Direction of that ellipse's major axis, degrees in [0, 180) from +x toward +y.
    ellipse_deviation : float
        RMS of the harmonics 1 and 3..n of ``r^-2`` relative to its 0th (0 for an ellipse).
    star_shapedness : float
        ``|net turn| / total turn`` of the direction from the centroid along the contour;
        1 when every ray from the centroid meets the contour once.
    descriptors : ShapeDescriptors
        Table 1 descriptors of the contour.
    """

    harmonics: np.ndarray
    axis_ratio: float
    ellipse_angle: float
    ellipse_deviation: float
    star_shapedness: float
    descriptors: ShapeDescriptors


def polar_fourier_series(
    points: np.ndarray,
    centroid: tuple[float, float] | None = None,
    n_harmonics: int = 8,
    *,
    power: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Fourier coefficients (eq. 4) of ``r(theta)**power`` about the centroid, exact per edge.

    Parameters
    ----------
    points : np.ndarray
        (n, 2) ordered contour points ``(x, y)``, the vertices of a polygon (closed by its chord).
    centroid : tuple of float, optional
        Centre of the polar coordinates; by default the area centroid of the polygon.
    n_harmonics : int
        Highest harmonic, >= 0.
    power : int
        1 for the radius ``r`` (the paper's series) or -2 for ``r^-2`` (exactly harmonics 0 and
        2 for an ellipse centred on the centroid).

    Returns
    -------
    a, b : np.ndarray
        (n_harmonics + 1,) coefficients of ``a0/2 + sum a_n cos(n theta) + b_n sin(n theta)``;
        ``a[0] / 2`` is the mean of ``r**power`` over theta and ``b[0] == 0``. theta is measured
        from +x toward +y (image axes).

    Raises
    ------
    ValueError
        For bad points or parameters, or when the contour does not wind around the centroid
        (centroid outside it or on it).
    """
    coeffs, _ = _polar_series(points, centroid, n_harmonics, power)
    return coeffs.real.copy(), coeffs.imag.copy()


def polar_harmonics(
    points: np.ndarray,
    centroid: tuple[float, float] | None = None,
    n_harmonics: int = 8,
    *,
    normalise: bool = True,
) -> np.ndarray:
    """Amplitudes of the harmonics 0..n of the contour radius ``r(theta)`` about the centroid.

    Parameters
    ----------
    points : np.ndarray
        (n, 2) ordered contour points ``(x, y)`` (an open contour is closed by its chord).
    centroid : tuple of float, optional
        Centre of the polar coordinates; by default the area centroid of the polygon.
    n_harmonics : int
        Highest harmonic, >= 0.
    normalise : bool
        Divide by the mean radius ``a0/2`` so the amplitudes are scale invariant (then index 0
        is 1). Otherwise index 0 is the mean radius in pixels.

    Returns
    -------
    np.ndarray
        (n_harmonics + 1,) amplitudes ``sqrt(a_n^2 + b_n^2)`` (index 0: ``a0/2``). Rotation
        invariant. A circle about its centre has only harmonic 0, an ellipse mainly 2 (plus
        4, 6, ...), an equilateral triangle 3 (0.275) and 6, a square 4 (0.139) and 8.

    Raises
    ------
    ValueError
        As :func:`polar_fourier_series`.
    """
    coeffs, _ = _polar_series(points, centroid, n_harmonics, 1)
    amplitudes = np.abs(coeffs)
    amplitudes[0] = 0.5 * coeffs[0].real
    return amplitudes / amplitudes[0] if normalise else amplitudes


def shape_features(
    points: np.ndarray,
    *,
    closed: bool = True,
    centroid: tuple[float, float] | None = None,
    n_harmonics: int = 8,
) -> ShapeFeatures:
    """Compute the features :func:`classify_shape` uses (see :class:`ShapeFeatures`).

    Raises
    ------
    ValueError
        For bad points, or when the contour does not wind around the centroid.
    """
    pts = as_contour(points, min_points=3)
    return _features(pts, shape_descriptors(pts, closed=closed), centroid, n_harmonics)


def _features(
    pts: np.ndarray,
    descriptors: ShapeDescriptors,
    centroid: tuple[float, float] | None,
    n_harmonics: int,
) -> ShapeFeatures:
    """:func:`shape_features` with the descriptors already computed."""
    n_harmonics = max(int(n_harmonics), 3)
    r_coeffs, star = _polar_series(pts, centroid, n_harmonics, 1)
    rho_coeffs, _ = _polar_series(pts, centroid, n_harmonics, -2)
    harmonics = np.abs(r_coeffs)
    harmonics[0] = 0.5 * r_coeffs[0].real
    harmonics /= harmonics[0]

    rho_mean = 0.5 * rho_coeffs[0].real
    kappa = min(abs(rho_coeffs[2]) / rho_mean, 1.0)  # (1/b^2 - 1/a^2) / (1/b^2 + 1/a^2)
    rest = np.abs(np.concatenate((rho_coeffs[1:2], rho_coeffs[3:]))) / rho_mean
    # rho is smallest along the major axis: rho_2 = -kappa * rho_mean * e^{2i psi}
    angle = math.degrees(0.5 * np.angle(-rho_coeffs[2])) % 180.0
    return ShapeFeatures(
        harmonics=harmonics,
        axis_ratio=math.sqrt((1.0 - kappa) / (1.0 + kappa)),
        ellipse_angle=angle,
        ellipse_deviation=float(np.sqrt(np.sum(rest**2))),
        star_shapedness=star,
        descriptors=descriptors,
    )


def classify_shape(
    points: np.ndarray,
    *,
    d_alpha: float,
    centroid_inside: bool,
    closed: bool = True,
    des_threshold_deg: float = 30.0,
    centroid: tuple[float, float] | None = None,
    thresholds: ClassifierThresholds | None = None,
) -> str:
    """Label a contour "circle", "ellipse", "des", "triangle", "rectangle", "line" or "other".

    Decision rule, first match wins (thresholds: :class:`ClassifierThresholds`):

    1. **line**: the minimum-area box is at least ``line_elongation`` (6) times longer than wide.
    2. **other**: the centroid is not inside (``centroid_inside`` False, or the contour does not
       wind around it) or the contour is not star-shaped about it (star-shapedness < 0.9):
       polar harmonics are meaningless there (crescents, C shapes, spirals).
    3. **rectangle**: the shape fills >= 0.9 of its minimum-area box (an ellipse fills pi/4).
       A square has a strong 4th harmonic of ``r`` (0.139) but a 4:1 rectangle's ``r`` and
       ``r^-2`` harmonics are within 0.04 of an ellipse's, so rectangularity is the cue that
       works at all aspect ratios.
    4. **circle** / **ellipse**: the ``r^-2`` harmonics other than 0 and 2 are negligible
       (ellipse deviation <= 0.02 + 0.7 px / b); a circle if the axis ratio ``b/a`` from
       harmonic 2 is >= 0.9.
    5. **triangle**: a strong 3rd harmonic of ``r`` (>= 0.1 of the mean radius) and the shape
       fills at most 0.65 of its minimum-area box (any triangle fills exactly 1/2).
    6. **des**: the paper's rule, D_alpha below ``des_threshold_deg`` with the centroid inside,
       plus a moderate deformation (ellipse deviation <= 0.4 + 0.7 px / b).
    7. **other**: everything else (stars, ragged or merged shapes).

    Parameters
    ----------
    points : np.ndarray
        (n, 2) ordered contour points ``(x, y)``.
    d_alpha : float
        Shape angle D_alpha in degrees (eq. 3; mean or median, from the detector).
    centroid_inside : bool
        Result of the point-in-polygon test of the centroid.
    closed : bool
        Whether the contour is closed (open ones are closed by their chord).
    des_threshold_deg : float
        D_alpha threshold of a DES, degrees.
    centroid : tuple of float, optional
        Centre of gravity; by default the area centroid of the polygon.
    thresholds : ClassifierThresholds, optional
        Override the decision thresholds.

    Returns
    -------
    str
        One of :data:`SHAPE_LABELS`.

    Raises
    ------
    ValueError
        If ``points`` is not an (n, 2) finite array with at least 3 points, or ``d_alpha`` is
        not a finite number.
    """
    th = thresholds or ClassifierThresholds()
    if not math.isfinite(float(d_alpha)):
        raise ValueError(f"d_alpha must be a finite angle in degrees, got {d_alpha!r}")
    pts = as_contour(points, min_points=3)
    descriptors = shape_descriptors(pts, closed=closed)
    if descriptors.elongation >= th.line_elongation:
        return "line"
    if not centroid_inside:
        return "other"
    try:
        features = _features(pts, descriptors, centroid, 8)
    except ValueError:  # the contour does not wind around the centroid
        return "other"
    if features.star_shapedness < th.min_star_shapedness:
        return "other"
    if descriptors.rectangularity >= th.rectangle_min_rectangularity:
        return "rectangle"
    allowance = th.raster_allowance_px / max(descriptors.semi_minor, 1e-9)
    if features.ellipse_deviation <= th.ellipse_max_deviation + allowance:
        return "circle" if features.axis_ratio >= th.circle_min_axis_ratio else "ellipse"
    if (
        features.harmonics[3] >= th.triangle_min_h3
        and descriptors.rectangularity <= th.triangle_max_rectangularity
    ):
        return "triangle"
    if d_alpha < des_threshold_deg and features.ellipse_deviation <= (
        th.des_max_deviation + allowance
    ):
        return "des"
    return "other"


def _polar_series(
    points: np.ndarray,
    centroid: tuple[float, float] | None,
    n_harmonics: int,
    power: int,
) -> tuple[np.ndarray, float]:
    """Complex coefficients ``a_n + i b_n`` of ``r**power`` and the star-shapedness."""
    if power not in (1, -2):
        raise ValueError(f"power must be 1 or -2, got {power!r}")
    if int(n_harmonics) != n_harmonics or n_harmonics < 0:
        raise ValueError(f"n_harmonics must be an integer >= 0, got {n_harmonics!r}")
    n_harmonics = int(n_harmonics)
    pts = drop_repeated_points(as_contour(points, min_points=3), closed=True)
    if centroid is None:
        area, c = polygon_area_centroid(pts)
        if area == 0.0:
            raise ValueError("points enclose no area; polar harmonics need a closed shape")
    else:
        c = np.asarray(centroid, dtype=np.float64)
        if c.shape != (2,) or not np.isfinite(c).all():
            raise ValueError(f"centroid must be a finite (x, y) pair, got {centroid!r}")

    x0, y0 = pts[:, 0] - c[0], pts[:, 1] - c[1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    ex, ey = x1 - x0, y1 - y0
    length = np.sqrt(ex * ex + ey * ey)  # (np.hypot is several times slower)
    nx, ny = ey / length, -ex / length
    d = x0 * nx + y0 * ny
    flip = np.where(d < 0, -1.0, 1.0)  # make (nx, ny) point from the centroid to the edge
    nx, ny, d = nx * flip, ny * flip, d * flip
    scale = float(np.sqrt((x0 * x0 + y0 * y0).max()))
    ok = d > 1e-12 * scale  # edges on a line through the centroid add nothing to int f d theta
    if not ok.all():
        x0, y0, x1, y1, nx, ny, d = (v[ok] for v in (x0, y0, x1, y1, nx, ny, d))
    t0 = (y0 * nx - x0 * ny) / d  # tan(u) at both ends, u = theta - phi in (-pi/2, pi/2)
    t1 = (y1 * nx - x1 * ny) / d
    z0 = (1.0 + 1j * t0) / np.sqrt(1.0 + t0 * t0)  # e^{iu}
    z1 = (1.0 + 1j * t1) / np.sqrt(1.0 + t1 * t1)
    du = np.arctan(t1) - np.arctan(t0)  # each edge subtends less than pi

    net_turn = float(du.sum())
    winding = round(net_turn / (2.0 * math.pi))
    if winding == 0:
        raise ValueError(
            f"the contour does not wind around the centroid ({c[0]:.6g}, {c[1]:.6g}); "
            "polar harmonics need the centroid inside the contour"
        )
    star_shapedness = abs(net_turn) / float(np.abs(du).sum())

    # G[m] = int_{u0}^{u1} e^{imu} du for m = 0..n+2 (G[-m] = conj(G[m]))
    g = [du.astype(complex)]
    w0, w1 = np.ones_like(z0), np.ones_like(z1)
    for m in range(1, n_harmonics + 3):
        w0, w1 = w0 * z0, w1 * z1
        g.append((w1 - w0) / (1j * m))
    coeffs = np.empty(n_harmonics + 1, dtype=complex)
    phase = np.ones_like(z0)  # e^{i n phi}
    e_phi = nx + 1j * ny
    if power == 1:
        # int r e^{in theta} d theta = d e^{in phi} K_n, K_n = int e^{inu} / cos u du:
        # K_0 = asinh(tan u), K_1 = u - i log(cos u), K_n = 2 G_{n-1} - K_{n-2}
        k_prev = np.arcsinh(t1) - np.arcsinh(t0) + 0j
        k_cur = du + 0.5j * (np.log1p(t1 * t1) - np.log1p(t0 * t0))
        for n in range(n_harmonics + 1):
            if n >= 2:
                k_prev, k_cur = k_cur, 2.0 * g[n - 1] - k_prev
            kn = k_prev if n == 0 else k_cur
            coeffs[n] = np.dot(d, phase * kn)
            phase = phase * e_phi
    else:
        # int r^-2 e^{in theta} d theta = e^{in phi} / d^2 int cos^2(u) e^{inu} du
        #                                = e^{in phi} / d^2 (G_n / 2 + (G_{n+2} + G_{n-2}) / 4)
        inv_d2 = 1.0 / (d * d)
        for n in range(n_harmonics + 1):
            g_minus = g[n - 2] if n >= 2 else np.conj(g[2 - n])
            coeffs[n] = np.dot(inv_d2, phase * (0.5 * g[n] + 0.25 * (g[n + 2] + g_minus)))
            phase = phase * e_phi

    coeffs /= math.pi * winding
    coeffs[0] = coeffs[0].real
    return coeffs, star_shapedness


# ------------------------------------------------------------------------- many contours


def classify_shapes(
    points: np.ndarray,
    offsets: np.ndarray,
    *,
    d_alpha: np.ndarray,
    centroid_inside: np.ndarray,
    des_threshold_deg: float = 30.0,
    centroids: np.ndarray | None = None,
    thresholds: ClassifierThresholds | None = None,
) -> list[str | None]:
    """:func:`classify_shape` for K contours at once, vectorised over all their points.

    The same decision rule on the same features: the descriptors are those of
    :func:`~labauto.vision.descriptors.shape_descriptors_batch` (one ``cv2.minAreaRect`` per
    contour, everything else per-contour sums), the polar series of ``r`` (harmonics 0-3, all
    the rule reads) and ``r^-2`` (0-8) from one pass over all edges of all contours. Results
    equal :func:`classify_shape`'s up to floating-point rounding. (``closed`` is not an
    argument: the label does not depend on it.)

    Parameters
    ----------
    points : np.ndarray
        (N, 2) ordered contour points ``(x, y)`` of all contours, concatenated.
    offsets : np.ndarray
        (K + 1,) int; contour k is ``points[offsets[k]:offsets[k + 1]]``.
    d_alpha : np.ndarray
        (K,) shape angles D_alpha in degrees.
    centroid_inside : np.ndarray
        (K,) bool results of the point-in-polygon test of the centroids.
    des_threshold_deg : float
        D_alpha threshold of a DES, degrees.
    centroids : np.ndarray, optional
        (K, 2) centres of gravity; by default the area centroids of the polygons.
    thresholds : ClassifierThresholds, optional
        Override the decision thresholds.

    Returns
    -------
    list of str or None
        One of :data:`SHAPE_LABELS` per contour; None where :func:`classify_shape` raises
        ValueError (fewer than 3 points, fewer than 2 distinct ones, a non-finite point or
        ``d_alpha``).
    """
    th = thresholds or ClassifierThresholds()
    pts = np.asarray(points, dtype=np.float64)
    off = np.asarray(offsets, dtype=np.int64)
    k = len(off) - 1
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must be an (N, 2) array of (x, y), got shape {pts.shape}")
    if off.ndim != 1 or k < 0 or off[0] != 0 or off[-1] != len(pts) or np.any(np.diff(off) < 0):
        raise ValueError("offsets must rise from 0 to len(points)")
    d_alpha = np.asarray(d_alpha, dtype=np.float64).reshape(k)
    inside = np.asarray(centroid_inside, dtype=bool).reshape(k)
    labels: list[str | None] = [None] * k
    if k == 0:
        return labels
    counts = np.diff(off)
    finite_pts = np.isfinite(pts).all(axis=1)
    usable = np.isfinite(d_alpha) & (counts >= 3)
    if not finite_pts.all():
        bad = np.repeat(np.arange(k), counts)[~finite_pts]
        usable[bad] = False
    if not usable.any():
        return labels
    idx = np.flatnonzero(usable)
    if not usable.all():
        pts = pts[np.repeat(usable, counts)]
        off = np.concatenate(([0], np.cumsum(counts[usable])))
    q, q_off = drop_repeated_points_batch(pts, off)
    desc = shape_descriptors_batch(q, q_off, min_points=2)
    label = np.full(len(idx), "", dtype=object)
    valid = desc.valid
    line = valid & (desc.elongation >= th.line_elongation)
    label[line] = "line"
    label[valid & ~line & ~inside[idx]] = "other"
    todo = valid & ~line & inside[idx]
    if todo.any():
        if not todo.all():
            q_counts = np.diff(q_off)
            q = q[np.repeat(todo, q_counts)]
            q_off = np.concatenate(([0], np.cumsum(q_counts[todo])))
        if centroids is None:
            area, centres = polygon_area_centroid_batch(q, q_off)
            has_centre = area != 0.0  # _polar_series: "points enclose no area"
        else:
            centres = np.asarray(centroids, dtype=np.float64).reshape(k, 2)[idx[todo]]
            has_centre = np.isfinite(centres).all(axis=1)
            centres = np.where(has_centre[:, None], centres, 0.0)
        r, rho, star, winding = _polar_series_batch(q, q_off, centres, 3, 8)
        mean_r = 0.5 * r[:, 0].real
        rho_mean = 0.5 * rho[:, 0].real
        with np.errstate(divide="ignore", invalid="ignore"):
            h3 = np.abs(r[:, 3]) / mean_r
            kappa = np.minimum(np.abs(rho[:, 2]) / rho_mean, 1.0)
            rest = np.abs(np.concatenate((rho[:, 1:2], rho[:, 3:]), axis=1)) / rho_mean[:, None]
            deviation = np.sqrt(np.sum(rest**2, axis=1))
            axis_ratio = np.sqrt((1.0 - kappa) / (1.0 + kappa))
        rect = desc.rectangularity[todo]
        allowance = th.raster_allowance_px / np.maximum(desc.semi_minor[todo], 1e-9)
        ellipse_like = deviation <= th.ellipse_max_deviation + allowance
        conditions = [
            ~has_centre | (winding == 0) | (star < th.min_star_shapedness),
            rect >= th.rectangle_min_rectangularity,
            ellipse_like & (axis_ratio >= th.circle_min_axis_ratio),
            ellipse_like,
            (h3 >= th.triangle_min_h3) & (rect <= th.triangle_max_rectangularity),
            (d_alpha[idx[todo]] < des_threshold_deg)
            & (deviation <= th.des_max_deviation + allowance),
        ]
        choices = ["other", "rectangle", "circle", "ellipse", "triangle", "des"]
        label[todo] = np.select(conditions, choices, default="other")
    for j, name in zip(idx[valid].tolist(), label[valid].tolist(), strict=True):
        labels[j] = name
    return labels


def _polar_series_batch(
    q: np.ndarray, q_off: np.ndarray, centres: np.ndarray, n_r: int, n_rho: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_polar_series` of K polygons at once, for ``r`` and ``r^-2`` together.

    ``q`` holds the polygons without repeated points (``drop_repeated_points_batch``), polygon
    k runs around ``centres[k]``. Every edge contributes its exact integral (module
    docstring), summed per polygon with ``np.add.reduceat``; edges on a line through the
    centre contribute nothing. Returns the (K, n_r + 1) coefficients of ``r``, the
    (K, n_rho + 1) coefficients of ``r^-2`` (both 0 where the winding number is 0), the
    star-shapedness and the winding number of every polygon.
    """
    counts = np.diff(q_off)
    k = len(counts)
    starts = q_off[:-1]
    owner = np.repeat(np.arange(k), counts)
    nxt = np.arange(1, len(q) + 1)
    nxt[q_off[1:] - 1] = starts  # the last vertex joins the first
    x0, y0 = q[:, 0] - centres[owner, 0], q[:, 1] - centres[owner, 1]
    x1, y1 = x0[nxt], y0[nxt]
    ex, ey = x1 - x0, y1 - y0
    length = np.sqrt(ex * ex + ey * ey)  # (np.hypot is several times slower)
    nx, ny = ey / length, -ex / length
    d = x0 * nx + y0 * ny
    flip = np.where(d < 0, -1.0, 1.0)  # make (nx, ny) point from the centre to the edge
    nx, ny, d = nx * flip, ny * flip, d * flip
    scale = np.sqrt(np.maximum.reduceat(x0 * x0 + y0 * y0, starts))
    ok = d > 1e-12 * scale[owner]  # edges on a line through the centre add nothing
    d = np.where(ok, d, 1.0)
    t0 = np.where(ok, (y0 * nx - x0 * ny) / d, 0.0)  # tan(u) at both ends
    t1 = np.where(ok, (y1 * nx - x1 * ny) / d, 0.0)
    sec0, sec1 = np.sqrt(1.0 + t0 * t0), np.sqrt(1.0 + t1 * t1)
    z0, z1 = np.empty(len(q), complex), np.empty(len(q), complex)  # e^{iu}
    z0.real, z0.imag = 1.0 / sec0, t0 / sec0
    z1.real, z1.imag = 1.0 / sec1, t1 / sec1
    # u1 - u0 in one arctan2: tan(u1) - tan(u0) and 1 + tan(u0) tan(u1) are sin(u1 - u0) and
    # cos(u1 - u0) divided by cos(u0) cos(u1) > 0
    du = np.arctan2(t1 - t0, 1.0 + t0 * t1)

    net_turn = np.add.reduceat(du, starts)
    winding = np.rint(net_turn / (2.0 * math.pi))
    total_turn = np.add.reduceat(np.abs(du), starts)
    star = np.abs(net_turn) / np.where(total_turn > 0, total_turn, 1.0)

    # G[m] = int_{u0}^{u1} e^{imu} du, m = 0 .. max(n_r - 1, n_rho + 2)
    g = [du.astype(complex)]
    w0, w1 = z0.copy(), z1.copy()
    for m in range(1, max(n_r - 1, n_rho + 2) + 1):
        if m > 1:
            w0 *= z0
            w1 *= z1
        g.append((w1 - w0) * (-1j / m))
    e_phi = np.empty(len(q), complex)
    e_phi.real, e_phi.imag = nx, ny
    phases = [np.ones(len(q), complex)]  # e^{in phi}
    for _ in range(max(n_r, n_rho)):
        phases.append(phases[-1] * e_phi)

    # r: int r e^{in theta} d theta = d e^{in phi} K_n, K_n = 2 G_{n-1} - K_{n-2}
    r = np.empty((k, n_r + 1), complex)
    # K_0 = asinh(t1) - asinh(t0) = log((t1 + sec1) / (t0 + sec0)), t + sec = 1 / (sec - t)
    # without cancellation for t < 0; K_1 = du - i log(cos u) |_0^1 = du + i log(sec1 / sec0)
    e0 = np.where(t0 >= 0, t0 + sec0, 1.0 / (sec0 - t0))
    e1 = np.where(t1 >= 0, t1 + sec1, 1.0 / (sec1 - t1))
    k_prev = np.log(e1 / e0) + 0j
    k_cur = np.empty(len(q), complex)
    k_cur.real, k_cur.imag = du, np.log(sec1 / sec0)
    for n in range(n_r + 1):
        if n >= 2:
            k_prev, k_cur = k_cur, 2.0 * g[n - 1] - k_prev
        kn = k_prev if n == 0 else k_cur
        r[:, n] = np.add.reduceat(d * phases[n] * kn, starts)
    # r^-2: e^{in phi} / d^2 (G_n / 2 + (G_{n+2} + G_{n-2}) / 4)
    rho = np.empty((k, n_rho + 1), complex)
    inv_d2 = np.where(ok, 1.0 / (d * d), 0.0)
    for n in range(n_rho + 1):
        g_minus = g[n - 2] if n >= 2 else np.conj(g[2 - n])
        term = phases[n] * (0.5 * g[n] + 0.25 * (g[n + 2] + g_minus))
        rho[:, n] = np.add.reduceat(inv_d2 * term, starts)

    norm = np.where(winding != 0, math.pi * winding, np.inf)[:, None]
    r /= norm
    rho /= norm
    r[:, 0] = r[:, 0].real
    rho[:, 0] = rho[:, 0].real
    return r, rho, star, winding
