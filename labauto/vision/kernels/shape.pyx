# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
# distutils: extra_compile_args = -fno-math-errno -fno-trapping-math
"""Shape kernel: Table 1 descriptors and the exact polar series (eq. 4) of many contours.

See :mod:`labauto.vision.descriptors` and :mod:`labauto.vision.harmonics` for the definitions
and the choices made; this is their inner loop. :func:`measure_contours` takes K contours
concatenated (``points[offsets[k]:offsets[k + 1]]``) and, per contour (contours shared among
threads), checks the coordinates are finite (one vectorised pass), drops repeated points,
then computes

* the area and area centroid of the polygon (about the vertex mean), the curve centroid when
  there is no area, the semi-axes from the second moments, the perimeter;
* the convex hull (monotone chain after a natural merge sort: an ordered contour is made of a
  few x-monotone runs, and the sort is handed the points starting at the last run, which on a
  closed contour usually goes on into the first) and the minimum-area box around it (rotating
  calipers, each caliper's next four heights and three steps at once, :func:`_rise3`); the
  hull's perimeter from the box's edges;
* optionally the Fourier coefficients of ``r`` and ``r^-2`` about the centre, exact per edge
  (see :func:`_series`), harmonic by harmonic in vectorised passes over all vertices and edges;
  the sums over the edges run in LANES partial sums (added up in a fixed order); atan2 and log
  are the C library's.

Compiled with ``-fno-math-errno`` (second line) so that loops with ``sqrt`` vectorise, and
``-fno-trapping-math`` so that selects (``a if c else b``) on computed values vectorise too (it
changes no result: it lets the compiler compute both sides).

Everything is float64 and per contour in a fixed order (the descriptors' sums in vertex order),
so a contour's results do not depend on the other contours of the batch or the thread count.
"""

from cython.parallel cimport parallel, prange
from libc.math cimport INFINITY, NAN, atan2, fabs, isfinite, log, nearbyint, sqrt
from libc.stdint cimport int64_t, uint64_t, uintptr_t
from libc.stdlib cimport free, malloc
from libc.string cimport memcpy

import numpy as np

cdef enum:
    # descriptor status (per contour)
    S_OK = 0
    S_TOO_FEW_POINTS = 1  # fewer than min_points points
    S_NON_FINITE = 2  # a NaN or infinite coordinate
    S_ONE_POINT = 3  # fewer than 2 distinct points
    S_NEGATIVE_MOMENTS = 4  # a self-intersecting polygon with a negative second moment
    # series status (per contour)
    S_SERIES_OK = 0
    S_SERIES_SKIPPED = 1  # not asked for, a line (elongation >= max_elongation), too few points
    S_SERIES_NO_AREA = 2  # no centre given and the polygon has no area
    S_SERIES_BAD_CENTRE = 3  # the given centre is not finite
    S_SERIES_NO_WINDING = 4  # the contour does not wind around the centre
    NV = 14  # len(VALUE_NAMES)
    LANES = 8  # partial sums of a vectorised reduction (8 doubles: one AVX-512 register)

OK, TOO_FEW_POINTS, NON_FINITE, ONE_POINT, NEGATIVE_MOMENTS = (
    S_OK, S_TOO_FEW_POINTS, S_NON_FINITE, S_ONE_POINT, S_NEGATIVE_MOMENTS
)
SERIES_OK, SERIES_SKIPPED, SERIES_NO_AREA, SERIES_BAD_CENTRE, SERIES_NO_WINDING = (
    S_SERIES_OK, S_SERIES_SKIPPED, S_SERIES_NO_AREA, S_SERIES_BAD_CENTRE, S_SERIES_NO_WINDING
)

#: Columns of the (K, NV) value array of :func:`measure_contours`.
VALUE_NAMES = (
    "area", "centroid_x", "centroid_y", "semi_major", "semi_minor", "perimeter", "closing",
    "convex_perimeter", "elongation", "rectangularity", "centre_x", "centre_y",
    "star_shapedness", "winding",
)

cdef extern from *:
    # restrict pointers: the per-edge loops over harmonics read and write several arrays of one
    # work buffer; without restrict gcc does not vectorise them (too many pointers to check)
    ctypedef double* double_r "double * __restrict__"
    ctypedef const double* cdouble_r "const double * __restrict__"

cdef double PI = 3.141592653589793
cdef double NO_AREA_COMPACTNESS = 1e-9  # below it a polygon has no area (a traced line)


# ------------------------------------------------------------------------------ small pieces


cdef inline Py_ssize_t _round_up(Py_ssize_t n) noexcept nogil:
    """n rounded up to a multiple of LANES (whole 64-byte lines of doubles)."""
    return (n + LANES - 1) // LANES * LANES


cdef Py_ssize_t _dedup(const double* src, Py_ssize_t n, bint closed, double* dst) noexcept nogil:
    """Copy points unequal to their predecessor (if closed, drop a last one equal to the first)."""
    cdef Py_ssize_t i, m = 0
    cdef double x, y
    for i in range(n):
        x = src[2 * i]
        y = src[2 * i + 1]
        if m == 0 or x != dst[2 * m - 2] or y != dst[2 * m - 1]:
            dst[2 * m] = x
            dst[2 * m + 1] = y
            m += 1
    if closed and m > 1 and dst[0] == dst[2 * m - 2] and dst[1] == dst[2 * m - 1]:
        m -= 1
    return m


cdef bint _all_finite(const double* x, Py_ssize_t n) noexcept nogil:
    """Whether the n doubles x are all finite: no exponent field all ones (inf, NaN), as an
    integer OR over all of them (one vectorised loop, no early exit)."""
    cdef Py_ssize_t i
    cdef uint64_t bits, bad = 0
    for i in range(n):
        memcpy(&bits, x + i, 8)
        bad |= ((bits >> 52) & 0x7ff) == 0x7ff
    return bad == 0


cdef inline double _lanes_sum(const double* acc) noexcept nogil:
    """Sum of the LANES partial sums of a reduction, in a fixed order."""
    return ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))


cdef void _area_about(
    const double* p, Py_ssize_t n, double mx, double my, double* out,
) noexcept nogil:
    """out = (signed area, centroid x, centroid y) of the polygon p (n vertices, vertex 0 again
    at n) summed about (mx, my), the vertex mean; the mean when no area."""
    cdef Py_ssize_t i
    cdef double px, py, qx, qy, c, s = 0.0, sx = 0.0, sy = 0.0
    for i in range(n):
        px = p[2 * i] - mx
        py = p[2 * i + 1] - my
        qx = p[2 * i + 2] - mx
        qy = p[2 * i + 3] - my
        c = px * qy - qx * py
        s += c
        sx += (px + qx) * c
        sy += (py + qy) * c
    s *= 0.5
    out[0] = s
    if s == 0.0:
        out[1] = mx
        out[2] = my
    else:
        out[1] = mx + sx / (6.0 * s)
        out[2] = my + sy / (6.0 * s)


cdef void _area_centroid(const double* p, Py_ssize_t n, double* out) noexcept nogil:
    """out = (signed area, centroid x, centroid y) about the vertex mean; the mean when no area
    (p: n vertices, vertex 0 again at n)."""
    cdef Py_ssize_t i
    cdef double mx = 0.0, my = 0.0
    for i in range(n):
        mx += p[2 * i]
        my += p[2 * i + 1]
    _area_about(p, n, mx / n, my / n, out)


