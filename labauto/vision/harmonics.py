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

Implementation: the per-edge integrals are summed per contour in the same call as the descriptors
(:func:`labauto.vision.descriptors.measure_contours`): written out in numpy in
:mod:`labauto.vision.shape_plain`, and by the compiled shape kernel
(:func:`labauto.vision.kernels.shape.measure_contours`) when it runs. The kernel folds the factor
``e^{in phi}`` into per-vertex powers: with ``w = e^{i theta}`` at the edge's ends, ``e^{in phi} int
e^{inu} du = (w1^n - w0^n) / (in)``, so each vertex's powers serve both of its edges, and the
``r^-2`` terms are gathered per harmonic: ``sum_edges c (w1^n - w0^n)`` (``c``: an edge's
coefficient ``1 / (2 d^2)`` or ``e^{2i phi} / (4 d^2)``) for every ``n``, a few multiply-adds per
edge and harmonic instead of three complex products. The kernel goes harmonic by harmonic, each a
vectorised pass over all vertices and edges. (Summation order is a rounding matter only; where an
edge's line passes close to the centre, ``1 / d^2`` is large and the ``r^-2`` coefficients of any
summation order carry rounding of that size: ~1e-10 of the 0th for a line 0.004 px from the centre.)
:func:`classify_shapes` labels all contours of an image in one call; the single-contour functions
are a batch of one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from labauto.vision.descriptors import (
    ShapeDescriptors,
    as_contour,
    as_contour_set,
    measure_contours,
    raise_for_status,
    shape_descriptors,
)
from labauto.vision.shape_plain import OK, SERIES_NO_AREA, SERIES_NO_WINDING, SERIES_OK

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
    if power not in (1, -2):
        raise ValueError(f"power must be 1 or -2, got {power!r}")
    n = _check_harmonics(n_harmonics)
    r, rho, _ = _polar_series(points, centroid, n if power == 1 else -1, n if power == -2 else -1)
    coeffs = r if power == 1 else rho
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
    coeffs, _, _ = _polar_series(points, centroid, _check_harmonics(n_harmonics), -1)
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
    descriptors = shape_descriptors(pts, closed=closed)
    n_harmonics = max(int(n_harmonics), 3)
    r, rho, star = _polar_series(pts, centroid, n_harmonics, n_harmonics)
    harmonics, axis_ratio, deviation = _ellipse_measures(r[None], rho[None])
    return ShapeFeatures(
        harmonics=harmonics[0],
        axis_ratio=float(axis_ratio[0]),
        ellipse_angle=float(_ellipse_angle(rho[None])[0]),
        ellipse_deviation=float(deviation[0]),
        star_shapedness=star,
        descriptors=descriptors,
    )


