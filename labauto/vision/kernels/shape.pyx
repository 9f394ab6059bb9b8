# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
# distutils: extra_compile_args = -fno-math-errno
"""Shape kernel: Table 1 descriptors and the exact polar series (eq. 4) of many contours.

See :mod:`labauto.vision.descriptors` and :mod:`labauto.vision.harmonics` for the definitions
and the choices made; this is their inner loop. :func:`measure_contours` takes K contours
concatenated (``points[offsets[k]:offsets[k + 1]]``) and, per contour (contours shared among
threads), drops repeated points, then computes

* the area and area centroid of the polygon (about the vertex mean), the curve centroid when
  there is no area, the semi-axes from the second moments, the perimeter;
* the convex hull (monotone chain after a natural merge sort: an ordered contour is made of a
  few x-monotone runs) and the minimum-area box around it (rotating calipers);
* optionally the Fourier coefficients of ``r`` and ``r^-2`` about the centre, exact per edge
  (``r^-2`` summed by parts over the vertices, see :func:`_series`).

Compiled with ``-fno-math-errno`` (second line) so that loops with ``sqrt`` vectorise.

Everything is float64 and per contour in a fixed order, so a contour's results do not depend on
the other contours of the batch.
"""

from cython.parallel cimport parallel, prange
from libc.math cimport INFINITY, NAN, atan2, fabs, isfinite, log, nearbyint, sqrt
from libc.stdint cimport int64_t
from libc.stdlib cimport free, malloc

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


cdef void _area_centroid(const double* p, Py_ssize_t n, double* out) noexcept nogil:
    """out = (signed area, centroid x, centroid y) about the vertex mean; the mean when no area."""
    cdef Py_ssize_t i, j
    cdef double mx = 0.0, my = 0.0, px, py, qx, qy, c, s = 0.0, sx = 0.0, sy = 0.0
    for i in range(n):
        mx += p[2 * i]
        my += p[2 * i + 1]
    mx /= n
    my /= n
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        px = p[2 * i] - mx
        py = p[2 * i + 1] - my
        qx = p[2 * j] - mx
        qy = p[2 * j + 1] - my
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


cdef inline bint _less(const double* a, const double* b) noexcept nogil:
    return a[0] < b[0] or (a[0] == b[0] and a[1] < b[1])


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


cdef inline Py_ssize_t _walk(
    const double* h, Py_ssize_t m, Py_ssize_t j, const double* o, double ux, double uy,
) noexcept nogil:
    """From vertex j, the first vertex along the hull whose successor is lower in direction
    (ux, uy) (heights about o; at most m steps).

    Between two hull edges an extreme vertex moves 0 or 1 steps, seldom more, and the two are
    about equally likely: the first two steps are taken without branches (selects on locals),
    so the one branch left (a third step) is predictable."""
    cdef Py_ssize_t jn, steps = 2
    cdef double cur = _dot(h + 2 * j, o, ux, uy), nxt
    cdef bint take
    jn = j + 1 if j + 1 < m else 0
    nxt = _dot(h + 2 * jn, o, ux, uy)
    take = not (nxt < cur)
    j = jn if take else j
    cur = nxt if take else cur
    jn = j + 1 if j + 1 < m else 0
    nxt = _dot(h + 2 * jn, o, ux, uy)
    take = take & (not (nxt < cur))
    j = jn if take else j
    cur = nxt if take else cur
    while take and steps < m:
        jn = j + 1 if j + 1 < m else 0
        nxt = _dot(h + 2 * jn, o, ux, uy)
        take = not (nxt < cur)
        j = jn if take else j
        cur = nxt if take else cur
        steps += 1
    return j