cdef inline bint _less(const double* a, const double* b) noexcept nogil:
    return a[0] < b[0] or (a[0] == b[0] and a[1] < b[1])


cdef Py_ssize_t _last_run(const double* a, Py_ssize_t n) noexcept nogil:
    """Start of the last run of the n (x, y) pairs a as :func:`_sort_points` finds runs
    (non-decreasing or strictly decreasing), found backwards from the end."""
    cdef Py_ssize_t i = n - 1
    if n < 2:
        return 0
    if _less(a + 2 * i, a + 2 * i - 2):
        while i > 0 and _less(a + 2 * i, a + 2 * i - 2):
            i -= 1
    else:
        while i > 0 and not _less(a + 2 * i, a + 2 * i - 2):
            i -= 1
    return i


cdef double* _sort_points(double* a, double* tmp, Py_ssize_t n, Py_ssize_t* runs) noexcept nogil:
    """Sort n (x, y) pairs by x, then y (natural merge sort); returns a or tmp, the sorted one."""
    cdef Py_ssize_t i = 0, j, lo, mid, hi, nr = 0, m, r, u, v, w
    cdef double t
    cdef double* src = a
    cdef double* dst = tmp
    cdef double* swap
    while i < n:  # runs: non-decreasing, or strictly decreasing (reversed in place)
        j = i + 1
        if j < n and _less(a + 2 * j, a + 2 * i):
            while j < n and _less(a + 2 * j, a + 2 * j - 2):
                j += 1
            u = i
            v = j - 1
            while u < v:
                t = a[2 * u]; a[2 * u] = a[2 * v]; a[2 * v] = t
                t = a[2 * u + 1]; a[2 * u + 1] = a[2 * v + 1]; a[2 * v + 1] = t
                u += 1
                v -= 1
        else:
            while j < n and not _less(a + 2 * j, a + 2 * j - 2):
                j += 1
        runs[nr] = i
        nr += 1
        i = j
    runs[nr] = n
    while nr > 1:
        m = 0
        r = 0
        while r < nr:
            lo = runs[r]
            if r + 1 < nr:
                mid = runs[r + 1]
                hi = runs[r + 2]
            else:
                mid = runs[r + 1]
                hi = mid
            u = lo
            v = mid
            w = lo
            while u < mid and v < hi:
                if _less(src + 2 * v, src + 2 * u):
                    dst[2 * w] = src[2 * v]; dst[2 * w + 1] = src[2 * v + 1]
                    v += 1
                else:
                    dst[2 * w] = src[2 * u]; dst[2 * w + 1] = src[2 * u + 1]
                    u += 1
                w += 1
            while u < mid:
                dst[2 * w] = src[2 * u]; dst[2 * w + 1] = src[2 * u + 1]
                u += 1
                w += 1
            while v < hi:
                dst[2 * w] = src[2 * v]; dst[2 * w + 1] = src[2 * v + 1]
                v += 1
                w += 1
            runs[m] = lo
            m += 1
            r += 2
        runs[m] = n
        nr = m
        swap = src
        src = dst
        dst = swap
    return src


cdef inline double _turn(const double* o, const double* a, const double* b) noexcept nogil:
    """(a - o) x (b - o): > 0 for a left (counter-clockwise) turn o -> a -> b."""
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


cdef Py_ssize_t _chain(
    const double* p, Py_ssize_t n, Py_ssize_t step, double* h, Py_ssize_t k, Py_ssize_t t,
) noexcept nogil:
    """One chain of the monotone chain: push the n points p, p + 2 step, ... onto the stack h of
    k vertices, first popping the top while it does not turn left and k >= t; the new k."""
    cdef Py_ssize_t i
    cdef const double* pi
    for i in range(n):
        pi = p + 2 * i * step
        while k >= t and _turn(h + 2 * k - 4, h + 2 * k - 2, pi) <= 0.0:
            k -= 1
        h[2 * k] = pi[0]
        h[2 * k + 1] = pi[1]
        k += 1
    return k


cdef Py_ssize_t _hull(const double* p, Py_ssize_t n, double* h, double* w) noexcept nogil:
    """Convex hull (Andrew's monotone chain) of n >= 1 sorted points into h (2 (n + 1) doubles;
    w: 4 n + 4 doubles of work).

    Counter-clockwise in (x, y) axes, without collinear vertices; collinear points give their two
    ends, a single point one vertex. The points are first split by the line from the first (L)
    to the last (R) sorted point: the lower chain L -> R takes only those not above it, the upper
    chain R -> L those not below it (a band of 1e-12 of the scale, so rounding keeps every hull
    vertex in its chain). Points off a chain would be pushed and popped again at about one
    mispredicted branch each; the split is branchless (both lists written, one count advanced).
    """
    cdef Py_ssize_t i, k, nl = 1, nu = 0
    cdef double lx = p[0], ly = p[1], dx = p[2 * n - 2] - lx, dy = p[2 * n - 1] - ly
    cdef double ex, ey, c, tol, sx = fabs(dx) + fabs(dy)
    cdef double* lower = w  # L, the points not above the line (ascending), R
    cdef double* upper = w + 2 * n + 2  # L, the points not below it (ascending)
    lower[0] = lx
    lower[1] = ly
    upper[0] = lx
    upper[1] = ly
    for i in range(1, n - 1):
        ex = p[2 * i] - lx
        ey = p[2 * i + 1] - ly
        c = dx * ey - dy * ex  # > 0: above (left of L -> R)
        tol = 1e-12 * sx * (fabs(ex) + fabs(ey))
        lower[2 * nl] = p[2 * i]
        lower[2 * nl + 1] = p[2 * i + 1]
        upper[2 * nu + 2] = p[2 * i]
        upper[2 * nu + 3] = p[2 * i + 1]
        nl += c <= tol
        nu += c >= -tol
    if n > 1:
        lower[2 * nl] = p[2 * n - 2]  # R
        lower[2 * nl + 1] = p[2 * n - 1]
        nl += 1
    k = _chain(lower, nl, 1, h, 0, 2)
    k = _chain(upper + 2 * nu, nu + 1 if n > 1 else 0, -1, h, k, k + 1)  # descending, then L
    if k > 1:
        k -= 1  # the last vertex repeats the first
    if k == 2 and h[0] == h[2] and h[1] == h[3]:
        k = 1
    return k


cdef inline double _dot(const double* p, const double* o, double ux, double uy) noexcept nogil:
    return (p[0] - o[0]) * ux + (p[1] - o[1]) * uy