def _ellipse_measures(r: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised harmonics of ``r``, axis ratio and ellipse deviation (what the label reads).

    ``r`` and ``rho`` are (K, n + 1) complex coefficients of ``r`` and ``r^-2`` (n >= 2 for
    ``rho``); see :class:`ShapeFeatures`.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        harmonics = np.abs(r)
        harmonics[:, 0] = 0.5 * r[:, 0].real
        harmonics /= harmonics[:, :1]
        rho_mean = 0.5 * rho[:, 0].real
        # kappa = (1/b^2 - 1/a^2) / (1/b^2 + 1/a^2)
        kappa = np.minimum(np.abs(rho[:, 2]) / rho_mean, 1.0)
        rest = np.abs(np.concatenate((rho[:, 1:2], rho[:, 3:]), axis=1)) / rho_mean[:, None]
        deviation = np.sqrt(np.sum(rest**2, axis=1))
        axis_ratio = np.sqrt((1.0 - kappa) / (1.0 + kappa))
    return harmonics, axis_ratio, deviation


def _ellipse_angle(rho: np.ndarray) -> np.ndarray:
    """Direction of the major axis (degrees in [0, 180)) from (K, n + 1) coefficients of
    ``r^-2``: rho is smallest along the major axis, rho_2 = -kappa * rho_mean * e^{2i psi}."""
    return np.degrees(0.5 * np.angle(-rho[:, 2])) % 180.0


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
        If ``points`` is not an (n, 2) finite array with at least 3 points (2 distinct, with
        non-negative second moments), ``d_alpha`` is not a finite number or ``centroid`` is
        not an (x, y) pair (a non-finite centroid gives "other").
    """
    if not math.isfinite(float(d_alpha)):
        raise ValueError(f"d_alpha must be a finite angle in degrees, got {d_alpha!r}")
    pts = as_contour(points, min_points=3)
    centroids = None
    if centroid is not None:
        centroids = np.asarray(centroid, dtype=np.float64)
        if centroids.shape != (2,):
            raise ValueError(f"centroid must be an (x, y) pair, got {centroid!r}")
    labels, status = _classify(
        pts,
        np.array([0, len(pts)], np.int64),
        np.array([float(d_alpha)]),
        np.array([bool(centroid_inside)]),
        des_threshold_deg,
        None if centroids is None else centroids[None],
        thresholds or ClassifierThresholds(),
    )
    raise_for_status(int(status[0]), "points")
    return labels[0]  # type: ignore[return-value]


def _check_harmonics(n_harmonics: int) -> int:
    if int(n_harmonics) != n_harmonics or n_harmonics < 0:
        raise ValueError(f"n_harmonics must be an integer >= 0, got {n_harmonics!r}")
    return int(n_harmonics)


def _polar_series(
    points: np.ndarray,
    centroid: tuple[float, float] | None,
    n_r: int,
    n_rho: int,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Complex coefficients ``a_n + i b_n`` of ``r`` (0..n_r) and ``r^-2`` (0..n_rho), and the
    star-shapedness, of one contour (the kernel on a batch of one; -1: no harmonics)."""
    pts = as_contour(points, min_points=3)
    centres = None
    if centroid is not None:
        centres = np.asarray(centroid, dtype=np.float64)
        if centres.shape != (2,) or not np.isfinite(centres).all():
            raise ValueError(f"centroid must be a finite (x, y) pair, got {centroid!r}")
        centres = centres[None]
    measured = measure_contours(
        pts, np.array([0, len(pts)], np.int64), centroids=centres, n_r=int(n_r), n_rho=int(n_rho)
    )
    status = int(measured.series_status[0])
    if status == SERIES_NO_AREA:
        raise ValueError("points enclose no area; polar harmonics need a closed shape")
    if status == SERIES_NO_WINDING:
        cx, cy = measured.values["centre_x"][0], measured.values["centre_y"][0]
        raise ValueError(
            f"the contour does not wind around the centroid ({cx:.6g}, {cy:.6g}); "
            "polar harmonics need the centroid inside the contour"
        )
    star = float(measured.values["star_shapedness"][0])
    return measured.r[0], measured.rho[0], star


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
    """:func:`classify_shape` for K contours at once, in one call of the shape kernel.

    The same decision rule on the same features (:func:`classify_shape` is this function on a
    batch of one): the descriptors of
    :func:`~labauto.vision.descriptors.shape_descriptors_batch` and, where the rule needs them
    (not a line, centroid inside), the polar series of ``r`` (harmonics 0-3, all the rule
    reads) and ``r^-2`` (0-8), computed per contour by
    :func:`~labauto.vision.descriptors.measure_contours` (contours shared among threads; a
    contour's result does not depend on the others). (``closed`` is not an argument: the label
    does not depend on it.)

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
    pts, off = as_contour_set(points, offsets)
    k = len(off) - 1
    d_alpha = np.asarray(d_alpha, dtype=np.float64).reshape(k)
    inside = np.asarray(centroid_inside, dtype=bool).reshape(k)
    if centroids is not None:
        centroids = np.asarray(centroids, dtype=np.float64).reshape(k, 2)
    th = thresholds or ClassifierThresholds()
    return _classify(pts, off, d_alpha, inside, des_threshold_deg, centroids, th)[0]


def _classify(
    pts: np.ndarray,
    off: np.ndarray,
    d_alpha: np.ndarray,
    inside: np.ndarray,
    des_threshold_deg: float,
    centroids: np.ndarray | None,
    th: ClassifierThresholds,
) -> tuple[list[str | None], np.ndarray]:
    """The decision rule of :func:`classify_shape` on K checked contours: one kernel call for
    the descriptors and, where the label needs them (not a line, centroid inside), the polar
    series of ``r`` (harmonics 0-3, all the rule reads) and ``r^-2`` (0-8). Returns the labels
    (None where the descriptors do not exist or ``d_alpha`` is not finite) and the descriptor
    status of every contour."""
    finite = np.isfinite(d_alpha)
    measured = measure_contours(
        pts,
        off,
        series=inside & finite,
        centroids=centroids,
        max_elongation=th.line_elongation,
        n_r=3,
        n_rho=8,
    )
    v = measured.values
    valid = (measured.status == OK) & finite
    line = v["elongation"] >= th.line_elongation
    rect = v["rectangularity"]
    harmonics, axis_ratio, deviation = _ellipse_measures(measured.r, measured.rho)
    allowance = th.raster_allowance_px / np.maximum(v["semi_minor"], 1e-9)
    ellipse_like = deviation <= th.ellipse_max_deviation + allowance
    conditions = [
        line,
        ~inside
        | (measured.series_status != SERIES_OK)  # no centre, or it is outside
        | (v["star_shapedness"] < th.min_star_shapedness),
        rect >= th.rectangle_min_rectangularity,
        ellipse_like & (axis_ratio >= th.circle_min_axis_ratio),
        ellipse_like,
        (harmonics[:, 3] >= th.triangle_min_h3) & (rect <= th.triangle_max_rectangularity),
        (d_alpha < des_threshold_deg) & (deviation <= th.des_max_deviation + allowance),
    ]
    # label index into SHAPE_LABELS: the first matching condition (set last), else "other"
    choices = [5, 6, 4, 0, 1, 3, 2]  # line, other, rectangle, circle, ellipse, triangle, des
    code = np.full(len(valid), 6)
    for condition, choice in zip(conditions[::-1], choices[::-1], strict=True):
        code[condition] = choice
    code[~valid] = -1
    labels = [None if c < 0 else SHAPE_LABELS[c] for c in code.tolist()]
    return labels, measured.status
