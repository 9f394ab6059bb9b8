# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Shape angle kernel (eq. 3): centroid, area, gap, D_alpha mean and median, centroid inside.

See :mod:`labauto.vision.shape_angle` for the definitions and the choices made. One call handles
all K contours of an image; contours are shared among threads. Per contour: the mean of the
points, the polygon moments (centred on that mean), the length along the points, then one pass
for the deviation angles and the even-odd crossing count of the centroid, and the median of the
angles by selection (Hoare's quickselect, O(n) expected; the remaining range is sorted if the
pivots keep failing, so O(n log n) at worst).

The sums over a contour's points are numpy's (``np.add.reduceat``: the first term plus the
pairwise sum of the rest, 8 accumulators in blocks of at most 128) and the sum of the angles
runs in point order (``np.bincount``), so the results equal the numpy formulas of the module's
documentation to the last bit, except that ``acos`` may differ from numpy's ``arccos`` in the
last place.
"""

from cython.parallel cimport prange
from libc.math cimport M_PI, acos, fabs, hypot, isfinite
from libc.stdlib cimport qsort

ctypedef fused grad_t:
    float
    double

cdef double DEGREES = 180.0 / M_PI
# numpy's pairwise summation: blocks of at most this many terms, 8 accumulators in a block
cdef Py_ssize_t PW_BLOCKSIZE = 128
# quickselect rounds on one contour before the remaining range is sorted instead
cdef int MAX_ROUNDS = 64


cdef struct Sums:
    double a, b, c, d


# --- numpy's pairwise sums of per-point terms -------------------------------------------------

cdef inline void _mean_terms(const double* p, Py_ssize_t i, double* t) noexcept nogil:
    t[0] = p[2 * i]
    t[1] = p[2 * i + 1]


cdef inline void _moment_terms(
    const double* p, Py_ssize_t n, double mx, double my, Py_ssize_t i, double* t
) noexcept nogil:
    """Polygon terms of edge i -> i + 1 (the last point joins the first), centred on (mx, my)."""
    cdef Py_ssize_t j = i + 1 if i + 1 < n else 0
    cdef double x = p[2 * i] - mx, y = p[2 * i + 1] - my
    cdef double xn = p[2 * j] - mx, yn = p[2 * j + 1] - my
    cdef double cross = x * yn - xn * y
    t[0] = cross
    t[1] = (x + xn) * cross
    t[2] = (y + yn) * cross
    t[3] = x * x + y * y


cdef inline void _step_terms(const double* p, Py_ssize_t n, Py_ssize_t i, double* t) noexcept nogil:
    """Length of the step i -> i + 1; 0 from the last point (no step to the next contour)."""
    t[0] = hypot(p[2 * i + 2] - p[2 * i], p[2 * i + 3] - p[2 * i + 1]) if i + 1 < n else 0.0


cdef inline void _terms(
    int kind, const double* p, Py_ssize_t n, double mx, double my, Py_ssize_t i, double* t
) noexcept nogil:
    if kind == 0:
        _mean_terms(p, i, t)
    elif kind == 1:
        _moment_terms(p, n, mx, my, i, t)
    else:
        _step_terms(p, n, i, t)


cdef Sums _pairwise(
    int kind, int m, const double* p, Py_ssize_t n, double mx, double my,
    Py_ssize_t lo, Py_ssize_t hi,
) noexcept nogil:
    """numpy's pairwise sums over terms lo..hi-1 of ``m`` (<= 4) per-point quantities."""
    cdef Sums out
    cdef double r[4][8]
    cdef double t[4]
    cdef double res[4]
    cdef Py_ssize_t count = hi - lo, i, half
    cdef int j, q
    cdef Sums left, right
    if count < 8:
        for q in range(4):
            res[q] = 0.0
        for i in range(lo, hi):
            _terms(kind, p, n, mx, my, i, t)
            for q in range(m):
                res[q] = res[q] + t[q]
    elif count <= PW_BLOCKSIZE:
        for j in range(8):
            _terms(kind, p, n, mx, my, lo + j, t)
            for q in range(m):
                r[q][j] = t[q]
        i = lo + 8
        while i < hi - count % 8:
            for j in range(8):
                _terms(kind, p, n, mx, my, i + j, t)
                for q in range(m):
                    r[q][j] = r[q][j] + t[q]
            i = i + 8
        for q in range(m):
            res[q] = ((r[q][0] + r[q][1]) + (r[q][2] + r[q][3])) + (
                (r[q][4] + r[q][5]) + (r[q][6] + r[q][7])
            )
        while i < hi:
            _terms(kind, p, n, mx, my, i, t)
            for q in range(m):
                res[q] = res[q] + t[q]
            i = i + 1
    else:
        half = count // 2
        half = half - half % 8
        left = _pairwise(kind, m, p, n, mx, my, lo, lo + half)
        right = _pairwise(kind, m, p, n, mx, my, lo + half, hi)
        out.a = left.a + right.a
        out.b = left.b + right.b
        out.c = left.c + right.c
        out.d = left.d + right.d
        return out
    out.a = res[0]
    out.b = res[1] if m > 1 else 0.0
    out.c = res[2] if m > 2 else 0.0
    out.d = res[3] if m > 3 else 0.0
    return out