cdef extern from *:
    """
    /* The heights d_k = (p[0] - o[0]) ux + (p[1] - o[1]) uy of the four points p = h + 2 k
       (k = 0..3, as _dot rounds them: the same products and sum on every path); returns how
       many of the steps 0 -> 1, 1 -> 2, 2 -> 3 in a row do not go down (0..3) and d_3 in *d3,
       without branches. */
    static inline int labauto_rise3(const double* h, const double* o, double ux, double uy,
                                    double* d3) {
        const double d0 = (h[0] - o[0]) * ux + (h[1] - o[1]) * uy;
        const double d1 = (h[2] - o[0]) * ux + (h[3] - o[1]) * uy;
        const double d2 = (h[4] - o[0]) * ux + (h[5] - o[1]) * uy;
        const double e3 = (h[6] - o[0]) * ux + (h[7] - o[1]) * uy;
        const int s1 = !(d1 < d0), s2 = s1 & !(d2 < d1), s3 = s2 & !(e3 < d2);
        *d3 = e3;
        return s1 + s2 + s3;
    }
    """
    int _rise3 "labauto_rise3"(
        const double* h, const double* o, double ux, double uy, double* d3
    ) noexcept nogil


cdef inline Py_ssize_t _walk(
    const double* h, Py_ssize_t m, Py_ssize_t j, const double* o, double ux, double uy,
) noexcept nogil:
    """From vertex j, the first vertex along the hull whose successor is lower in direction
    (ux, uy) (heights about o; at most m steps; h holds vertices 0, 1, 2 again after m - 1).

    Between two hull edges an extreme vertex moves 0, 1, 2, 3 or more steps about 45, 35, 13,
    4 and 3 % of the time (short and long hull edges alternate): the heights of j..j + 3 and
    the first three steps at once, without branches (:func:`_rise3`); a fourth step and on
    goes by a loop (entered 7 % of the time)."""
    cdef Py_ssize_t jn, steps, rise
    cdef double d3, nxt
    cdef bint take
    rise = _rise3(h + 2 * j, o, ux, uy, &d3)
    steps = m if rise > m else rise  # (a triangle: once round at most)
    j += steps
    j = j - m if j >= m else j
    take = rise == 3
    while take and steps < m:
        jn = j + 1 if j + 1 < m else 0
        nxt = _dot(h + 2 * jn, o, ux, uy)
        take = not (nxt < d3)
        j = jn if take else j
        d3 = nxt if take else d3
        steps += 1
    return j


cdef double _min_area_box(
    const double* h, Py_ssize_t m, double* u, double* side,
) noexcept nogil:
    """Long and short side of the minimum-area rectangle around the convex polygon h (m vertices,
    counter-clockwise): rotating calipers, one side of the box on each hull edge in turn; of
    boxes with the same area (to 1e-12) the least elongated. Returns the polygon's perimeter.

    Two passes: the edges' lengths and unit directions into u (one loop, square roots and
    divisions vectorised; the perimeter is the lengths' sum in edge order), then the calipers
    (:func:`_walk`, on a copy of h that goes on for 4 vertices past the last; u: 5 m + 8
    doubles)."""
    cdef Py_ssize_t i, j, far = 0, hi = 0, lo = 0
    cdef double ux, uy, length, width, extent, area, best = INFINITY, long_side, short_side
    cdef double d_far, d_hi, d_lo, d, perimeter = 0.0
    cdef double* hx = u + 2 * m
    cdef double* lengths = u + 4 * m + 8
    side[0] = 0.0
    side[1] = 0.0
    if m < 3:  # a point (0) or a segment (twice its length)
        for i in range(m):
            j = i + 1 if i + 1 < m else 0
            ux = h[2 * j] - h[2 * i]
            uy = h[2 * j + 1] - h[2 * i + 1]
            perimeter += sqrt(ux * ux + uy * uy)
        if m == 2:
            ux = h[2] - h[0]
            uy = h[3] - h[1]
            side[0] = sqrt(ux * ux + uy * uy)
        return perimeter
    for i in range(2 * m - 2):  # u[2 i], u[2 i + 1]: edge i -> i + 1, the last one below
        u[i] = h[i + 2] - h[i]
    u[2 * m - 2] = h[0] - h[2 * m - 2]
    u[2 * m - 1] = h[1] - h[2 * m - 1]
    for i in range(m):
        ux = u[2 * i]
        uy = u[2 * i + 1]
        length = sqrt(ux * ux + uy * uy)
        lengths[i] = length
        u[2 * i] = ux / length
        u[2 * i + 1] = uy / length
    for i in range(m):
        perimeter += lengths[i]
    for i in range(2 * m):
        hx[i] = h[i]
    for i in range(8):
        hx[2 * m + i] = h[i % (2 * m)]
    # the extreme vertices of the first edge by a full scan (the first of equal heights)
    ux = u[0]
    uy = u[1]
    d_far = _dot(h, h, -uy, ux)
    d_hi = _dot(h, h, ux, uy)
    d_lo = d_hi
    for j in range(1, m):
        d = _dot(h + 2 * j, h, -uy, ux)
        far = j if d > d_far else far
        d_far = d if d > d_far else d_far
        d = _dot(h + 2 * j, h, ux, uy)
        hi = j if d > d_hi else hi
        d_hi = d if d > d_hi else d_hi
        lo = j if d < d_lo else lo
        d_lo = d if d < d_lo else d_lo
    for i in range(m):
        ux = u[2 * i]
        uy = u[2 * i + 1]
        if i > 0:  # as the edge turns counter-clockwise, so do its extreme vertices
            far = _walk(hx, m, far, h + 2 * i, -uy, ux)
            hi = _walk(hx, m, hi, h + 2 * i, ux, uy)
            lo = _walk(hx, m, lo, h + 2 * i, -ux, -uy)  # lowest: highest in direction -u
        width = _dot(h + 2 * far, h + 2 * i, -uy, ux)
        extent = _dot(h + 2 * hi, h + 2 * i, ux, uy) - _dot(h + 2 * lo, h + 2 * i, ux, uy)
        area = width * extent
        long_side = extent if extent >= width else width
        short_side = width if extent >= width else extent
        # ties (a triangle's three boxes have the same area): the least elongated box
        if area < best * (1.0 - 1e-12) or (
            area <= best * (1.0 + 1e-12) and long_side * side[1] < side[0] * short_side
        ):
            best = area if area < best else best
            side[0] = long_side
            side[1] = short_side
    return perimeter


# ------------------------------------------------------------------------------ descriptors


