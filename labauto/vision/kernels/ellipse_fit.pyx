# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
# distutils: extra_compile_args = -fno-math-errno
"""Ellipse fitting kernel: algebraic seed, orthogonal contact points, geometric fit (LM).

See :mod:`labauto.vision.ellipse_fit` for the method (Halir-Flusser's direct fit, Eberly's
contact-point root, Ahn's Jacobian, the Levenberg-Marquardt damping and stopping rules). Every
contour is fitted on its own, start to end, in plain C: the contours of a batch are shared
among threads, and a contour's result does not depend on the rest of the batch. The per-point
arithmetic is the documented one up to rounding (the Newton step over a common denominator,
divisions by a contour's constants as multiplications by their reciprocals); the per-point
stages run on blocks of up to BLOCK points so that the compiler vectorises them. A contour's
last block is padded to a multiple of 4 points by repeating its last point (the padding takes
the same Newton steps as that point, so it costs no extra sweep), so that the loops run over
whole vectors of 4 doubles without a scalar remainder; the padding adds nothing to any sum
or result.

Sums over a contour's points (the moments of the algebraic fit, the cost, J^T d and J^T J of
the geometric fit) run in point order, as plain loops (see "ordered sums" below). Compiled with
``-fno-math-errno`` (see the second line) so that loops with ``sqrt`` vectorise, and (setup.py)
with ``-ffp-contract=off``: no fused multiply-adds, every product and sum rounded as written.

Parameter rows are ``(cx, cy, a, b, angle_deg)``. Status codes: 0 ok, 1 fewer than 5 points,
2 degenerate points, 3 the best conic is not an ellipse (4: a bad initial row).
"""

from cython.parallel cimport prange
from libc.math cimport (
    INFINITY, NAN, atan2, cbrt, copysign, cos, fabs, fmod, hypot, isfinite, sin, sqrt,
)
from libc.stdlib cimport free, malloc

cdef double PI = 3.141592653589793
cdef int MAX_NEWTON = 60  # contact-point Newton steps at most (2-4 are typical)
cdef enum:
    OK = 0
    TOO_FEW = 1
    DEGENERATE = 2
    NOT_ELLIPSE = 3
    BAD_INITIAL = 4
cdef enum:
    BLOCK = 128  # points per block of the per-point stages
    PARALLEL_MIN_POINTS = 2000  # smaller batches run on one thread (no thread start-up)


# ---------------------------------------------------------------------------- ordered sums


cdef extern from *:
    """

    /* The sums of _evaluate over m points, added to acc[0..20] in point order:
       acc[0] += d^2, acc[1 + r] += j_r d, acc[6 + q] += j_r j_c (r <= c, row by row: the
       upper triangle of J^T J), with d = dd[k] and j_r = jj[r * stride + k]. */
    static void labauto_normal_sums(const double* dd, const double* jj, Py_ssize_t stride,
                                    Py_ssize_t m, double* acc) {
        Py_ssize_t k = 0;
        int r, c, q;
        double d, j[5];
        for (; k < m; k++) {
            d = dd[k];
            for (r = 0; r < 5; r++) j[r] = jj[r * stride + k];
            acc[0] += d * d;
            for (r = 0; r < 5; r++) acc[1 + r] += j[r] * d;
            q = 6;
            for (r = 0; r < 5; r++)
                for (c = r; c < 5; c++) acc[q++] += j[r] * j[c];
        }
    }

    /* The moment sums of _algebraic over n points (x, y interleaved), added to mom[0..13] in
       point order: x, y, x^2, xy, y^2, x^3, x^2 y, x y^2, y^3, x^4, x^3 y, x^2 y^2, x y^3, y^4
       of x = (x - mx) inv, y = (y - my) inv (the products as written below). mom[14..15]
       must be 0 (padding, left 0). */
    static void labauto_moment_sums(const double* pts, Py_ssize_t n, double mx, double my,
                                    double inv, double* mom) {
        Py_ssize_t i = 0;
        double x, y, xx, xy, yy;
        for (; i < n; i++) {
            x = (pts[2 * i] - mx) * inv;
            y = (pts[2 * i + 1] - my) * inv;
            xx = x * x;
            xy = x * y;
            yy = y * y;
            mom[0] += x;
            mom[1] += y;
            mom[2] += xx;
            mom[3] += xy;
            mom[4] += yy;
            mom[5] += xx * x;
            mom[6] += xx * y;
            mom[7] += x * yy;
            mom[8] += yy * y;
            mom[9] += xx * xx;
            mom[10] += xx * xy;
            mom[11] += xx * yy;
            mom[12] += xy * yy;
            mom[13] += yy * yy;
        }
    }
    """
    void _moment_sums "labauto_moment_sums"(
        const double* pts, Py_ssize_t n, double mx, double my, double inv, double* mom
    ) noexcept nogil
    void _normal_sums "labauto_normal_sums"(
        const double* dd, const double* jj, Py_ssize_t stride, Py_ssize_t m, double* acc
    ) noexcept nogil


# ------------------------------------------------------------------------------ small helpers


cdef inline double _py_mod(double x, double m) noexcept nogil:
    """``x % m`` with Python's (and numpy's) sign convention, m > 0."""
    cdef double r = fmod(x, m)
    if r != 0.0:
        if r < 0.0:
            r += m
    else:
        r = 0.0
    return r