cdef void _min_area_box(const double* h, Py_ssize_t m, double* u, double* side) noexcept nogil:
    """Long and short side of the minimum-area rectangle around the convex polygon h (m vertices,
    counter-clockwise): rotating calipers, one side of the box on each hull edge in turn; of
    boxes with the same area (to 1e-12) the least elongated.

    Two passes: the unit directions of all edges into u (2 m doubles; one loop, square roots
    and divisions vectorised), then the calipers (:func:`_walk`)."""
    cdef Py_ssize_t i, j, far = 0, hi = 0, lo = 0
    cdef double ux, uy, length, width, extent, area, best = INFINITY, long_side, short_side
    side[0] = 0.0
    side[1] = 0.0
    if m == 2:
        ux = h[2] - h[0]
        uy = h[3] - h[1]
        side[0] = sqrt(ux * ux + uy * uy)
    if m < 3:
        return
    for i in range(2 * m - 2):  # u[2 i], u[2 i + 1]: edge i -> i + 1, the last one below
        u[i] = h[i + 2] - h[i]
    u[2 * m - 2] = h[0] - h[2 * m - 2]
    u[2 * m - 1] = h[1] - h[2 * m - 1]
    for i in range(m):
        ux = u[2 * i]
        uy = u[2 * i + 1]
        length = sqrt(ux * ux + uy * uy)
        u[2 * i] = ux / length
        u[2 * i + 1] = uy / length
    for i in range(m):
        ux = u[2 * i]
        uy = u[2 * i + 1]
        if i == 0:  # the extreme vertices of the first edge by a full scan
            for j in range(1, m):
                if _dot(h + 2 * j, h, -uy, ux) > _dot(h + 2 * far, h, -uy, ux):
                    far = j
                if _dot(h + 2 * j, h, ux, uy) > _dot(h + 2 * hi, h, ux, uy):
                    hi = j
                if _dot(h + 2 * j, h, ux, uy) < _dot(h + 2 * lo, h, ux, uy):
                    lo = j
        else:  # as the edge turns counter-clockwise, so do its extreme vertices
            far = _walk(h, m, far, h + 2 * i, -uy, ux)
            hi = _walk(h, m, hi, h + 2 * i, ux, uy)
            lo = _walk(h, m, lo, h + 2 * i, -ux, -uy)  # lowest: highest in direction -u
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


# ------------------------------------------------------------------------------ descriptors


cdef int _descriptors(
    const double* q, Py_ssize_t n, double* sorted_a, double* sorted_b, Py_ssize_t* runs,
    double* hull, double* work, double* out,
) noexcept nogil:
    """Descriptors of the polygon q (n >= 2 points, no repeats) into out[0:10]; the status
    (work: 4 n + 4 doubles)."""
    cdef Py_ssize_t i, j, m
    cdef double ac[3]
    cdef double side[2]
    cdef double ex, ey, seg, total = 0.0, area, cx, cy, mx = 0.0, my = 0.0
    cdef double px, py, qx, qy, c, w, area2 = 0.0, sxx = 0.0, syy = 0.0, sxy = 0.0, scale
    cdef double half_trace, root, major2, box_area, long_side, short_side
    cdef bint has_area
    cdef double* s
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        ex = q[2 * j] - q[2 * i]
        ey = q[2 * j + 1] - q[2 * i + 1]
        seg = sqrt(ex * ex + ey * ey)
        total += seg
        mx += (q[2 * i] + q[2 * j]) * seg  # for the curve centroid
        my += (q[2 * i + 1] + q[2 * j + 1]) * seg
    out[5] = total
    out[6] = seg  # the closing segment, last point to first
    _area_centroid(q, n, ac)
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
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        px = q[2 * i] - cx
        py = q[2 * i + 1] - cy
        qx = q[2 * j] - cx
        qy = q[2 * j + 1] - cy
        if has_area:
            w = px * qy - qx * py
            area2 += w
        else:
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
    for i in range(2 * n):
        sorted_a[i] = q[i]
    s = _sort_points(sorted_a, sorted_b, n, runs)
    m = _hull(s, n, hull, work)
    total = 0.0
    for i in range(m):
        j = i + 1 if i + 1 < m else 0
        ex = hull[2 * j] - hull[2 * i]
        ey = hull[2 * j + 1] - hull[2 * i + 1]
        total += sqrt(ex * ex + ey * ey)
    out[7] = total
    _min_area_box(hull, m, sorted_a, side)  # the sorted points are done with
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


cdef inline void _powers(double ux, double uy, int m, double* pr, double* pi) noexcept nogil:
    """pr + i pi = (ux + i uy)^k for k = 0..m (four interleaved chains: short latency)."""
    cdef int k
    pr[0] = 1.0
    pi[0] = 0.0
    pr[1] = ux
    pi[1] = uy
    pr[2] = ux * ux - uy * uy
    pi[2] = 2.0 * ux * uy
    pr[3] = pr[2] * ux - pi[2] * uy
    pi[3] = pr[2] * uy + pi[2] * ux
    cdef double u4r = pr[2] * pr[2] - pi[2] * pi[2], u4i = 2.0 * pr[2] * pi[2]
    for k in range(4, m + 1):
        pr[k] = pr[k - 4] * u4r - pi[k - 4] * u4i
        pi[k] = pr[k - 4] * u4i + pi[k - 4] * u4r