cdef Sums _reduceat(
    int kind, int m, const double* p, Py_ssize_t n, double mx, double my
) noexcept nogil:
    """``np.add.reduceat`` of one contour's terms: the first term plus the pairwise rest."""
    cdef double t[4]
    cdef Sums out = _pairwise(kind, m, p, n, mx, my, 1, n)
    _terms(kind, p, n, mx, my, 0, t)
    out.a = t[0] + out.a
    if m > 1:
        out.b = t[1] + out.b
    if m > 2:
        out.c = t[2] + out.c
    if m > 3:
        out.d = t[3] + out.d
    return out


# --- one contour --------------------------------------------------------------------------------

cdef bint _geometry(
    const double* p, Py_ssize_t n, bint closed, double open_ratio,
    double* centroid, double* area, double* gap,
) noexcept nogil:
    """Centre of gravity, polygon area and gap fraction of one contour of ``n`` interleaved
    ``(x, y)`` points (``open_ratio``: see ``OPEN_MIN_AREA_RATIO``). Returns whether all
    coordinates are finite."""
    cdef Sums s = _reduceat(0, 2, p, n, 0.0, 0.0)
    cdef double mx = s.a / n, my = s.b / n
    cdef double twice_area, spread, min_ratio, safe, length, chord, total
    if not (isfinite(s.a) and isfinite(s.b)):
        return False
    s = _reduceat(1, 4, p, n, mx, my)
    twice_area = s.a
    spread = s.d / n
    # open contours: the chord-closed polygon if it encloses a real area (a disk has
    # area / spread = pi, a straight line 0), else the points' mean
    min_ratio = 1e-6 if closed else open_ratio
    if fabs(twice_area) / 2.0 > min_ratio * spread:
        safe = 3.0 * twice_area
        centroid[0] = mx + s.b / safe
        centroid[1] = my + s.c / safe
    else:
        centroid[0] = mx + 0.0
        centroid[1] = my + 0.0
    area[0] = fabs(twice_area) / 2.0
    if closed:
        gap[0] = 0.0
    else:
        length = _reduceat(2, 1, p, n, 0.0, 0.0).a
        chord = hypot(p[2 * n - 2] - p[0], p[2 * n - 1] - p[1])
        total = length + chord
        gap[0] = chord / total if total > 0 else 0.0
    return True


cdef bint _inside(const double* p, Py_ssize_t n, double qx, double qy) noexcept nogil:
    """Even-odd test of (qx, qy) against the polygon through the points (last joins first)."""
    cdef Py_ssize_t i, j
    cdef int hits = 0
    cdef double x0, y0, x1, y1
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        x0 = p[2 * i]
        y0 = p[2 * i + 1]
        x1 = p[2 * j]
        y1 = p[2 * j + 1]
        if (y0 > qy) != (y1 > qy) and qx < x0 + (qy - y0) * (x1 - x0) / (y1 - y0):
            hits = hits ^ 1
    return hits != 0


cdef bint _angles(
    const double* p, const grad_t* g, Py_ssize_t n, double cx, double cy, double* alpha
) noexcept nogil:
    """Deviation angles alpha_i (degrees) of one contour into ``alpha``; whether all finite."""
    cdef Py_ssize_t i
    cdef double gx, gy, mx, my, dot, norm, cos
    cdef bint finite = True
    for i in range(n):
        gx = g[2 * i]
        gy = g[2 * i + 1]
        mx = cx - p[2 * i]
        my = cy - p[2 * i + 1]
        dot = fabs(gx * mx + gy * my)
        norm = hypot(gx, gy) * hypot(mx, my)
        cos = dot / norm if norm > 0 else 0.0
        cos = cos if cos < 1.0 else 1.0
        finite = finite & (isfinite(gx) & isfinite(gy))
        alpha[i] = acos(cos) * DEGREES
    return finite


cdef int _compare(const void* a, const void* b) noexcept nogil:
    cdef double x = (<const double*>a)[0], y = (<const double*>b)[0]
    return (x > y) - (x < y)


cdef double _median(double* a, Py_ssize_t n) noexcept nogil:
    """Median of a[0..n-1] (reorders a): the mean of the two middle values for even n."""
    cdef Py_ssize_t k = (n - 1) // 2, lo = 0, hi = n - 1, i, j
    cdef double pivot, x, y, z, upper
    cdef int rounds = 0
    while hi > lo:
        if rounds == MAX_ROUNDS:
            qsort(a + lo, hi - lo + 1, sizeof(double), _compare)
            break
        rounds = rounds + 1
        # Hoare partition around the median of three
        x = a[lo]
        y = a[lo + (hi - lo) // 2]
        z = a[hi]
        pivot = y if (x <= y) == (y <= z) else (x if (y <= x) == (x <= z) else z)
        i = lo
        j = hi
        while i <= j:
            while a[i] < pivot:
                i = i + 1
            while a[j] > pivot:
                j = j - 1
            if i <= j:
                x = a[i]
                a[i] = a[j]
                a[j] = x
                i = i + 1
                j = j - 1
        # now a[lo..j] <= pivot <= a[i..hi], and a[j+1..i-1] == pivot
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    # every value after a[k] is >= a[k]
    if n % 2 == 1:
        return 0.5 * (a[k] + a[k])
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
    cdef Py_ssize_t n_points = points.shape[0], n_contours = offsets.shape[0] - 1, k, s, n, i
    cdef int bad = 0
    cdef double total
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
                       &scratch[s]):
            bad += 1
            continue
        inside[k] = _inside(&points[s, 0], n, centroid[k, 0], centroid[k, 1])
        total = 0.0
        for i in range(s, s + n):
            total = total + scratch[i]
        d_alpha_mean[k] = total / n
        d_alpha_median[k] = _median(&scratch[offsets[k]], n)
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