cdef inline void _normalise(double* p) noexcept nogil:
    """``Ellipse.normalised`` on a row in place: ``a >= b``, angle in [0, 180)."""
    cdef double a = fabs(p[2]), b = fabs(p[3])
    if b > a:
        p[2] = b
        p[3] = a
        p[4] = p[4] + 90.0
    else:
        p[2] = a
        p[3] = b
    p[4] = _py_mod(p[4], 180.0)


cdef int _solve(double* m, double* rhs, int n) noexcept nogil:
    """Solve ``m x = rhs`` (n x n row-major, n <= 5) in place by LU with partial pivoting.

    ``rhs`` becomes x. Returns 0, or 1 for an exactly singular matrix (x is then NaN).
    """
    cdef int i, j, k, piv
    cdef double best, t, inv
    for k in range(n):
        piv = k
        best = fabs(m[k * n + k])
        for i in range(k + 1, n):
            if fabs(m[i * n + k]) > best:
                best = fabs(m[i * n + k])
                piv = i
        if not best > 0.0:
            for i in range(n):
                rhs[i] = NAN
            return 1
        if piv != k:
            for j in range(n):
                t = m[k * n + j]
                m[k * n + j] = m[piv * n + j]
                m[piv * n + j] = t
            t = rhs[k]
            rhs[k] = rhs[piv]
            rhs[piv] = t
        inv = 1.0 / m[k * n + k]
        for i in range(k + 1, n):
            t = m[i * n + k] * inv
            m[i * n + k] = t
            for j in range(k + 1, n):
                m[i * n + j] -= t * m[k * n + j]
            rhs[i] -= t * rhs[k]
    for i in range(n - 1, -1, -1):
        t = rhs[i]
        for j in range(i + 1, n):
            t -= m[i * n + j] * rhs[j]
        rhs[i] = t / m[i * n + i]
    return 0


# --------------------------------------------------------------------------------- algebraic


cdef void _sym3_extreme_eigenvalues(const double* s, double* lo, double* hi) noexcept nogil:
    """Smallest and largest eigenvalue of a symmetric 3x3 matrix (row-major)."""
    cdef double p1 = s[1] * s[1] + s[2] * s[2] + s[5] * s[5]
    cdef double q = (s[0] + s[4] + s[8]) / 3.0
    cdef double d0 = s[0] - q, d1 = s[4] - q, d2 = s[8] - q
    cdef double p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1
    cdef double p, r, phi, e1, e3, det
    if p2 <= 0.0:
        lo[0] = q
        hi[0] = q
        return
    p = sqrt(p2 / 6.0)
    # det((s - q I) / p) / 2
    det = (d0 * (d1 * d2 - s[5] * s[5]) - s[1] * (s[1] * d2 - s[5] * s[2])
           + s[2] * (s[1] * s[5] - d1 * s[2]))
    r = det / (2.0 * p * p * p)
    r = -1.0 if r < -1.0 else (1.0 if r > 1.0 else r)
    phi = atan2(sqrt(1.0 - r * r), r) / 3.0  # acos(r) / 3
    e1 = q + 2.0 * p * cos(phi)
    e3 = q + 2.0 * p * cos(phi + 2.0 * PI / 3.0)
    lo[0] = e3
    hi[0] = e1


cdef inline double _cubic(double c2, double c1, double c0, double x) noexcept nogil:
    return ((x + c2) * x + c1) * x + c0


cdef inline double _polish(double c2, double c1, double c0, double x) noexcept nogil:
    """Two Newton steps on ``x^3 + c2 x^2 + c1 x + c0`` (a root found in closed form)."""
    cdef int it
    cdef double f, df
    for it in range(2):
        f = _cubic(c2, c1, c0, x)
        df = (3.0 * x + 2.0 * c2) * x + c1
        if df != 0.0 and isfinite(f / df):
            x = x - f / df
    return x


cdef double _real_eigenvector(const double* m, double lam, double* v) noexcept nogil:
    """Unit eigenvector of the 3x3 ``m`` for the real eigenvalue ``lam``; returns its cond.

    The largest cross product of two rows of ``m - lam I``; ``cond = 4 v0 v2 - v1^2``.
    """
    cdef double r[9]
    cdef double c[9]
    cdef double n[3]
    cdef int i, best = 0
    cdef double norm
    for i in range(9):
        r[i] = m[i]
    r[0] -= lam
    r[4] -= lam
    r[8] -= lam
    _cross(r, r + 3, c)
    _cross(r, r + 6, c + 3)
    _cross(r + 3, r + 6, c + 6)
    for i in range(3):
        n[i] = c[3 * i] * c[3 * i] + c[3 * i + 1] * c[3 * i + 1] + c[3 * i + 2] * c[3 * i + 2]
    if n[1] > n[best]:
        best = 1
    if n[2] > n[best]:
        best = 2
    norm = sqrt(n[best])
    if not norm > 0.0:
        v[0] = 0.0
        v[1] = 0.0
        v[2] = 0.0
        return -1.0
    for i in range(3):
        v[i] = c[3 * best + i] / norm
    return 4.0 * v[0] * v[2] - v[1] * v[1]


cdef inline void _cross(const double* a, const double* b, double* out) noexcept nogil:
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