cdef inline void _differences(
    cdouble_r p0r, cdouble_r p0i, cdouble_r p1r, cdouble_r p1i, cdouble_r inv_m, int m,
    double_r dr, double_r di,
) noexcept nogil:
    """dr + i di = D_k = (w1^k - w0^k) / (ik) for k = 1..m (one vectorised loop)."""
    cdef int k
    for k in range(1, m + 1):
        dr[k] = (p1i[k] - p0i[k]) * inv_m[k]
        di[k] = (p0r[k] - p1r[k]) * inv_m[k]


cdef inline void _add_vertex(
    cdouble_r pr, cdouble_r pi, int m, double h, double gr, double gi, double_r hr, double_r hi,
    double_r s1, double_r s2, double_r s3, double_r s4,
) noexcept nogil:
    """Add a vertex's powers w^p = pr + i pi (p = 1..m) with the real weight h and the complex
    weight g = gr + i gi: H_p += h w^p and the four real products of g and w^p, from which
    sum g w^p = (s1 - s2) + i (s3 + s4) and sum g conj(w^p) = (s1 + s2) + i (s4 - s3)
    (one vectorised loop)."""
    cdef int p
    for p in range(1, m + 1):
        hr[p] += h * pr[p]
        hi[p] += h * pi[p]
        s1[p] += gr * pr[p]
        s2[p] += gi * pi[p]
        s3[p] += gr * pi[p]
        s4[p] += gi * pr[p]


