# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Shape angle kernel (eq. 3): centroid, area, gap, D_alpha mean and median, centroid inside.

See :mod:`labauto.vision.shape_angle` for the definitions and the choices made. One call handles
all K contours of an image; contours are shared among threads. Per contour:

1. geometry, one loop over the points: the polygon moments, the sums for the mean and spread of
   the points, and the length along them. Coordinates are taken relative to the first point:
   the terms are then of the contour's size, not of its position in the image, which keeps the
   sums as accurate as centring on the mean without a pass for the mean, and the two edges at
   the first point (the closing one included) add nothing. Plain sums in point order.
2. the deviation angles; then one loop for their sum (point order) and the even-odd crossings
   of the centroid's ray.
3. the median of the angles by quickselect (O(n) expected, branchless partitions; the remaining
   range is sorted if the pivots keep failing, so O(n log n) at worst).

The angle is ``atan2(|g x m|, |g . m|)``: the same angle as eq. 3's ``arccos(|g . m| / (|g|
|m|))`` but well-conditioned everywhere (``arccos`` near 0 degrees turns a rounding of the cosine
into up to 1e-8 rad), scale-free (no norms to overflow) and accurate to a few ulp (the C
library's ``atan2``).
"""

from cython.parallel cimport prange
from libc.math cimport M_PI, atan2, fabs, isfinite, sqrt
from libc.stdlib cimport qsort

ctypedef fused grad_t:
    float
    double

cdef double DEGREES = 180.0 / M_PI
# quickselect rounds on one contour before the remaining range is sorted instead
cdef int MAX_ROUNDS = 64


# --- one contour --------------------------------------------------------------------------------

cdef bint _geometry(
    const double* p, Py_ssize_t n, bint closed, double open_ratio,
    double* centroid, double* area, double* gap,
) noexcept nogil:
    """Centre of gravity, polygon area and gap fraction of one contour of ``n`` interleaved
    ``(x, y)`` points (``open_ratio``: see ``OPEN_MIN_AREA_RATIO``). Returns whether all
    coordinates are finite."""
    cdef double x0 = p[0], y0 = p[1]
    cdef double sx = 0.0, sy = 0.0, ss = 0.0, twice_area = 0.0, moment_x = 0.0, moment_y = 0.0
    cdef double length = 0.0, x, y, xn, yn, cross, spread, min_ratio, chord, total
    cdef Py_ssize_t i
    # edge i -> i + 1 relative to the first point; the closing edge (last -> first) adds 0
    for i in range(n - 1):
        x = p[2 * i] - x0
        y = p[2 * i + 1] - y0
        xn = p[2 * i + 2] - x0
        yn = p[2 * i + 3] - y0
        sx = sx + x
        sy = sy + y
        ss = ss + (x * x + y * y)
        cross = x * yn - xn * y
        twice_area = twice_area + cross
        moment_x = moment_x + (x + xn) * cross
        moment_y = moment_y + (y + yn) * cross
        if not closed:
            length = length + sqrt((xn - x) * (xn - x) + (yn - y) * (yn - y))
    x = p[2 * n - 2] - x0  # the last point
    y = p[2 * n - 1] - y0
    sx = sx + x
    sy = sy + y
    ss = ss + (x * x + y * y)
    if not (isfinite(sx) and isfinite(sy)):
        return False
    spread = (ss - (sx * sx + sy * sy) / n) / n  # mean squared distance from the mean
    # open contours: the chord-closed polygon if it encloses a real area (a disk has
    # area / spread = pi, a straight line 0), else the points' mean
    min_ratio = 1e-6 if closed else open_ratio
    area[0] = fabs(twice_area) / 2.0
    if area[0] > min_ratio * spread:
        centroid[0] = x0 + moment_x / (3.0 * twice_area)
        centroid[1] = y0 + moment_y / (3.0 * twice_area)
    else:
        centroid[0] = x0 + sx / n
        centroid[1] = y0 + sy / n
    chord = sqrt(x * x + y * y)
    total = length + chord
    gap[0] = chord / total if not closed and total > 0 else 0.0
    return True


cdef inline int _crosses(
    double x0, double y0, double x1, double y1, double qx, double qy
) noexcept nogil:
    """1 if the edge (x0, y0) -> (x1, y1) crosses the ray from (qx, qy) towards +x, else 0."""
    return (y0 > qy) != (y1 > qy) and qx < x0 + (qy - y0) * (x1 - x0) / (y1 - y0)


cdef bint _inside(const double* p, Py_ssize_t n, double qx, double qy) noexcept nogil:
    """Even-odd test of (qx, qy) against the polygon through the points (last joins first)."""
    cdef Py_ssize_t i
    cdef int hits = _crosses(p[2 * n - 2], p[2 * n - 1], p[0], p[1], qx, qy)
    for i in range(1, n):
        hits = hits ^ _crosses(p[2 * i - 2], p[2 * i - 1], p[2 * i], p[2 * i + 1], qx, qy)
    return hits != 0


cdef inline double _alpha(double gx, double gy, double mx, double my) noexcept nogil:
    """Deviation angle ``atan2(|g x m|, |g . m|)`` (degrees) of (gx, gy) from (mx, my); 90 if
    either is 0."""
    cdef double dot = fabs(gx * mx + gy * my), cross = fabs(gx * my - gy * mx)
    if dot == 0.0 and cross == 0.0:
        return 90.0
    return atan2(cross, dot) * DEGREES


cdef bint _angles(
    const double* p, const grad_t* g, Py_ssize_t n, double cx, double cy,
    double* alpha, double* total, bint* inside,
) noexcept nogil:
    """Deviation angles alpha_i (degrees) of one contour into ``alpha``, their sum into
    ``total`` and the even-odd test of the centroid (cx, cy) into ``inside``; whether all
    gradients are finite."""
    cdef Py_ssize_t i
    cdef double x, y, xp = p[2 * n - 2], yp = p[2 * n - 1], sum_alpha = 0.0
    cdef int hits = 0
    cdef bint finite = True
    for i in range(n):
        alpha[i] = _alpha(g[2 * i], g[2 * i + 1], cx - p[2 * i], cy - p[2 * i + 1])
    for i in range(n):
        x = p[2 * i]
        y = p[2 * i + 1]
        sum_alpha = sum_alpha + alpha[i]
        finite = finite & (isfinite(g[2 * i]) & isfinite(g[2 * i + 1]))
        hits = hits ^ _crosses(xp, yp, x, y, cx, cy)  # the edge into point i
        xp = x
        yp = y
    total[0] = sum_alpha
    inside[0] = hits != 0
    return finite


cdef int _compare(const void* a, const void* b) noexcept nogil:
    cdef double x = (<const double*>a)[0], y = (<const double*>b)[0]
    return (x > y) - (x < y)


cdef inline Py_ssize_t _partition(
    double* a, Py_ssize_t lo, Py_ssize_t hi, double pivot, bint or_equal
) noexcept nogil:
    """Move the values of a[lo..hi-1] below ``pivot`` (``or_equal``: not above it) to the
    front, keeping the order of neither part; returns where the rest starts. Branchless: each
    value is swapped with the first of the rest, which then grows only if the value belongs in
    front (a branch on the value would be mispredicted about half the time)."""
    cdef Py_ssize_t i, front = lo
    cdef double x
    for i in range(lo, hi):
        x = a[i]
        a[i] = a[front]
        a[front] = x
        front = front + ((x <= pivot) if or_equal else (x < pivot))
    return front


cdef double _median(double* a, Py_ssize_t n) noexcept nogil:
    """Median of a[0..n-1] (reorders a): the mean of the two middle values for even n.

    Quickselect of rank k = (n - 1) // 2 around the median of three: each round splits the
    range a[lo..hi-1] into the values below the pivot, those equal to it (never empty, so every
    round shrinks the range, and runs of equal angles end it at once) and those above, and goes
    on in the part holding rank k. The remaining range is sorted if the pivots keep failing.
    """
    cdef Py_ssize_t k = (n - 1) // 2, lo = 0, hi = n, below, not_above, i
    cdef double x, y, z, pivot, upper
    cdef int rounds = 0
    while hi - lo > 1:
        if rounds == MAX_ROUNDS:
            qsort(a + lo, hi - lo, sizeof(double), _compare)
            break
        rounds = rounds + 1
        x = a[lo]
        y = a[lo + (hi - lo) // 2]
        z = a[hi - 1]
        pivot = y if (x <= y) == (y <= z) else (x if (y <= x) == (x <= z) else z)
        below = _partition(a, lo, hi, pivot, False)
        if k < below:
            hi = below
            continue
        not_above = _partition(a, below, hi, pivot, True)
        if k < not_above:
            break  # a[k] == pivot
        lo = not_above
    # a[0..k-1] <= a[k] <= a[k+1..n-1]
    if n % 2 == 1:
        return a[k]
    upper = a[k + 1]
    for i in range(k + 2, n):
        upper = a[i] if a[i] < upper else upper
    return 0.5 * (a[k] + upper)


# --- the batch entry points -------------------------------------------------------------------

cdef int _check_offsets(const long long[::1] offsets, Py_ssize_t n_points) except -1:
    cdef Py_ssize_t k
    if offsets.shape[0] < 1 or offsets[0] != 0 or offsets[offsets.shape[0] - 1] != n_points:
        raise ValueError("offsets must start at 0 and end at len(points)")
    for k in range(offsets.shape[0] - 1):
        if offsets[k + 1] <= offsets[k]:
            raise ValueError("every contour needs at least one point")
    return 0


def shape_angles(
    const double[:, ::1] points,
    const grad_t[:, ::1] gradients,
    const long long[::1] offsets,
    const unsigned char[::1] closed,
    double open_min_area_ratio,
    double[:, ::1] centroid,
    double[::1] d_alpha_mean,
    double[::1] d_alpha_median,
    unsigned char[::1] inside,
    double[::1] area,
    double[::1] gap_fraction,
    double[::1] scratch,
    int num_threads=1,
) -> None:
    """Fill the (K,) / (K, 2) outputs for the K contours ``points[offsets[k]:offsets[k + 1]]``.

    Parameters
    ----------
    points : float64 (N, 2); gradients : float32 or float64 (N, 2); offsets : int64 (K + 1,)
    closed : uint8 (K,)
    open_min_area_ratio : the ``OPEN_MIN_AREA_RATIO`` of the centroid of an open contour
    centroid, d_alpha_mean, d_alpha_median, inside (uint8), area, gap_fraction : outputs
    scratch : float64 (N,), overwritten (the angles, reordered by the median selection)

    Raises
    ------
    ValueError
        If the offsets do not split the points into non-empty contours, or a point or gradient
        is not finite.
    """
    cdef Py_ssize_t n_points = points.shape[0], n_contours = offsets.shape[0] - 1, k, s, n
    cdef int bad = 0
    cdef double total
    cdef bint is_inside
    if points.shape[1] != 2 or gradients.shape[0] != n_points or gradients.shape[1] != 2 \
            or scratch.shape[0] != n_points:
        raise ValueError("points and gradients must both be (N, 2)")
    _check_offsets(offsets, n_points)
    if closed.shape[0] != n_contours or centroid.shape[0] != n_contours \
            or centroid.shape[1] != 2 or d_alpha_mean.shape[0] != n_contours \
            or d_alpha_median.shape[0] != n_contours or inside.shape[0] != n_contours \
            or area.shape[0] != n_contours or gap_fraction.shape[0] != n_contours:
        raise ValueError("closed and the outputs must have one entry per contour")
    for k in prange(n_contours, nogil=True, schedule="dynamic", num_threads=num_threads):
        s = offsets[k]
        n = offsets[k + 1] - s
        if not _geometry(&points[s, 0], n, closed[k] != 0, open_min_area_ratio,
                         &centroid[k, 0], &area[k], &gap_fraction[k]):
            bad += 1
            continue
        if not _angles(&points[s, 0], &gradients[s, 0], n, centroid[k, 0], centroid[k, 1],
                       &scratch[s], &total, &is_inside):
            bad += 1
            continue
        inside[k] = is_inside
        d_alpha_mean[k] = total / n
        d_alpha_median[k] = _median(&scratch[s], n)
    if bad:
        raise ValueError("points and gradients must be finite")


def polygon_centroids(
    const double[:, ::1] points,
    const long long[::1] offsets,
    const unsigned char[::1] closed,
    double open_min_area_ratio,
    double[:, ::1] centroid,
    double[::1] area,
    double[::1] gap_fraction,
    int num_threads=1,
) -> None:
    """Fill centre of gravity (K, 2), area (K,) and gap fraction (K,) of the K contours.

    Raises
    ------
    ValueError
        If the offsets do not split the points into non-empty contours, or a point is not
        finite.
    """
    cdef Py_ssize_t n_points = points.shape[0], n_contours = offsets.shape[0] - 1, k, s
    cdef int bad = 0
    if points.shape[1] != 2:
        raise ValueError("points must be (N, 2)")
    _check_offsets(offsets, n_points)
    if closed.shape[0] != n_contours or centroid.shape[0] != n_contours \
            or centroid.shape[1] != 2 or area.shape[0] != n_contours \
            or gap_fraction.shape[0] != n_contours:
        raise ValueError("closed and the outputs must have one entry per contour")
    for k in prange(n_contours, nogil=True, schedule="dynamic", num_threads=num_threads):
        s = offsets[k]
        if not _geometry(&points[s, 0], offsets[k + 1] - s, closed[k] != 0,
                         open_min_area_ratio, &centroid[k, 0], &area[k], &gap_fraction[k]):
            bad += 1
    if bad:
        raise ValueError("points must be finite")


def points_in_polygons(
    const double[:, ::1] query,
    const double[:, ::1] points,
    const long long[::1] offsets,
    unsigned char[::1] inside,
    int num_threads=1,
) -> None:
    """Fill ``inside[k]`` (uint8) with the even-odd test of query point k against polygon k.

    Raises
    ------
    ValueError
        If the offsets do not split the points into non-empty contours.
    """
    cdef Py_ssize_t n_points = points.shape[0], n_contours = offsets.shape[0] - 1, k, s
    if points.shape[1] != 2 or query.shape[1] != 2:
        raise ValueError("query and points must be (K, 2) and (N, 2)")
    _check_offsets(offsets, n_points)
    if query.shape[0] != n_contours or inside.shape[0] != n_contours:
        raise ValueError("query and inside must have one entry per contour")
    for k in prange(n_contours, nogil=True, schedule="dynamic", num_threads=num_threads):
        s = offsets[k]
        inside[k] = _inside(&points[s, 0], offsets[k + 1] - s, query[k, 0], query[k, 1])