cdef double _complex_eigenvector_real_part(
    const double* m, double lre, double lim, double* v
) noexcept nogil:
    """Real part of the eigenvector of ``m`` for ``lre + i lim`` in LAPACK's normalisation.

    (Unit 2-norm, the component of largest modulus real.) Returns its cond.
    """
    cdef double rr[9]
    cdef double ri[9]
    cdef double cr[9]
    cdef double ci[9]
    cdef double nrm[3]
    cdef double mod2, big, scale, pr, pi_, tr, ti
    cdef int i, j, best = 0, k = 0
    cdef int pairs[6]
    pairs[:] = [0, 3, 0, 6, 3, 6]
    for i in range(9):
        rr[i] = m[i]
        ri[i] = 0.0
    for i in range(3):
        rr[4 * i] -= lre
        ri[4 * i] = -lim
    for j in range(3):  # complex cross products of row pairs
        _ccross(rr + pairs[2 * j], ri + pairs[2 * j], rr + pairs[2 * j + 1],
                ri + pairs[2 * j + 1], cr + 3 * j, ci + 3 * j)
        nrm[j] = 0.0
        for i in range(3):
            nrm[j] += cr[3 * j + i] * cr[3 * j + i] + ci[3 * j + i] * ci[3 * j + i]
    if nrm[1] > nrm[best]:
        best = 1
    if nrm[2] > nrm[best]:
        best = 2
    if not nrm[best] > 0.0:
        v[0] = 0.0
        v[1] = 0.0
        v[2] = 0.0
        return -1.0
    big = -1.0
    for i in range(3):
        mod2 = cr[3 * best + i] * cr[3 * best + i] + ci[3 * best + i] * ci[3 * best + i]
        if mod2 > big:
            big = mod2
            k = i
    # multiply by conj(v_k) / |v_k| / |v|: v_k becomes real
    pr = cr[3 * best + k]
    pi_ = -ci[3 * best + k]
    scale = 1.0 / (sqrt(big) * sqrt(nrm[best]))
    for i in range(3):
        tr = cr[3 * best + i]
        ti = ci[3 * best + i]
        v[i] = (tr * pr - ti * pi_) * scale
    return 4.0 * v[0] * v[2] - v[1] * v[1]


cdef inline void _ccross(
    const double* ar, const double* ai, const double* br, const double* bi,
    double* outr, double* outi,
) noexcept nogil:
    cdef int i, j, k
    for i in range(3):
        j = (i + 1) % 3
        k = (i + 2) % 3
        outr[i] = (ar[j] * br[k] - ai[j] * bi[k]) - (ar[k] * br[j] - ai[k] * bi[j])
        outi[i] = (ar[j] * bi[k] + ai[j] * br[k]) - (ar[k] * bi[j] + ai[k] * br[j])


cdef int _ellipse_eigenvector(const double* m, double* best_v) noexcept nogil:
    """The eigenvector of the 3x3 ``m`` (unit norm) with the largest ``4 v0 v2 - v1^2``.

    Returns 1 when that is > 0 (the vector describes an ellipse), else 0.
    """
    cdef double c2 = -(m[0] + m[4] + m[8])
    cdef double c1 = (m[0] * m[4] - m[1] * m[3]) + (m[0] * m[8] - m[2] * m[6]) \
        + (m[4] * m[8] - m[5] * m[7])
    cdef double c0 = -(m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
                       + m[2] * (m[3] * m[7] - m[4] * m[6]))
    # depressed cubic y^3 + p y + q with x = y - c2 / 3
    cdef double shift = -c2 / 3.0
    cdef double p = c1 - c2 * c2 / 3.0
    cdef double q = (2.0 * c2 * c2 * c2 - 9.0 * c2 * c1) / 27.0 + c0
    cdef double disc = q * q / 4.0 + p * p * p / 27.0
    cdef double roots[3]
    cdef double v[3]
    cdef double cond, best = -1e300, rad, phi, u, w, re, im
    cdef int i, j, nroots
    if disc <= 0.0:  # three real roots
        rad = sqrt(-p / 3.0) if p < 0.0 else 0.0
        if rad > 0.0:
            w = -q / (2.0 * rad * rad * rad)
            w = -1.0 if w < -1.0 else (1.0 if w > 1.0 else w)
            phi = atan2(sqrt(1.0 - w * w), w) / 3.0
            for i in range(3):
                roots[i] = _polish(c2, c1, c0, shift + 2.0 * rad * cos(phi - 2.0 * PI * i / 3.0))
        else:
            for i in range(3):
                roots[i] = shift
        nroots = 3
    else:  # one real root and a complex pair
        w = sqrt(disc)
        u = -q / 2.0 + w
        u = cbrt(u)
        w = -q / 2.0 - w
        w = cbrt(w)
        roots[0] = _polish(c2, c1, c0, shift + u + w)
        nroots = 1
        # the pair: deflate x^3 + c2 x^2 + c1 x + c0 = (x - r)(x^2 + e1 x + e0)
        re = -(c2 + roots[0]) / 2.0
        im = (c1 + roots[0] * (c2 + roots[0])) - re * re
        im = sqrt(im) if im > 0.0 else 0.0
        cond = _complex_eigenvector_real_part(m, re, im, v)
        if cond > best:
            best = cond
            for j in range(3):
                best_v[j] = v[j]
    for i in range(nroots):
        cond = _real_eigenvector(m, roots[i], v)
        if cond > best:
            best = cond
            for j in range(3):
                best_v[j] = v[j]
    return 1 if best > 0.0 else 0