cdef int _series(
    const double* q, Py_ssize_t n, bint given, double cx, double cy, int n_r, int n_rho,
    double* work, double* geo, double* r, double* rho, double* out,
) noexcept nogil:
    """Coefficients of r (harmonics 0..n_r) and r^-2 (0..n_rho) about the centre into r, rho
    (interleaved re, im), centre, star-shapedness and winding into out[10:14]; the status.

    Per edge at distance d from the centre, foot point in direction phi (nu = e^{i phi}),
    u = theta - phi from u0 to u1: G_m = int e^{imu} du, K_n = int e^{inu} / cos u du (K_0 =
    asinh tan u, K_1 = u - i log cos u, K_n = 2 G_{n-1} - K_{n-2}); r contributes
    d e^{in phi} K_n and r^-2 e^{in phi} / d^2 (G_n / 2 + (G_{n+2} + G_{n-2}) / 4). With
    w = e^{i theta} = nu e^{iu} at the vertices, D_m = e^{im phi} G_m = (w1^m - w0^m) / (im)
    for m != 0 (D_0 = u1 - u0 = du), so the powers are per vertex, shared by its two edges.

    r^-2: an edge adds h D_n + conj(a) D_{n+2} + a D_{n-2}, h = 1 / (2 d^2), a = nu^2 / (4 d^2).
    Summed by parts, sum over edges c (w1^m - w0^m) = sum over vertices (c_in - c_out) w^m
    (c_in, c_out: of the edges ending and starting at the vertex; 0 for an edge skipped), so
    with H_m = sum (h_in - h_out) w^m and A_m = sum (a_in - a_out) w^m the contour's sums are
    sum h D_m = H_m / (im), sum a D_m = A_m / (im) and sum conj(a) D_m = conj(A_{-m}) / (im),
    and only the D_0 terms (sum h du, sum a du) are per edge: one pass over a vertex's powers
    (:func:`_add_vertex`) instead of D_m and three complex products per edge and harmonic.

    r: an edge adds d Q_n, Q_n = e^{in phi} K_n = 2 nu D_{n-1} - nu^2 Q_{n-2} (n_r is small: per
    edge, with D_1..D_{n_r - 1}), Q_0 = K_0, Q_1 = nu K_1, Im K_1 = log(r1 / r0) from one log
    per vertex.
    """
    cdef Py_ssize_t i, j
    cdef int k, p, big_m = n_r - 1 if n_r - 1 > n_rho + 2 else n_rho + 2
    cdef Py_ssize_t w = big_m + 3  # >= 4: _powers writes 0..3 at least
    cdef double* p0r = work  # powers of w at the edge's first vertex
    cdef double* p0i = work + w
    cdef double* p1r = work + 2 * w  # and at its second
    cdef double* p1i = work + 3 * w
    cdef double* dr = work + 4 * w  # D_m at index m + 2, m = 0..n_r - 1 (for r)
    cdef double* di = work + 5 * w
    cdef double* inv_m = work + 6 * w
    cdef double* hr = work + 7 * w  # vertex sums of r^-2 (_add_vertex), index p = 1..n_rho + 2
    cdef double* hi = work + 8 * w
    cdef double* s1 = work + 9 * w
    cdef double* s2 = work + 10 * w
    cdef double* s3 = work + 11 * w
    cdef double* s4 = work + 12 * w
    cdef double_r gx = geo  # per vertex: position about the centre (vertex 0 again at n), 1 / r
    cdef double_r gy = geo + n + 1
    cdef double_r gir = geo + 2 * n + 2
    cdef double_r gnx = geo + 3 * n + 2  # per edge: unit normal nu, distance d
    cdef double_r gny = geo + 4 * n + 2
    cdef double_r gd = geo + 5 * n + 2
    cdef double* swap
    cdef double ac[3]
    cdef double x0, y0, x1, y1, ir0, ir1, lr0 = 0.0, lr1 = 0.0, ux0, uy0, ex, ey, inv_len
    cdef double nx, ny, d, scale2 = 0.0, thresh, c0, s0, c1, s1_, du, net = 0.0, total = 0.0
    cdef double a0, b0, a1, b1, k0, k1, qpr, qpi, qcr, qci, tr, ti, n2r, n2i, hh, ar, ai
    cdef double h_du = 0.0, ar_du = 0.0, ai_du = 0.0, h_prev = 0.0, ar_prev = 0.0, ai_prev = 0.0
    cdef double h_first = 0.0, ar_first = 0.0, ai_first = 0.0, winding, norm
    for k in range(2 * (n_r + 1)):
        r[k] = 0.0
    for k in range(6 * w):
        hr[k] = 0.0
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
    # vertices about the centre and 1 / r, then the edges' unit normals towards the edge and
    # distances: two branch-free loops (square roots and divisions vectorised) before the
    # edge loop with its atan2 and logs
    for i in range(n):
        x0 = q[2 * i] - cx
        y0 = q[2 * i + 1] - cy
        gx[i] = x0
        gy[i] = y0
        gir[i] = 1.0 / sqrt(x0 * x0 + y0 * y0)
    for i in range(n):  # (a max does not vectorise)
        d = gx[i] * gx[i] + gy[i] * gy[i]
        scale2 = d if d > scale2 else scale2
    thresh = 1e-12 * sqrt(scale2)  # edges on a line through the centre add nothing
    gx[n] = gx[0]
    gy[n] = gy[0]
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

    x0 = gx[0]
    y0 = gy[0]
    ir0 = gir[0]
    if n_r >= 0:
        lr0 = -log(ir0)
    ux0 = x0 * ir0
    uy0 = y0 * ir0
    _powers(ux0, uy0, big_m, p0r, p0i)
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        x1 = gx[j]
        y1 = gy[j]
        ir1 = gir[j]
        if n_r >= 0:
            lr1 = -log(ir1)
        _powers(x1 * ir1, y1 * ir1, big_m, p1r, p1i)
        nx = gnx[i]
        ny = gny[i]
        d = gd[i]
        hh = 0.0
        ar = 0.0
        ai = 0.0
        if d > thresh:
            c0 = d * ir0  # cos and sin of u at both ends
            s0 = (y0 * nx - x0 * ny) * ir0
            c1 = d * ir1
            s1_ = (y1 * nx - x1 * ny) * ir1
            du = atan2(s1_ * c0 - c1 * s0, c1 * c0 + s1_ * s0)  # each edge subtends less than pi
            net += du
            total += fabs(du)
            n2r = nx * nx - ny * ny  # nu^2
            n2i = 2.0 * nx * ny
            hh = 0.5 / (d * d)
            ar = 0.5 * hh * n2r  # nu^2 / (4 d^2)
            ai = 0.5 * hh * n2i
            h_du += hh * du
            ar_du += ar * du
            ai_du += ai * du
            if n_r >= 0:
                # K_0 = asinh(tan u1) - asinh(tan u0) = log(e1 / e0), e = (1 + sin u) / cos u,
                # or cos u / (1 - sin u) without cancellation for sin u < 0
                a0 = 1.0 + s0 if s0 >= 0.0 else c0
                b0 = c0 if s0 >= 0.0 else 1.0 - s0
                a1 = 1.0 + s1_ if s1_ >= 0.0 else c1
                b1 = c1 if s1_ >= 0.0 else 1.0 - s1_
                k0 = log((a1 * b0) / (b1 * a0))
                k1 = lr1 - lr0  # log(cos u0 / cos u1)
                _differences(p0r, p0i, p1r, p1i, inv_m, n_r - 1, dr + 2, di + 2)
                qpr = k0  # Q_0
                qpi = 0.0
                qcr = nx * du - ny * k1  # Q_1 = nu K_1
                qci = nx * k1 + ny * du
                for k in range(n_r + 1):
                    if k >= 2:
                        tr = 2.0 * (nx * dr[k + 1] - ny * di[k + 1]) - (n2r * qpr - n2i * qpi)
                        ti = 2.0 * (nx * di[k + 1] + ny * dr[k + 1]) - (n2r * qpi + n2i * qpr)
                        qpr = qcr
                        qpi = qci
                        qcr = tr
                        qci = ti
                    r[2 * k] += d * (qpr if k == 0 else qcr)
                    r[2 * k + 1] += d * (qpi if k == 0 else qci)
        if i == 0:  # vertex 0 last, when its incoming edge is known
            h_first = hh
            ar_first = ar
            ai_first = ai
        elif n_rho >= 0 and (h_prev != hh or ar_prev != ar or ai_prev != ai):
            # vertex i: in edge i - 1, out edge i (both skipped: nothing, the vertex may be the
            # centre itself)
            _add_vertex(
                p0r, p0i, n_rho + 2, h_prev - hh, ar_prev - ar, ai_prev - ai, hr, hi, s1, s2,
                s3, s4,
            )
        h_prev = hh
        ar_prev = ar
        ai_prev = ai
        swap = p0r
        p0r = p1r
        p1r = swap
        swap = p0i
        p0i = p1i
        p1i = swap
        x0 = x1
        y0 = y1
        ir0 = ir1
        lr0 = lr1
    if n_rho >= 0 and (h_prev != h_first or ar_prev != ar_first or ai_prev != ai_first):
        _powers(ux0, uy0, big_m, p0r, p0i)
        _add_vertex(
            p0r, p0i, n_rho + 2, h_prev - h_first, ar_prev - ar_first, ai_prev - ai_first, hr,
            hi, s1, s2, s3, s4,
        )

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
    """Everything about one contour (buf: 8 max_n + 2 doubles, then the work of the hull,
    4 max_n + 4, and of the series, 13 (big_m + 3), sharing their place)."""
    cdef Py_ssize_t i, n
    cdef int nh = n_r if n_r > n_rho else n_rho
    cdef double* q = buf
    cdef double* work = buf + 8 * max_n + 2
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
    for i in range(2 * n_raw):
        if not isfinite(src[i]):
            status[0] = S_NON_FINITE
            return
    n = _dedup(src, n_raw, True, q)
    if n < 2:
        status[0] = S_ONE_POINT
    else:
        status[0] = _descriptors(
            q, n, buf + 2 * max_n, buf + 4 * max_n, runs, buf + 6 * max_n, work, out
        )
        if status[0] != S_OK:
            for i in range(NV):
                out[i] = NAN
    if want_series and nh >= 0 and not (isfinite(max_elongation) and out[8] >= max_elongation):
        series_status[0] = _series(
            q, n, given, cx, cy, n_r, n_rho, work, buf + 2 * max_n, r, rho, out
        )


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
    cdef int big_m = n_r - 1 if n_r - 1 > n_rho + 2 else n_rho + 2
    cdef double* buf
    cdef Py_ssize_t* runs
    if k_total == 0:
        return status_arr, series_arr, values_arr, r_arr, rho_arr
    n_buf = 8 * max_n + 2 + max(4 * max_n + 4, 13 * (big_m + 3)) + 8
    nt = max(num_threads, 1) if k_total >= 16 else 1
    with nogil, parallel(num_threads=nt):
        buf = <double*> malloc(n_buf * sizeof(double))
        runs = <Py_ssize_t*> malloc((max_n + 2) * sizeof(Py_ssize_t))
        for k in prange(k_total, schedule="dynamic", chunksize=4):
            if buf == NULL or runs == NULL:
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
        free(buf)
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
    cdef Py_ssize_t k_total = offsets.shape[0] - 1, k
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
    with nogil:
        for k in range(k_total):
            _area_centroid(&points[0, 0] + 2 * offsets[k], offsets[k + 1] - offsets[k], ac)
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
    u = np.empty(2 * m, np.float64)
    cdef double[::1] uv = u
    _min_area_box(&h[0, 0], m, &uv[0], side)
    return side[0], side[1]