cdef int _descriptors(
    const double* q, Py_ssize_t n, double* sorted_a, double* sorted_b, Py_ssize_t* runs,
    double* hull, double* work, double* out,
) noexcept nogil:
    """Descriptors of the polygon q (n >= 2 points, no repeats, vertex 0 again at n) into
    out[0:10]; the status (work: 5 n + 8 doubles).

    The sums over the vertices are plain sums in vertex order: the moments of a sliver (a
    traced line that still encloses a little area) divide by its area, and the rounding of
    another order would change them by parts in 1e9."""
    cdef Py_ssize_t i, j, m
    cdef double ac[3]
    cdef double side[2]
    cdef double ex, ey, total = 0.0, area, cx, cy, mx = 0.0, my = 0.0, vx = 0.0, vy = 0.0
    cdef double px, py, qx, qy, c, w, area2 = 0.0, sxx = 0.0, syy = 0.0, sxy = 0.0, scale
    cdef double_r seg = sorted_b  # (before the sort)
    cdef double half_trace, root, major2, box_area, long_side, short_side
    cdef bint has_area
    cdef double* s
    # perimeter: the segment lengths (one vectorised loop) into seg, then in one loop their
    # sums, the curve centroid's and the vertex mean's (about which the area is summed)
    for i in range(n):
        ex = q[2 * i + 2] - q[2 * i]
        ey = q[2 * i + 3] - q[2 * i + 1]
        seg[i] = sqrt(ex * ex + ey * ey)
    for i in range(n):
        total += seg[i]
        mx += (q[2 * i] + q[2 * i + 2]) * seg[i]  # for the curve centroid
        my += (q[2 * i + 1] + q[2 * i + 3]) * seg[i]
        vx += q[2 * i]
        vy += q[2 * i + 1]
    out[5] = total
    out[6] = seg[n - 1]  # the closing segment, last point to first
    _area_about(q, n, vx / n, vy / n, ac)
    area = fabs(ac[0])
    has_area = 4.0 * PI * area > NO_AREA_COMPACTNESS * total * total
    if has_area:
        cx = ac[1]
        cy = ac[2]
    else:  # a traced line: the centroid of the curve with uniform mass per length
        area = 0.0
        cx = 0.5 * mx / total
        cy = 0.5 * my / total
    out[0] = area
    out[1] = cx
    out[2] = cy

    # second moments about the centroid: of the filled polygon, or of the curve without area
    # (one loop per case: the curve's square root and division would otherwise be computed
    # for every polygon too)
    if has_area:
        for i in range(n):
            px = q[2 * i] - cx
            py = q[2 * i + 1] - cy
            qx = q[2 * i + 2] - cx
            qy = q[2 * i + 3] - cy
            w = px * qy - qx * py
            area2 += w
            sxx += w * (px * px + px * qx + qx * qx)
            syy += w * (py * py + py * qy + qy * qy)
            sxy += w * (2.0 * px * py + px * qy + qx * py + 2.0 * qx * qy)
    else:
        for i in range(n):
            px = q[2 * i] - cx
            py = q[2 * i + 1] - cy
            qx = q[2 * i + 2] - cx
            qy = q[2 * i + 3] - cy
            ex = qx - px
            ey = qy - py
            w = sqrt(ex * ex + ey * ey) / total
            sxx += w * (px * px + px * qx + qx * qx)
            syy += w * (py * py + py * qy + qy * qy)
            sxy += w * (2.0 * px * py + px * qy + qx * py + 2.0 * qx * qy)
    if has_area:
        sxx /= 6.0 * area2
        syy /= 6.0 * area2
        sxy /= 12.0 * area2
        scale = 4.0  # filled ellipse: variance along an axis = semi-axis^2 / 4
    else:
        sxx /= 3.0
        syy /= 3.0
        sxy /= 6.0
        scale = 3.0  # uniform segment of length L: variance L^2 / 12, semi-axis L / 2
    half_trace = 0.5 * (sxx + syy)
    ex = 0.5 * (sxx - syy)
    root = sqrt(ex * ex + sxy * sxy)
    major2 = scale * (half_trace + root)
    out[3] = sqrt(major2) if major2 >= 0.0 else NAN
    out[4] = sqrt(scale * (half_trace - root)) if half_trace - root > 0.0 else 0.0

    # convex hull and its minimum-area box
    # the points to sort, starting with the contour's last monotone run: on a closed contour
    # it usually goes on into the first (3 runs become 2, one merge pass fewer); the sorted
    # points do not depend on the order they come in
    j = _last_run(q, n)
    for i in range(2 * (n - j)):
        sorted_a[i] = q[2 * j + i]
    for i in range(2 * j):
        sorted_a[2 * (n - j) + i] = q[i]
    s = _sort_points(sorted_a, sorted_b, n, runs)
    m = _hull(s, n, hull, work)
    out[7] = _min_area_box(hull, m, work, side)  # the hull's work is done with
    long_side = side[0]
    short_side = side[1]
    if short_side > 1e-12 * long_side:
        box_area = long_side * short_side
        out[8] = long_side / short_side
    else:
        box_area = 0.0
        out[8] = INFINITY
    out[9] = (area / box_area if area < box_area else 1.0) if box_area > 0.0 else 0.0
    return S_OK if major2 >= 0.0 else S_NEGATIVE_MOMENTS


# ------------------------------------------------------------------------------ polar series


cdef void _vertex_powers(
    cdouble_r wx, cdouble_r wy, double_r pr, double_r pi, Py_ssize_t nv,
) noexcept nogil:
    """pr + i pi *= wx + i wy at nv vertices (one vectorised loop)."""
    cdef Py_ssize_t i
    cdef double xr
    for i in range(nv):
        xr = pr[i] * wx[i] - pi[i] * wy[i]
        pi[i] = pr[i] * wy[i] + pi[i] * wx[i]
        pr[i] = xr