cdef int _conic_to_params(const double* conic, double* out) noexcept nogil:
    """Conic ``A x^2 + B xy + C y^2 + D x + E y + F`` -> ``cx, cy, major, minor, deg``.

    Returns 1 when the conic is a real ellipse (``out`` is filled either way).
    """
    cdef double sgn = -1.0 if conic[0] + conic[2] < 0.0 else 1.0
    cdef double a_ = conic[0] * sgn, b_ = conic[1] * sgn, c_ = conic[2] * sgn
    cdef double d_ = conic[3] * sgn, e_ = conic[4] * sgn, f_ = conic[5] * sgn
    cdef double den = b_ * b_ - 4.0 * a_ * c_
    cdef double x0 = (2.0 * c_ * d_ - b_ * e_) / den
    cdef double y0 = (2.0 * a_ * e_ - b_ * d_) / den
    cdef double f0 = f_ + 0.5 * (d_ * x0 + e_ * y0)
    cdef double half_sum = 0.5 * (a_ + c_)
    cdef double root = hypot(0.5 * (a_ - c_), 0.5 * b_)
    cdef double lam_small = half_sum - root, lam_big = half_sum + root
    cdef double major = sqrt(-f0 / lam_small), minor = sqrt(-f0 / lam_big)
    out[0] = x0
    out[1] = y0
    out[2] = major
    out[3] = minor
    out[4] = _py_mod(0.5 * atan2(b_, a_ - c_) * (180.0 / PI) + 90.0, 180.0)
    return 1 if (den < 0.0 and lam_small > 0.0 and f0 < 0.0 and isfinite(major)
                 and isfinite(minor)) else 0


cdef int _algebraic(const double* pts, Py_ssize_t n, double* out) noexcept nogil:
    """Halir-Flusser direct fit of n points (x, y interleaved) -> ``out`` row; status code."""
    cdef Py_ssize_t i
    cdef double sx = 0.0, sy = 0.0, mx, my, x, y, ss = 0.0, scale, inv
    cdef double mom[17]  # x^i y^j at _moment_index(i, j), divided by n (2 padding)
    cdef double sc[36]
    cdef double s3[9]
    cdef double t[9]
    cdef double rhs[3]
    cdef double mm[9]
    cdef double mat[9]
    cdef double a1[3]
    cdef double conic[6]
    cdef double lo, hi
    cdef int r, c, ok
    cdef int ex[6]
    cdef int fy[6]
    ex[:] = [2, 1, 0, 1, 0, 0]
    fy[:] = [0, 1, 2, 0, 1, 0]
    if n < 5:
        return TOO_FEW
    for i in range(n):
        sx += pts[2 * i]
        sy += pts[2 * i + 1]
    mx = sx / n
    my = sy / n
    for i in range(n):
        x = pts[2 * i] - mx
        y = pts[2 * i + 1] - my
        ss += x * x + y * y
    scale = sqrt(ss / (2.0 * n))
    scale = scale if scale > 0.0 else 1.0
    inv = 1.0 / scale
    for i in range(17):
        mom[i] = 0.0
    _moment_sums(pts, n, mx, my, inv, mom + 1)
    for i in range(1, 15):
        mom[i] = mom[i] / n
    mom[0] = 1.0
    # the scatter of the design rows (x^2, xy, y^2, x, y, 1): moment x^(ei+ej) y^(fi+fj)
    for r in range(6):
        for c in range(6):
            sc[6 * r + c] = mom[_moment_index(ex[r] + ex[c], fy[r] + fy[c])]
    for r in range(3):
        for c in range(3):
            s3[3 * r + c] = sc[6 * (r + 3) + c + 3]
    # collinear points (or fewer than 3 distinct ones) make S3 singular
    _sym3_extreme_eigenvalues(s3, &lo, &hi)
    if lo <= 1e-10 * hi:
        return DEGENERATE
    # T = -S3^-1 S2^T, column by column (column c: the design column c of x^2, xy, y^2)
    for c in range(3):
        for r in range(9):
            mat[r] = s3[r]
        for r in range(3):
            rhs[r] = sc[6 * c + r + 3]
        _solve(mat, rhs, 3)
        for r in range(3):
            t[3 * r + c] = -rhs[r]
    # M = S1 + S2 T, then C1^-1 M with C1 = [[0, 0, 2], [0, -1, 0], [2, 0, 0]]
    for r in range(3):
        for c in range(3):
            mat[3 * r + c] = sc[6 * r + c] + (sc[6 * r + 3] * t[c] + sc[6 * r + 4] * t[3 + c]
                                              + sc[6 * r + 5] * t[6 + c])
    for c in range(3):
        mm[c] = mat[6 + c] / 2.0
        mm[3 + c] = -mat[3 + c]
        mm[6 + c] = mat[c] / 2.0
    for r in range(9):
        if not isfinite(mm[r]):
            return DEGENERATE
    ok = _ellipse_eigenvector(mm, a1)
    for r in range(3):
        conic[r] = a1[r]
        conic[3 + r] = t[3 * r] * a1[0] + t[3 * r + 1] * a1[1] + t[3 * r + 2] * a1[2]
    if not _conic_to_params(conic, out) or not ok:
        return NOT_ELLIPSE
    out[0] = mx + scale * out[0]
    out[1] = my + scale * out[1]
    out[2] = out[2] * scale
    out[3] = out[3] * scale
    return OK


cdef inline int _moment_index(int i, int j) noexcept nogil:
    """Index of the moment x^i y^j (i + j <= 4) in ``_algebraic``'s ``mom``."""
    cdef int d = i + j
    return d * (d + 1) // 2 + j