cdef void _edge_sums(
    cdouble_r pr, cdouble_r pi, cdouble_r hh, cdouble_r ar, cdouble_r ai, Py_ssize_t ne,
    double* out,
) noexcept nogil:
    """Sums over the edges (ne: a multiple of LANES) of their weights h (hh) and a = ar + i ai
    times the change of the power w^m (pr + i pi) along the edge, dw = w1^m - w0^m: out =
    (sum h Re dw, sum h Im dw, and the four real products of a and dw, s1 = sum ar Re dw,
    s2 = sum ai Im dw, s3 = sum ar Im dw, s4 = sum ai Re dw). One vectorised pass, LANES partial
    sums per sum."""
    cdef double a_hr[LANES]
    cdef double a_hi[LANES]
    cdef double a_s1[LANES]
    cdef double a_s2[LANES]
    cdef double a_s3[LANES]
    cdef double a_s4[LANES]
    cdef Py_ssize_t b, l, i
    cdef double dr, di
    for l in range(LANES):
        a_hr[l] = 0.0
        a_hi[l] = 0.0
        a_s1[l] = 0.0
        a_s2[l] = 0.0
        a_s3[l] = 0.0
        a_s4[l] = 0.0
    for b in range(ne // LANES):
        for l in range(LANES):
            i = b * LANES + l
            dr = pr[i + 1] - pr[i]
            di = pi[i + 1] - pi[i]
            a_hr[l] += hh[i] * dr
            a_hi[l] += hh[i] * di
            a_s1[l] += ar[i] * dr
            a_s2[l] += ai[i] * di
            a_s3[l] += ar[i] * di
            a_s4[l] += ai[i] * dr
    out[0] = _lanes_sum(a_hr)
    out[1] = _lanes_sum(a_hi)
    out[2] = _lanes_sum(a_s1)
    out[3] = _lanes_sum(a_s2)
    out[4] = _lanes_sum(a_s3)
    out[5] = _lanes_sum(a_s4)


cdef void _edge_recurrence(
    cdouble_r pr, cdouble_r pi, cdouble_r gnx, cdouble_r gny, cdouble_r gd, double thresh,
    double inv_p, double_r q0r, double_r q0i, double_r q1r, double_r q1i, Py_ssize_t ne,
    double* out,
) noexcept nogil:
    """One step of the r recurrence on every edge (ne: a multiple of LANES): with the vertices'
    powers w^p (pr, pi), D_p = (w1^p - w0^p) / (ip) and Q_{p+1} = 2 nu D_p - nu^2 Q_{p-1}
    (q0: Q_{p-1}, q1: Q_p, shifted on); out = sum of d Q_{p+1} over the edges not skipped
    (d > thresh). One vectorised pass, LANES partial sums."""
    cdef double a_re[LANES]
    cdef double a_im[LANES]
    cdef Py_ssize_t b, l, i
    cdef double dr, di, nx, ny, n2r, n2i, tr, ti, d
    for l in range(LANES):
        a_re[l] = 0.0
        a_im[l] = 0.0
    for b in range(ne // LANES):
        for l in range(LANES):
            i = b * LANES + l
            dr = (pi[i + 1] - pi[i]) * inv_p
            di = (pr[i] - pr[i + 1]) * inv_p
            nx = gnx[i]
            ny = gny[i]
            d = gd[i]
            n2r = nx * nx - ny * ny
            n2i = 2.0 * nx * ny
            tr = 2.0 * (nx * dr - ny * di) - (n2r * q0r[i] - n2i * q0i[i])
            ti = 2.0 * (nx * di + ny * dr) - (n2r * q0i[i] + n2i * q0r[i])
            q0r[i] = q1r[i]
            q0i[i] = q1i[i]
            q1r[i] = tr
            q1i[i] = ti
            tr = d * tr
            ti = d * ti
            a_re[l] += tr if d > thresh else 0.0
            a_im[l] += ti if d > thresh else 0.0
    out[0] = _lanes_sum(a_re)
    out[1] = _lanes_sum(a_im)


cdef void _edge_terms(
    cdouble_r gx, cdouble_r gy, cdouble_r gir, cdouble_r lr, cdouble_r gnx, cdouble_r gny,
    cdouble_r gd, double thresh, double_r hh, double_r ar, double_r ai, double_r q0r,
    double_r q0i, double_r q1r, double_r q1i, Py_ssize_t ne, double* out,
) noexcept nogil:
    """Per edge (ne: a multiple of LANES; an edge with d <= thresh adds nothing): the angle
    du it subtends, the r^-2 weights h = 1 / (2 d^2), a = nu^2 / (4 d^2) (into hh, ar, ai),
    Q_0 = K_0 and Q_1 = nu K_1 of r (into q0, q1); out = (sum du, sum |du|, sum h du,
    sum a du (re, im), sum d Q_0, sum d Q_1 (re, im)). One vectorised pass."""
    cdef double a_net[LANES]
    cdef double a_total[LANES]
    cdef double a_h[LANES]
    cdef double a_ar[LANES]
    cdef double a_ai[LANES]
    cdef double a_r0[LANES]
    cdef double a_r1r[LANES]
    cdef double a_r1i[LANES]
    cdef Py_ssize_t b, l, i
    cdef double x0, y0, x1, y1, ir0, ir1, nx, ny, d, c0, s0, c1, s1, du, h, are, aim, n2r, n2i
    cdef double a0, b0, a1, b1, k0, k1
    cdef bint ok
    for l in range(LANES):
        a_net[l] = 0.0
        a_total[l] = 0.0
        a_h[l] = 0.0
        a_ar[l] = 0.0
        a_ai[l] = 0.0
        a_r0[l] = 0.0
        a_r1r[l] = 0.0
        a_r1i[l] = 0.0
    for b in range(ne // LANES):
        for l in range(LANES):
            i = b * LANES + l
            x0 = gx[i]
            y0 = gy[i]
            ir0 = gir[i]
            x1 = gx[i + 1]
            y1 = gy[i + 1]
            ir1 = gir[i + 1]
            nx = gnx[i]
            ny = gny[i]
            d = gd[i]
            ok = d > thresh
            c0 = d * ir0  # cos and sin of u at both ends
            s0 = (y0 * nx - x0 * ny) * ir0
            c1 = d * ir1
            s1 = (y1 * nx - x1 * ny) * ir1
            du = atan2(s1 * c0 - c1 * s0, c1 * c0 + s1 * s0)  # each edge subtends less than pi
            du = du if ok else 0.0
            a_net[l] += du
            a_total[l] += fabs(du)
            n2r = nx * nx - ny * ny  # nu^2
            n2i = 2.0 * nx * ny
            h = 0.5 / (d * d)
            h = h if ok else 0.0
            are = 0.5 * h * n2r  # a = nu^2 / (4 d^2)
            aim = 0.5 * h * n2i
            are = are if ok else 0.0
            aim = aim if ok else 0.0
            hh[i] = h
            ar[i] = are
            ai[i] = aim
            a_h[l] += h * du
            a_ar[l] += are * du
            a_ai[l] += aim * du
            # K_0 = asinh(tan u1) - asinh(tan u0) = log(e1 / e0), e = (1 + sin u) / cos u, or
            # cos u / (1 - sin u) without cancellation for sin u < 0. Where d > thresh, cos u =
            # d / r > 1e-12 at both ends, so the ratio is within 1e-25..1e25: a normal number.
            a0 = 1.0 + s0 if s0 >= 0.0 else c0
            b0 = c0 if s0 >= 0.0 else 1.0 - s0
            a1 = 1.0 + s1 if s1 >= 0.0 else c1
            b1 = c1 if s1 >= 0.0 else 1.0 - s1
            k0 = log((a1 * b0) / (b1 * a0))
            k1 = lr[i + 1] - lr[i]  # log(cos u0 / cos u1)
            q0r[i] = k0  # Q_0
            q0i[i] = 0.0
            q1r[i] = nx * du - ny * k1  # Q_1 = nu K_1
            q1i[i] = nx * k1 + ny * du
            k0 = d * k0
            a_r0[l] += k0 if ok else 0.0
            k0 = d * q1r[i]
            k1 = d * q1i[i]
            a_r1r[l] += k0 if ok else 0.0
            a_r1i[l] += k1 if ok else 0.0
    out[0] = _lanes_sum(a_net)
    out[1] = _lanes_sum(a_total)
    out[2] = _lanes_sum(a_h)
    out[3] = _lanes_sum(a_ar)
    out[4] = _lanes_sum(a_ai)
    out[5] = _lanes_sum(a_r0)
    out[6] = _lanes_sum(a_r1r)
    out[7] = _lanes_sum(a_r1i)


cdef inline Py_ssize_t _series_work(Py_ssize_t n, int n_r, int n_rho) noexcept nogil:
    """Doubles of work :func:`_series` needs for up to n vertices."""
    cdef Py_ssize_t ne = _round_up(n)
    cdef int big_m = n_r - 1 if n_r - 1 > n_rho + 2 else n_rho + 2
    return 8 * (ne + LANES) + 10 * ne + 7 * _round_up(big_m + 3)


cdef int _series(
    cdouble_r q, Py_ssize_t n, bint given, double cx, double cy, int n_r, int n_rho,
    double* work, double* r, double* rho, double* out,
) noexcept nogil:
    """Coefficients of r (harmonics 0..n_r) and r^-2 (0..n_rho) about the centre into r, rho
    (interleaved re, im), centre, star-shapedness and winding into out[10:14]; the status
    (work: :func:`_series_work` doubles, 64-byte aligned).

    Per edge at distance d from the centre, foot point in direction phi (nu = e^{i phi}),
    u = theta - phi from u0 to u1: G_m = int e^{imu} du, K_n = int e^{inu} / cos u du (K_0 =
    asinh tan u, K_1 = u - i log cos u, K_n = 2 G_{n-1} - K_{n-2}); r contributes
    d e^{in phi} K_n and r^-2 e^{in phi} / d^2 (G_n / 2 + (G_{n+2} + G_{n-2}) / 4). With
    w = e^{i theta} = nu e^{iu} at the vertices, D_m = e^{im phi} G_m = (w1^m - w0^m) / (im)
    for m != 0 (D_0 = u1 - u0 = du), so the powers are per vertex, shared by its two edges.

    r^-2: an edge adds h D_n + conj(a) D_{n+2} + a D_{n-2}, h = 1 / (2 d^2), a = nu^2 / (4 d^2)
    (h = a = 0 for an edge skipped). Gathered per harmonic, with H_m = sum h (w1^m - w0^m) and
    A_m = sum a (w1^m - w0^m) over the edges, the contour's sums are sum h D_m = H_m / (im),
    sum a D_m = A_m / (im) and sum conj(a) D_m = conj(A_{-m}) / (im): per edge and harmonic
    six real multiply-adds (:func:`_edge_sums`) instead of three complex products, and only
    the D_0 terms (sum h du, sum a du) apart.

    r: an edge adds d Q_n, Q_n = e^{in phi} K_n = 2 nu D_{n-1} - nu^2 Q_{n-2}, Q_0 = K_0,
    Q_1 = nu K_1, Im K_1 = log(r1 / r0) from one log per vertex.

    Order of the work: passes over all vertices or all edges, each a vectorised loop (the
    vertices about the centre; the edges' normals; the edges' du, weights, Q_0 and Q_1 with
    atan2 and log), then one pass per harmonic m = 1, 2, ...: every vertex's
    w^m from w^{m-1} (:func:`_vertex_powers`), the edges' sums H_m and A_m and, for r, every
    edge's D_m and Q_{m+1} (:func:`_edge_recurrence`). Each sum runs in LANES partial sums.
    """
    cdef Py_ssize_t i, ne = _round_up(n), nv = ne + LANES
    cdef int k, p, big_m = n_r - 1 if n_r - 1 > n_rho + 2 else n_rho + 2
    cdef Py_ssize_t nc = _round_up(big_m + 3)
    # per vertex (vertex 0 again at n and in the padding up to nv): position about the centre,
    # 1 / r, log r, w = e^{i theta}, its powers
    cdef double_r gx = work
    cdef double_r gy = work + nv
    cdef double_r gir = work + 2 * nv
    cdef double_r lr = work + 3 * nv
    cdef double_r wx = work + 4 * nv
    cdef double_r wy = work + 5 * nv
    cdef double_r pr = work + 6 * nv
    cdef double_r pi = work + 7 * nv
    # per edge (d = 0 from n on): unit normal nu, distance d, r^-2 weights, Q_{m-1} and Q_m
    cdef double_r gnx = work + 8 * nv
    cdef double_r gny = gnx + ne
    cdef double_r gd = gnx + 2 * ne
    cdef double_r hh = gnx + 3 * ne
    cdef double_r ar = gnx + 4 * ne
    cdef double_r ai = gnx + 5 * ne
    cdef double_r q0r = gnx + 6 * ne
    cdef double_r q0i = gnx + 7 * ne
    cdef double_r q1r = gnx + 8 * ne
    cdef double_r q1i = gnx + 9 * ne
    # per harmonic: 1 / m and the edge sums of r^-2 (H_m, A_m), index m = 1..n_rho + 2
    cdef double* inv_m = gnx + 10 * ne
    cdef double* hr = inv_m + nc
    cdef double* hi = inv_m + 2 * nc
    cdef double* s1 = inv_m + 3 * nc
    cdef double* s2 = inv_m + 4 * nc
    cdef double* s3 = inv_m + 5 * nc
    cdef double* s4 = inv_m + 6 * nc
    cdef double ac[3]
    cdef double sums[8]
    cdef int64_t bits, top = 0
    cdef double x0, y0, r2, ir, ex, ey, inv_len, nx, ny, d, scale2 = 0.0, thresh
    cdef double net, total, h_du, ar_du, ai_du, winding, norm, tr, ti
    for k in range(7 * nc):
        inv_m[k] = 0.0
    for k in range(1, big_m + 1):
        inv_m[k] = 1.0 / k
    if not given:
        _area_centroid(q, n, ac)
        if ac[0] == 0.0:
            return S_SERIES_NO_AREA
        cx = ac[1]
        cy = ac[2]
    elif not (isfinite(cx) and isfinite(cy)):
        return S_SERIES_BAD_CENTRE
    out[10] = cx
    out[11] = cy

    # vertices about the centre, 1 / r and w (0 at the centre itself: its edges are skipped)
    for i in range(n):
        x0 = q[2 * i] - cx
        y0 = q[2 * i + 1] - cy
        r2 = x0 * x0 + y0 * y0
        ir = 1.0 / sqrt(r2)
        gx[i] = x0
        gy[i] = y0
        gir[i] = ir
        ex = x0 * ir
        ey = y0 * ir
        wx[i] = ex if r2 > 0.0 else 0.0
        wy[i] = ey if r2 > 0.0 else 0.0
    for i in range(n, nv):
        gx[i] = gx[0]
        gy[i] = gy[0]
        gir[i] = gir[0]
        wx[i] = wx[0]
        wy[i] = wy[0]
    # the largest r^2 as the largest bit pattern (r^2 >= +0: its bits as an int64 order like
    # the numbers), an integer max that vectorises where a floating-point one does not
    for i in range(n):
        r2 = gx[i] * gx[i] + gy[i] * gy[i]
        memcpy(&bits, &r2, 8)
        top = bits if bits > top else top
    memcpy(&scale2, &top, 8)
    thresh = 1e-12 * sqrt(scale2)  # edges on a line through the centre add nothing
    if n_r >= 0:
        # log r = -log(1 / r): 1 / r is a normal number (r^2 a finite double); an infinite
        # 1 / r (a vertex on the centre) gives a wrong log, read only by skipped edges
        for i in range(nv):
            lr[i] = -log(gir[i])
    else:
        for i in range(nv):
            lr[i] = 0.0
    # the edges' unit normals towards the edge (nu) and distances
    for i in range(n):
        ex = gx[i + 1] - gx[i]
        ey = gy[i + 1] - gy[i]
        inv_len = 1.0 / sqrt(ex * ex + ey * ey)
        nx = ey * inv_len
        ny = -ex * inv_len
        d = gx[i] * nx + gy[i] * ny
        gnx[i] = -nx if d < 0.0 else nx  # nu = (nx, ny) points from the centre to the edge
        gny[i] = -ny if d < 0.0 else ny
        gd[i] = -d if d < 0.0 else d
    for i in range(n, ne):
        gnx[i] = 0.0
        gny[i] = 0.0
        gd[i] = 0.0

    _edge_terms(gx, gy, gir, lr, gnx, gny, gd, thresh, hh, ar, ai, q0r, q0i, q1r, q1i, ne, sums)
    net = sums[0]
    total = sums[1]
    h_du = sums[2]
    ar_du = sums[3]
    ai_du = sums[4]
    if n_r >= 0:
        r[0] = sums[5]
        r[1] = 0.0
    if n_r >= 1:
        r[2] = sums[6]
        r[3] = sums[7]
    for i in range(nv):
        pr[i] = 1.0
        pi[i] = 0.0
    for p in range(1, big_m + 1):  # w^p at every vertex; H_p and A_p; Q_{p+1} of r
        _vertex_powers(wx, wy, pr, pi, nv)
        if n_rho >= 0 and p <= n_rho + 2:
            _edge_sums(pr, pi, hh, ar, ai, ne, sums)
            hr[p] = sums[0]
            hi[p] = sums[1]
            s1[p] = sums[2]
            s2[p] = sums[3]
            s3[p] = sums[4]
            s4[p] = sums[5]
        if p <= n_r - 1:
            _edge_recurrence(pr, pi, gnx, gny, gd, thresh, inv_m[p], q0r, q0i, q1r, q1i, ne,
                             r + 2 * (p + 1))

    winding = nearbyint(net / (2.0 * PI))
    out[12] = fabs(net) / total if total > 0.0 else 0.0
    out[13] = winding
    if winding == 0.0:
        for k in range(2 * (n_r + 1)):
            r[k] = NAN
        for k in range(2 * (n_rho + 1)):
            rho[k] = NAN
        return S_SERIES_NO_WINDING
    norm = 1.0 / (PI * winding)
    for k in range(2 * (n_r + 1)):
        r[k] *= norm
    for k in range(n_rho + 1):
        # sum h D_k: H_k / (ik)
        if k == 0:
            tr = h_du
            ti = 0.0
        else:
            tr = hi[k] * inv_m[k]
            ti = -hr[k] * inv_m[k]
        # sum conj(a) D_{k+2}: conj(A_{-p}) / (ip), p = k + 2
        p = k + 2
        tr += (s3[p] - s4[p]) * inv_m[p]
        ti -= (s1[p] + s2[p]) * inv_m[p]
        # sum a D_{k-2}: A_p / (ip) for p = k - 2 > 0, A_{-p} / (-ip) for p = 2 - k > 0
        if k == 2:
            tr += ar_du
            ti += ai_du
        elif k > 2:
            p = k - 2
            tr += (s3[p] + s4[p]) * inv_m[p]
            ti -= (s1[p] - s2[p]) * inv_m[p]
        else:
            p = 2 - k
            tr += (s3[p] - s4[p]) * inv_m[p]
            ti += (s1[p] + s2[p]) * inv_m[p]
        rho[2 * k] = tr * norm
        rho[2 * k + 1] = ti * norm
    if n_r >= 0:
        r[1] = 0.0
    if n_rho >= 0:
        rho[1] = 0.0
    return S_SERIES_OK


# ------------------------------------------------------------------------------ batch


cdef void _contour(
    const double* src, Py_ssize_t n_raw, int min_points, double* buf, Py_ssize_t* runs,
    Py_ssize_t max_n, bint want_series, bint given, double cx, double cy, double max_elongation,
    int n_r, int n_rho, double* r, double* rho, double* out, signed char* status,
    signed char* series_status,
) noexcept nogil:
    """Everything about one contour (buf: 64-byte aligned, :func:`_buffer_size` doubles: the
    points without repeats, then the work of the descriptors or of the series)."""
    cdef Py_ssize_t i, n, part = _round_up(2 * max_n + 2)
    cdef int nh = n_r if n_r > n_rho else n_rho
    cdef double* q = buf
    cdef double* work = buf + part
    for i in range(NV):
        out[i] = NAN
    for i in range(2 * (n_r + 1)):
        r[i] = NAN
    for i in range(2 * (n_rho + 1)):
        rho[i] = NAN
    series_status[0] = S_SERIES_SKIPPED
    if n_raw < min_points:
        status[0] = S_TOO_FEW_POINTS
        return
    if not _all_finite(src, 2 * n_raw):
        status[0] = S_NON_FINITE
        return
    n = _dedup(src, n_raw, True, q)
    if n > 0:  # vertex 0 again after the last: the closing edge without a wrap
        q[2 * n] = q[0]
        q[2 * n + 1] = q[1]
    if n < 2:
        status[0] = S_ONE_POINT
    else:
        status[0] = _descriptors(
            q, n, work, work + part, runs, work + 2 * part, work + 3 * part, out
        )
        if status[0] != S_OK:
            for i in range(NV):
                out[i] = NAN
    if want_series and nh >= 0 and not (isfinite(max_elongation) and out[8] >= max_elongation):
        series_status[0] = _series(q, n, given, cx, cy, n_r, n_rho, work, r, rho, out)


cdef Py_ssize_t _buffer_size(Py_ssize_t max_n, int n_r, int n_rho) noexcept nogil:
    """Doubles of work :func:`_contour` needs for contours of up to max_n points: the points
    (with vertex 0 again after the last), then the work of the descriptors (two sorted copies,
    the hull, its work: three parts like the points' and 5 max_n + 8) or the series'."""
    cdef Py_ssize_t part = _round_up(2 * max_n + 2)
    cdef Py_ssize_t series = _series_work(max_n, n_r, n_rho), descriptors = 3 * part + 5 * max_n + 8
    return part + (series if series > descriptors else descriptors)


def measure_contours(
    const double[:, ::1] points,
    const int64_t[::1] offsets,
    int min_points,
    const unsigned char[::1] want_series,
    const double[:, ::1] centres,
    bint given_centres,
    double max_elongation,
    int n_r,
    int n_rho,
    int num_threads=1,
):
    """Descriptors (and polar series) of K concatenated contours in one call.

    Parameters
    ----------
    points : float64 (N, 2), C-contiguous
    offsets : int64 (K + 1,), rising from 0 to N
    min_points : contours with fewer (raw) points get status TOO_FEW_POINTS
    want_series : uint8 (K,), nonzero where the polar series is wanted
    centres : float64 (K, 2) centres of the series when ``given_centres`` (else any (K, 2))
    max_elongation : no series where the elongation is at least this (a line); inf: none
    n_r, n_rho : highest harmonic of r and r^-2 (-1: none)
    num_threads : threads sharing the contours from 16 contours on (fewer: one thread)

    Returns
    -------
    status : int8 (K,) descriptor status (OK, TOO_FEW_POINTS, NON_FINITE, ONE_POINT,
        NEGATIVE_MOMENTS); the descriptor values are NaN unless OK
    series_status : int8 (K,) SERIES_* codes; the coefficients are NaN unless SERIES_OK
    values : float64 (K, NV), columns VALUE_NAMES
    r, rho : complex128 (K, n_r + 1), (K, n_rho + 1)
    """
    cdef Py_ssize_t k_total = offsets.shape[0] - 1, k, max_n = 1, n_buf, nt
    if k_total < 0 or points.shape[1] != 2 or want_series.shape[0] != k_total \
            or centres.shape[0] != k_total or centres.shape[1] != 2 \
            or offsets[0] != 0 or offsets[k_total] != points.shape[0]:
        raise ValueError("measure_contours needs (N, 2) points, offsets from 0 to N and K rows")
    for k in range(k_total):
        if offsets[k + 1] < offsets[k]:
            raise ValueError("measure_contours: offsets must not decrease")
        if offsets[k + 1] - offsets[k] > max_n:
            max_n = offsets[k + 1] - offsets[k]
    n_r = max(n_r, -1)
    n_rho = max(n_rho, -1)
    status_arr = np.empty(k_total, np.int8)
    series_arr = np.empty(k_total, np.int8)
    values_arr = np.empty((k_total, NV), np.float64)
    r_arr = np.empty((k_total, n_r + 1), np.complex128)
    rho_arr = np.empty((k_total, n_rho + 1), np.complex128)
    cdef signed char[::1] status = status_arr
    cdef signed char[::1] series = series_arr
    cdef double[:, ::1] values = values_arr
    cdef double[:, ::1] r = r_arr.view(np.float64).reshape(k_total, 2 * (n_r + 1))
    cdef double[:, ::1] rho = rho_arr.view(np.float64).reshape(k_total, 2 * (n_rho + 1))
    cdef double* rp = &r[0, 0] if r.shape[0] > 0 and r.shape[1] > 0 else NULL
    cdef double* rhop = &rho[0, 0] if rho.shape[0] > 0 and rho.shape[1] > 0 else NULL
    cdef Py_ssize_t r_stride = r.shape[1], rho_stride = rho.shape[1]
    cdef double* mem
    cdef double* buf
    cdef Py_ssize_t* runs
    if k_total == 0:
        return status_arr, series_arr, values_arr, r_arr, rho_arr
    n_buf = _buffer_size(max_n, n_r, n_rho) + LANES  # + LANES: room to align to 64 bytes
    nt = max(num_threads, 1) if k_total >= 16 else 1
    with nogil, parallel(num_threads=nt):
        mem = <double*> malloc(n_buf * sizeof(double))
        buf = <double*> ((<uintptr_t> mem + 63) & ~(<uintptr_t> 63))
        runs = <Py_ssize_t*> malloc((max_n + 2) * sizeof(Py_ssize_t))
        for k in prange(k_total, schedule="dynamic", chunksize=4):
            if mem == NULL or runs == NULL:
                status[k] = -1
            else:
                _contour(
                    &points[0, 0] + 2 * offsets[k], offsets[k + 1] - offsets[k], min_points,
                    buf, runs, max_n, want_series[k] != 0, given_centres, centres[k, 0],
                    centres[k, 1], max_elongation, n_r, n_rho,
                    rp + k * r_stride if rp != NULL else NULL,
                    rhop + k * rho_stride if rhop != NULL else NULL,
                    &values[k, 0], &status[k], &series[k],
                )
        free(mem)
        free(runs)
    if (status_arr < 0).any():
        raise MemoryError("measure_contours: no memory for the per-thread buffers")
    return status_arr, series_arr, values_arr, r_arr, rho_arr


# ------------------------------------------------------------------------------ single pieces


def drop_repeated(const double[:, ::1] points, const int64_t[::1] offsets, bint closed):
    """Points unequal to their predecessor (if closed, also not a last one equal to the first)
    of K concatenated contours; returns (points (M, 2), offsets (K + 1,))."""
    cdef Py_ssize_t k_total = offsets.shape[0] - 1, k, n
    if k_total < 0 or points.shape[1] != 2 or offsets[0] != 0 \
            or offsets[k_total] != points.shape[0]:
        raise ValueError("drop_repeated needs (N, 2) points and offsets from 0 to N")
    out_arr = np.empty((points.shape[0], 2), np.float64)
    off_arr = np.empty(k_total + 1, np.int64)
    cdef double[:, ::1] out = out_arr
    cdef int64_t[::1] off = off_arr
    off[0] = 0
    with nogil:
        for k in range(k_total):
            n = offsets[k + 1] - offsets[k]
            if n > 0:
                n = _dedup(&points[0, 0] + 2 * offsets[k], n, closed, &out[0, 0] + 2 * off[k])
            off[k + 1] = off[k] + n
    return out_arr[: off[k_total]], off_arr


def area_centroids(const double[:, ::1] points, const int64_t[::1] offsets):
    """Absolute area and area centroid (the vertex mean without area) of K polygons, each with
    at least one vertex; returns (area (K,), centroid (K, 2))."""
    cdef Py_ssize_t k_total = offsets.shape[0] - 1, k, n, i, max_n = 0
    cdef double ac[3]
    if k_total < 0 or points.shape[1] != 2 or offsets[0] != 0 \
            or offsets[k_total] != points.shape[0]:
        raise ValueError("area_centroids needs (N, 2) points and offsets from 0 to N")
    area_arr = np.empty(k_total, np.float64)
    centroid_arr = np.empty((k_total, 2), np.float64)
    cdef double[::1] area = area_arr
    cdef double[:, ::1] centroid = centroid_arr
    for k in range(k_total):
        if offsets[k + 1] <= offsets[k]:
            raise ValueError("area_centroids: every polygon needs a vertex")
        max_n = max(max_n, offsets[k + 1] - offsets[k])
    # one polygon at a time, vertex 0 again after the last
    cdef double[::1] closed = np.empty(2 * max_n + 2, np.float64)
    with nogil:
        for k in range(k_total):
            n = offsets[k + 1] - offsets[k]
            for i in range(2 * n):
                closed[i] = points[offsets[k] + i // 2, i % 2]
            closed[2 * n] = closed[0]
            closed[2 * n + 1] = closed[1]
            _area_centroid(&closed[0], n, ac)
            area[k] = fabs(ac[0])
            centroid[k, 0] = ac[1]
            centroid[k, 1] = ac[2]
    return area_arr, centroid_arr


def convex_hull(const double[:, ::1] points):
    """Convex hull vertices (counter-clockwise in (x, y) axes) of n >= 1 points, (m, 2)."""
    cdef Py_ssize_t n = points.shape[0], i, m
    if n < 1 or points.shape[1] != 2:
        raise ValueError("convex_hull needs (n, 2) points, n >= 1")
    work = np.empty(10 * n + 6, np.float64)
    runs_arr = np.empty(n + 2, np.intp)
    cdef double[::1] w = work
    cdef Py_ssize_t[::1] runs = runs_arr
    cdef double* s
    with nogil:
        for i in range(2 * n):
            w[i] = (&points[0, 0])[i]
        s = _sort_points(&w[0], &w[2 * n], n, &runs[0])
        m = _hull(s, n, &w[4 * n], &w[6 * n + 2])
    return work[4 * n : 4 * n + 2 * m].reshape(m, 2).copy()


def min_area_box(const double[:, ::1] points):
    """(long, short) sides of the minimum-area rectangle around n >= 1 points."""
    cdef Py_ssize_t n = points.shape[0], m
    cdef double side[2]
    hull = convex_hull(points)
    cdef const double[:, ::1] h = hull
    m = h.shape[0]
    u = np.empty(5 * m + 8, np.float64)
    cdef double[::1] uv = u
    _min_area_box(&h[0, 0], m, &uv[0], side)
    return side[0], side[1]