# ---------------------------------------------------------------------------- contact points


cdef inline double _newton_step(
    double s, double ax2, double by2, double a2, double b2
) noexcept nogil:
    """Newton step ``-F(s) / F'(s)`` for the contact root, over a common denominator.

    ``ax2 = (a x)^2``, ``by2 = (b y)^2``: with ``pa = s + a^2``, ``pb = s + b^2``,
    ``F = ax2 / pa^2 + by2 / pb^2 - 1`` and the step is
    ``(ax2 pb^2 + by2 pa^2 - pa^2 pb^2) pa pb / (2 (ax2 pb^3 + by2 pa^3))`` (one division).
    """
    cdef double pa = s + a2, pb = s + b2
    cdef double pa2 = pa * pa, pb2 = pb * pb
    cdef double ta = ax2 * pb2, tb = by2 * pa2
    return ((ta + tb - pa2 * pb2) * (pa * pb)) / (2.0 * (ta * pb + tb * pa))


cdef void _contact_block(
    const double* uu, const double* vv, Py_ssize_t m, double a, double b,
    const double* guess, double* cus, double* cvs, double* roots,
) noexcept nogil:
    """Contact points of m <= BLOCK points ``(u, v)`` on ``u^2/a^2 + v^2/b^2 = 1``.

    Writes the contact points ``(cus, cvs)`` and the roots s. ``guess``: the roots of the same
    points on a nearby ellipse (not ``roots`` itself), or NULL: a first-order start. Each
    stage is a branch-free loop over the block (the compiler vectorises them): the first
    quadrant with the longer axis along x, the Newton start, Newton sweeps over the points
    still moving (each point stops after its own first step below the tolerance), the contact
    points; the rare points on the major axis inside the evolute are then redone one by one.

    The loops run over whole vectors: m is rounded up to a multiple of 4 here, and every
    array must hold that many points (the callers pad a block by repeating its last point,
    which gives the padding the same iterations, so no extra sweep).
    """
    cdef bint swap = a < b
    cdef double big = b if swap else a, small = a if swap else b
    cdef double a2 = big * big, b2 = small * small, lim = a2 - b2
    cdef double xx[BLOCK]
    cdef double yy[BLOCK]
    cdef double xin[BLOCK]
    cdef double ax2s[BLOCK]
    cdef double by2s[BLOCK]
    cdef long long act[BLOCK]
    cdef long long inner[BLOCK]
    cdef double u, v, x, y, ax, by, safe, s, s1, step, qx, qy, cu, cv
    cdef const double* starts = guess  # the Newton starts
    cdef long long n_inner = 0, busy, is_in, moving
    cdef Py_ssize_t k
    cdef int it
    m = (m + 3) & ~3  # (the compiler then knows that the loops need no scalar remainder)
    for k in range(m):
        u = uu[k]
        v = vv[k]
        x = fabs(v if swap else u)
        y = fabs(u if swap else v)
        # on the major axis inside the evolute: iterated as the dummy point (a, 0)
        is_in = (y == 0.0) & (big * x <= lim)
        inner[k] = is_in
        n_inner += is_in
        xin[k] = x
        xx[k] = big if is_in else x
        yy[k] = y
    if guess == NULL:  # first order: p = c + s grad(Q)/2 at the contact c
        starts = roots
        for k in range(m):
            x = xx[k]
            y = yy[k]
            qx = x / a2
            qy = y / b2
            roots[k] = 0.5 * (x * qx + y * qy - 1.0) / (qx * qx + qy * qy)
    for k in range(m):  # the safe start, one Newton step, the safe start again
        ax = big * xx[k]
        by = small * yy[k]
        safe = by - b2 if by - b2 > ax - a2 else ax - a2
        s = starts[k]
        s = s if s > safe else safe
        ax = ax * ax
        by = by * by
        s = s + _newton_step(s, ax, by, a2, b2)
        roots[k] = s if s > safe else safe
        ax2s[k] = ax
        by2s[k] = by
        act[k] = 1
    for it in range(MAX_NEWTON):
        busy = 0
        for k in range(m):
            s = roots[k]
            step = _newton_step(s, ax2s[k], by2s[k], a2, b2)
            s1 = s + step
            roots[k] = s1 if act[k] else s
            moving = act[k] & (fabs(step) > 1e-9 * (fabs(s1) + b2))
            act[k] = moving
            busy += moving
        if busy == 0:
            break
    for k in range(m):
        s = roots[k]
        qx = 1.0 / ((s + a2) * (s + b2))
        cu = a2 * xx[k] * (s + b2) * qx
        cv = b2 * yy[k] * (s + a2) * qx
        u = cv if swap else cu
        v = cu if swap else cv
        cus[k] = copysign(u, uu[k])
        cvs[k] = copysign(v, vv[k])
    if n_inner:
        for k in range(m):
            if inner[k]:
                cu = a2 * xin[k] / (a2 - b2) if big > small else 0.0
                cv = 1.0 - (cu / big) * (cu / big)
                cv = small * sqrt(0.0 if cv < 0.0 else (1.0 if cv > 1.0 else cv))
                roots[k] = -b2
                u = cv if swap else cu
                v = cu if swap else cv
                cus[k] = copysign(u, uu[k])
                cvs[k] = copysign(v, vv[k])


cdef inline void _pad_block(double* uu, double* vv, Py_ssize_t m) noexcept nogil:
    """Repeat the last of m >= 1 points up to a multiple of 4 (``_contact_block``)."""
    cdef Py_ssize_t k
    for k in range(m, (m + 3) & ~3):
        uu[k] = uu[m - 1]
        vv[k] = vv[m - 1]


cdef inline void _to_frame(
    const double* pts, Py_ssize_t m, double xc, double yc, double c, double s,
    double* uu, double* vv,
) noexcept nogil:
    """m points ``(x, y)`` (interleaved) in the frame of an ellipse (centre, cos, sin)."""
    cdef Py_ssize_t k
    cdef double dx, dy
    for k in range(m):
        dx = pts[2 * k] - xc
        dy = pts[2 * k + 1] - yc
        uu[k] = c * dx + s * dy
        vv[k] = c * dy - s * dx


cdef double _evaluate(
    const double* pts, Py_ssize_t n, const double* p, const double* guess, double* roots,
    double* hess, double* grad,
) noexcept nogil:
    """Orthogonal distances of n points to ellipse ``p`` (angle in radians) and their sums.

    Writes the contact roots, the upper triangle of J^T J (15, row by row) and J^T d (5);
    returns the sum of squared distances. ``guess``: the roots of the last accepted
    parameters, or NULL. Block by block: the contact points, then the distances along the
    outward normal and Ahn's Jacobian (``-n . d(contact)/d(parameter)``), then the sums in
    point order. The last block is padded to whole vectors of 4 by repeating its last point
    (``roots`` and ``guess`` hold n rounded up to a multiple of 4); the padding's distance and
    Jacobian rows are zeroed, so that they add exact zeros to the sums.
    """
    cdef double xc = p[0], yc = p[1], a = p[2], b = p[3]
    cdef double c = cos(p[4]), sn = sin(p[4])
    cdef double inv_a2 = 1.0 / (a * a), inv_b2 = 1.0 / (b * b), inv_a = 1.0 / a, inv_b = 1.0 / b
    cdef double uu[BLOCK]
    cdef double vv[BLOCK]
    cdef double cus[BLOCK]
    cdef double cvs[BLOCK]
    cdef double dd[BLOCK]
    cdef double jj[5 * BLOCK]
    cdef double acc[21]  # the sums: cost, J^T d (5), J^T J (15) (labauto_normal_sums)
    cdef double cost, u, v, fu, fv, nu, nv, norm
    cdef Py_ssize_t start, m, m4, k, blk
    cdef int r
    for k in range(21):
        acc[k] = 0.0
    for blk in range((n + BLOCK - 1) // BLOCK):
        start = blk * BLOCK
        m = n - start if n - start < BLOCK else BLOCK
        m4 = (m + 3) & ~3
        _to_frame(pts + 2 * start, m, xc, yc, c, sn, uu, vv)
        _pad_block(uu, vv, m)
        _contact_block(uu, vv, m4, a, b, guess + start if guess != NULL else NULL, cus, cvs,
                       roots + start)
        for k in range(m4):
            u = uu[k]
            v = vv[k]
            fu = cus[k]
            fv = cvs[k]
            nu = fu * inv_a2  # outward normal in the ellipse frame
            nv = fv * inv_b2
            norm = 1.0 / sqrt(nu * nu + nv * nv)
            nu = nu * norm
            nv = nv * norm
            dd[k] = nu * (u - fu) + nv * (v - fv)
            jj[k] = sn * nv - c * nu
            jj[BLOCK + k] = -(sn * nu + c * nv)
            jj[2 * BLOCK + k] = -nu * fu * inv_a
            jj[3 * BLOCK + k] = -nv * fv * inv_b
            jj[4 * BLOCK + k] = nu * fv - nv * fu
        # the padding adds +0 to every sum: no change (a sum starting at +0 is never -0)
        for k in range(m, m4):
            dd[k] = 0.0
            for r in range(5):
                jj[r * BLOCK + k] = 0.0
        _normal_sums(dd, jj, BLOCK, m4, acc)
    for k in range(5):
        grad[k] = acc[1 + k]
    for k in range(15):
        hess[k] = acc[6 + k]
    cost = acc[0]
    return cost


# -------------------------------------------------------------------------------- geometric


cdef void _levenberg_marquardt(
    const double* pts, Py_ssize_t n, double* p, int max_iter, double tol,
    double* roots, double* roots_t, double* rms, int* iterations, unsigned char* converged,
) noexcept nogil:
    """Geometric fit of one contour from the row ``p`` (degrees), in place (module docstring)."""
    cdef double hess[15]
    cdef double grad[5]
    cdef double hess_t[15]
    cdef double grad_t[5]
    cdef double mat[25]
    cdef double step[5]
    cdef double trial[5]
    cdef double diag[5]
    cdef double cost, cost_t, lam = 0.0, ridge, size, step_px
    cdef double* tmp
    cdef int it = 0, r, k, q
    cdef bint active, valid, accept, small_step, small_gain, done, conv = False
    p[4] = p[4] * (PI / 180.0)
    cost = _evaluate(pts, n, p, NULL, roots, hess, grad)
    active = max_iter > 0
    while active:
        it += 1
        q = 0
        for r in range(5):
            for k in range(r, 5):
                mat[5 * r + k] = hess[q]
                mat[5 * k + r] = hess[q]
                q += 1
            diag[r] = mat[6 * r]
        # a tiny ridge keeps the angle column solvable for a circle (where it is zero)
        ridge = 1e-12 * ((((diag[0] + diag[1]) + diag[2]) + diag[3]) + diag[4])
        for r in range(5):
            mat[6 * r] = mat[6 * r] + (lam * diag[r] + ridge)
            step[r] = grad[r]
        _solve(mat, step, 5)
        for r in range(5):
            step[r] = -step[r]
        size = p[2] if p[2] > p[3] else p[3]
        size = size if size > 1.0 else 1.0
        step_px = sqrt(
            (((step[0] * step[0] + step[1] * step[1]) + step[2] * step[2]) + step[3] * step[3])
            + (size * step[4]) * (size * step[4])
        )
        valid = True
        for r in range(5):
            trial[r] = p[r] + step[r]
            valid = valid and isfinite(trial[r])
        valid = valid and trial[2] > 0.0 and trial[3] > 0.0
        if valid:
            cost_t = _evaluate(pts, n, trial, roots, roots_t, hess_t, grad_t)
        else:
            cost_t = INFINITY
        small_step = step_px <= tol * size
        accept = cost_t <= cost
        small_gain = accept and lam == 0.0 and cost - cost_t <= tol * cost
        if accept:
            for r in range(5):
                p[r] = trial[r]
                grad[r] = grad_t[r]
            for r in range(15):
                hess[r] = hess_t[r]
            cost = cost_t
            tmp = roots
            roots = roots_t
            roots_t = tmp
            lam = 0.0 if lam <= 1e-6 else lam / 10.0
        elif not small_step:
            lam = 1e-3 if lam == 0.0 else lam * 10.0
        done = (accept and (small_step or small_gain)) or (not accept and small_step)
        conv = conv or done
        active = not done and lam <= 1e12 and it < max_iter
    p[4] = p[4] * (180.0 / PI)
    rms[0] = sqrt(cost / n)
    iterations[0] = it
    converged[0] = conv


# ------------------------------------------------------------------------------- entry points


cdef void _fit_one(
    const double* pts, Py_ssize_t n, double* row, int* status, bint seed, int max_iter,
    double tol, double* scratch, double* rms, int* iterations, unsigned char* converged,
) noexcept nogil:
    """Seed and/or fit one contour (``fit_ellipses``).

    ``scratch`` holds 2 n4 doubles, n4 = n rounded up to a multiple of 4 (``_evaluate``).
    """
    cdef int i
    cdef bint ok = True
    if seed:
        status[0] = _algebraic(pts, n, row)
    elif n < 5:
        status[0] = TOO_FEW
    else:
        for i in range(5):
            ok = ok and isfinite(row[i])
        status[0] = OK if ok and row[2] > 0.0 and row[3] > 0.0 else BAD_INITIAL
    if status[0] != OK:
        return
    if max_iter >= 0:
        _levenberg_marquardt(
            pts, n, row, max_iter, tol, scratch, scratch + ((n + 3) & ~3), rms, iterations,
            converged,
        )
    _normalise(row)


def fit_ellipses(
    const double[:, ::1] points,
    const Py_ssize_t[::1] offsets,
    const Py_ssize_t[::1] index,
    double[:, ::1] params,
    int[::1] status,
    double[::1] rms,
    int[::1] iterations,
    unsigned char[::1] converged,
    bint seed,
    int max_iter,
    double tol,
    int num_threads=1,
) -> None:
    """Algebraic seeds and/or geometric fits of K of the contours of a contour set, in place.

    Parameters
    ----------
    points : (N, 2) float64 ``(x, y)``, C-contiguous, every contour of the set
    offsets : (C + 1,) intp, contour c is ``points[offsets[c]:offsets[c + 1]]``, rising
        from 0 to N
    index : (K,) intp, the contours to fit (each in [0, C)); row j of the outputs is contour
        ``index[j]``. The detector fits its DES in place this way, without gathering their
        points; a plain batch passes ``arange(C)``.
    params : (K, 5) float64 rows ``(cx, cy, a, b, angle_deg)``: the initial rows when ``seed``
        is false (checked here: finite, a, b > 0), else written with the algebraic fits. On
        return the result rows, normalised as ``Ellipse.normalised`` (``a >= b``, angle in
        [0, 180)), where ``status`` is 0.
    status : (K,) int32, written: 0 ok, else the reason (module docstring)
    rms, iterations, converged : (K,) float64, int32, uint8, written for the geometric fits
    seed : compute the algebraic fits first
    max_iter : Levenberg-Marquardt iterations at most; < 0: no geometric fit (``rms`` etc.
        are left alone)
    tol : convergence tolerance (``fit_ellipse_geometric``)
    num_threads : threads sharing the contours (see :func:`labauto.vision.kernels.threads`)

    Contours are shared among threads when they hold PARALLEL_MIN_POINTS points or more;
    every contour's result is the same either way.
    """
    cdef Py_ssize_t c_count = offsets.shape[0] - 1, n_total = points.shape[0]
    cdef Py_ssize_t k_count = index.shape[0], k, c, n, n_fit = 0, n_scratch = 0
    cdef double* scratch
    # contour j's contact roots: 2 n4 doubles from scratch + 2 start[j] (n4: n rounded up to a
    # multiple of 4, _fit_one)
    cdef Py_ssize_t* start
    cdef double* base
    if c_count < 0 or params.shape[0] != k_count or params.shape[1] != 5 \
            or status.shape[0] != k_count or rms.shape[0] != k_count \
            or iterations.shape[0] != k_count or converged.shape[0] != k_count \
            or points.shape[1] != 2:
        raise ValueError("fit_ellipses: inconsistent array shapes")
    if c_count > 0 and (offsets[0] != 0 or offsets[c_count] != n_total):
        raise ValueError("fit_ellipses: offsets must run from 0 to len(points)")
    for c in range(c_count):
        if offsets[c + 1] < offsets[c]:
            raise ValueError("fit_ellipses: offsets must not decrease")
    for k in range(k_count):
        if index[k] < 0 or index[k] >= c_count:
            raise ValueError("fit_ellipses: index out of range of the contours")
    if k_count == 0:
        return
    start = <Py_ssize_t*>malloc(k_count * sizeof(Py_ssize_t))
    if start == NULL:
        raise MemoryError()
    for k in range(k_count):
        n = offsets[index[k] + 1] - offsets[index[k]]
        start[k] = n_scratch
        n_scratch += (n + 3) & ~3
        n_fit += n
    scratch = <double*>malloc((2 * n_scratch + 1) * sizeof(double))
    if scratch == NULL:
        free(start)
        raise MemoryError()
    base = <double*>&points[0, 0] if n_total > 0 else NULL
    # a short batch (a single fit, a robust refit) is faster on one thread than waking another
    cdef int nt = 1 if n_fit < PARALLEL_MIN_POINTS else max(num_threads, 1)
    for k in prange(k_count, nogil=True, schedule="dynamic", num_threads=nt):
        _fit_one(
            base + 2 * offsets[index[k]], offsets[index[k] + 1] - offsets[index[k]],
            &params[k, 0], &status[k], seed, max_iter, tol, scratch + 2 * start[k],
            &rms[k], &iterations[k], &converged[k],
        )
    free(scratch)
    free(start)


def orthogonal_distances(
    const double[:, ::1] points, double cx, double cy, double a, double b, double angle_rad,
    double[::1] out,
) -> None:
    """Signed orthogonal distances (outside > 0) of ``points`` to one ellipse, into ``out``."""
    cdef Py_ssize_t n = points.shape[0], start, m, k, blk
    cdef double c = cos(angle_rad), s = sin(angle_rad), nu, nv, norm
    cdef double uu[BLOCK]
    cdef double vv[BLOCK]
    cdef double cus[BLOCK]
    cdef double cvs[BLOCK]
    cdef double roots[BLOCK]
    if out.shape[0] != n or points.shape[1] != 2:
        raise ValueError("orthogonal_distances: inconsistent array shapes")
    if not (a > 0.0 and b > 0.0):
        raise ValueError("orthogonal_distances: semi-axes must be > 0")
    with nogil:
        for blk in range((n + BLOCK - 1) // BLOCK):
            start = blk * BLOCK
            m = n - start if n - start < BLOCK else BLOCK
            _to_frame(&points[start, 0], m, cx, cy, c, s, uu, vv)
            _pad_block(uu, vv, m)
            _contact_block(uu, vv, m, a, b, NULL, cus, cvs, roots)
            for k in range(m):
                nu = cus[k] / (a * a)
                nv = cvs[k] / (b * b)
                norm = 1.0 / sqrt(nu * nu + nv * nv)
                out[start + k] = (nu * norm) * (uu[k] - cus[k]) + (nv * norm) * (vv[k] - cvs[k])


def contact_points(
    const double[::1] u, const double[::1] v, double a, double b, double[::1] cu, double[::1] cv
) -> None:
    """Orthogonal contact points of ``(u, v)`` on ``u^2/a^2 + v^2/b^2 = 1`` into ``cu``, ``cv``."""
    cdef Py_ssize_t n = u.shape[0], start, m, k, blk
    cdef double uu[BLOCK]
    cdef double vv[BLOCK]
    cdef double cus[BLOCK]
    cdef double cvs[BLOCK]
    cdef double roots[BLOCK]
    if v.shape[0] != n or cu.shape[0] != n or cv.shape[0] != n:
        raise ValueError("contact_points: inconsistent array shapes")
    if not (a > 0.0 and b > 0.0):
        raise ValueError("contact_points: semi-axes must be > 0")
    with nogil:
        for blk in range((n + BLOCK - 1) // BLOCK):
            start = blk * BLOCK
            m = n - start if n - start < BLOCK else BLOCK
            for k in range(m):
                uu[k] = u[start + k]
                vv[k] = v[start + k]
            _pad_block(uu, vv, m)
            _contact_block(uu, vv, m, a, b, NULL, cus, cvs, roots)
            for k in range(m):
                cu[start + k] = cus[k]
                cv[start + k] = cvs[k]


def conics_to_params(
    const double[:, ::1] conics, double[:, ::1] out, unsigned char[::1] valid
) -> None:
    """Conic rows ``(A, B, C, D, E, F)`` -> rows ``(cx, cy, major, minor, angle_deg)``."""
    cdef Py_ssize_t k
    if conics.shape[1] != 6 or out.shape[0] != conics.shape[0] or out.shape[1] != 5 \
            or valid.shape[0] != conics.shape[0]:
        raise ValueError("conics_to_params: inconsistent array shapes")
    for k in range(conics.shape[0]):
        valid[k] = _conic_to_params(&conics[k, 0], &out[k, 0])
