# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Edge linking kernel (section 3.1): thinning, outer border tracing, ordered chains, sub-pixel.

See :mod:`labauto.vision.edges` for the definitions. One call of :func:`link` goes from a Canny
edge map to the finished chains:

1. the edge pixels are collected in raster order into a zeroed padded work map (one-pixel zero
   border, so a 3x3 neighbourhood never needs a bounds check): 64 pixels at a time, a bit mask
   of the nonzero ones from four SSE2 compares, then its set bits (a per-byte loop spends most
   of its time on mispredicted branches: an edge map is ~1 % edges, in short runs);
2. they are thinned in checkerboard classes (``thin_edges``): the same passes, in the same
   order, as deciding every pixel of a class at once. After the first pass only pixels next
   to a removal (marked DIRTY) are decided again: the others would be kept as before;
3. every 8-connected component, from its first pixel in raster order, gets the outer border
   trace of Suzuki and Abe, step for step as ``cv2.findContours`` (``RETR_CCOMP``,
   ``CHAIN_APPROX_NONE``) follows it; the trace becomes a chain (``traces_to_chains``: rotated
   to its first turnaround if traced out and back, each pixel at its first visit); components
   are emitted in reverse raster order of their first pixels, as ``findContours`` lists them;
4. optionally the gradient at every point and the Devernay sub-pixel position (float32
   arithmetic, as the numpy formulation of ``refine_subpixel``), in chain order, with the
   gradient rows of the point 16 ahead prefetched (a chain wanders over the image: without
   the prefetch the loop mostly waits on memory).

The work map is left all zero again (only the touched pixels are cleared), so the caller can
keep one per image size instead of paying for a fresh image-sized allocation on every call.
"""

from libc.math cimport sqrt
from libc.stdlib cimport free, malloc, realloc
from libc.string cimport memcpy

import numpy as np

cdef enum:
    AHEAD = 16  # _sample_points: prefetch the gradient rows of the point this far ahead


# marks in the work map: bit 0 edge pixel, the others are bookkeeping of the linker
cdef enum:
    EDGE = 1
    IN_TRACE = 2  # met in the current trace, not yet emitted
    SEEN = 4  # emitted (first visit done)
    DONE = 8  # component already linked
    DIRTY = 16  # thinning: a neighbour was removed since the pixel was last kept


ctypedef struct Vec:
    Py_ssize_t* data
    Py_ssize_t size
    Py_ssize_t cap
    int failed


cdef inline void _init(Vec* v, Py_ssize_t cap) noexcept nogil:
    v.size = 0
    v.cap = cap if cap > 16 else 16
    v.data = <Py_ssize_t*>malloc(v.cap * sizeof(Py_ssize_t))
    v.failed = v.data == NULL
    if v.failed:
        v.cap = 0


cdef inline int _reserve(Vec* v, Py_ssize_t size) noexcept nogil:
    """Make room for ``size`` values; -1 (and ``failed``) when out of memory."""
    cdef Py_ssize_t cap = v.cap
    cdef Py_ssize_t* grown
    if size <= cap:
        return 0
    if v.failed:
        return -1
    while cap < size:
        cap = 2 * cap
    grown = <Py_ssize_t*>realloc(v.data, cap * sizeof(Py_ssize_t))
    if grown == NULL:
        v.failed = 1
        return -1
    v.data = grown
    v.cap = cap
    return 0


cdef inline void _push(Vec* v, Py_ssize_t value) noexcept nogil:
    cdef Py_ssize_t* grown
    if v.size == v.cap:
        if v.failed:
            return
        grown = <Py_ssize_t*>realloc(v.data, 2 * v.cap * sizeof(Py_ssize_t))
        if grown == NULL:
            v.failed = 1
            return
        v.data = grown
        v.cap = 2 * v.cap
    v.data[v.size] = value
    v.size += 1


cdef inline Py_ssize_t _row_of(Py_ssize_t p, Py_ssize_t stride, double inverse) noexcept nogil:
    """``p // stride`` for 0 <= p < 2**50 without an integer division (``inverse = 1 / stride``).

    The float estimate is off by at most one either way; two compares correct it.
    """
    cdef Py_ssize_t y = <Py_ssize_t>(<double>p * inverse)
    y -= y * stride > p
    y += (y + 1) * stride <= p
    return y


cdef inline void _ring(Py_ssize_t stride, Py_ssize_t* ring) noexcept nogil:
    """Ring offsets N, NE, E, SE, S, SW, W, NW (the bit order of the removable table)."""
    ring[0] = -stride
    ring[1] = -stride + 1
    ring[2] = 1
    ring[3] = stride + 1
    ring[4] = stride
    ring[5] = stride - 1
    ring[6] = -1
    ring[7] = -stride - 1


# ---------------------------------------------------------------------------------------------
# collecting and thinning


cdef extern from *:
    """
    #include <emmintrin.h>
    static inline int labauto_ctz64(unsigned long long v) { return __builtin_ctzll(v); }

    /* bit k set where p[k] != 0, k < 64: four SSE2 compares of 16 bytes with zero */
    static inline unsigned long long labauto_nonzero64(const unsigned char* p) {
        const __m128i zero = _mm_setzero_si128();
        unsigned long long zeros = 0, bits;
        for (int k = 0; k < 4; k++) {
            bits = (unsigned)_mm_movemask_epi8(
                _mm_cmpeq_epi8(_mm_loadu_si128((const __m128i*)(p + 16 * k)), zero));
            zeros |= bits << (16 * k);
        }
        return ~zeros;
    }

    /* the same for the last n < 64 pixels of a row */
    static inline unsigned long long labauto_nonzero_tail(const unsigned char* p, Py_ssize_t n) {
        unsigned long long found = 0;
        for (Py_ssize_t k = 0; k < n; k++) found |= (unsigned long long)(p[k] != 0) << k;
        return found;
    }
    """
    unsigned long long _nonzero64 "labauto_nonzero64"(const unsigned char* p) noexcept nogil
    unsigned long long _nonzero_tail "labauto_nonzero_tail"(
        const unsigned char* p, Py_ssize_t n) noexcept nogil
    int _ctz "labauto_ctz64"(unsigned long long v) noexcept nogil
    void _prefetch "__builtin_prefetch"(const void* address) noexcept nogil


cdef int _collect(
    const unsigned char* edges, Py_ssize_t h, Py_ssize_t w, Py_ssize_t step, unsigned char* pad,
    Py_ssize_t stride, Vec* pixels,
) noexcept nogil:
    """Set EDGE at every nonzero pixel of ``edges`` (HxW, rows ``step`` bytes apart) in the
    padded map; list them in raster order. ``edges`` may be the interior of ``pad`` itself
    (``thin``).

    64 pixels at a time: a bit mask of the nonzero ones (SSE2 compares), then its set bits,
    lowest first. Most blocks of an edge map are empty and cost one test. Returns -1 when out
    of memory.
    """
    cdef Py_ssize_t x, y, at
    cdef const unsigned char* row
    cdef unsigned long long found
    for y in range(h):
        if pixels.cap - pixels.size < w and _reserve(pixels, pixels.size + w) < 0:
            return -1
        row = edges + y * step
        at = (y + 1) * stride + 1  # padded index of row[0]
        x = 0
        while x < w:
            found = _nonzero64(row + x) if x + 64 <= w else _nonzero_tail(row + x, w - x)
            while found != 0:
                pad[at + x + _ctz(found)] = EDGE
                pixels.data[pixels.size] = at + x + _ctz(found)
                pixels.size += 1
                found &= found - 1
            x += 64
    return 0


cdef int _thin(
    unsigned char* pad, Py_ssize_t stride, const Py_ssize_t* pixels, Py_ssize_t n,
    const unsigned char* removable, int max_iter,
) noexcept nogil:
    """Checkerboard thinning in place (0 or 1 at the listed pixels). Returns -1 on no memory.

    ``pixels``: the set pixels, ascending. Class of padded pixel p: parity of its row, then
    parity of p itself (as ``thin_edges``). Two pixels of one class are never neighbours, so
    deciding them one after the other in place is deciding them at once.

    A kept pixel is decided again in a later pass only if a neighbour was removed since (a
    removal marks its neighbours DIRTY): with the same neighbourhood the table gives the same
    answer. The first pass decides every pixel; Canny output then has few removals left, so
    the second pass is mostly one load per pixel. The marks left at the end are cleared.
    """
    cdef Py_ssize_t ring[8]
    cdef Py_ssize_t begin[4]
    cdef Py_ssize_t end[4]
    cdef Py_ssize_t i, j, p, row_end
    cdef int c, it, k, code, changed, odd_row
    cdef Py_ssize_t q
    cdef Py_ssize_t* by_class
    cdef unsigned char* cls
    if n == 0 or max_iter <= 0:
        return 0
    _ring(stride, ring)
    by_class = <Py_ssize_t*>malloc(n * sizeof(Py_ssize_t))
    cls = <unsigned char*>malloc(n)
    if by_class == NULL or cls == NULL:
        free(by_class)
        free(cls)
        return -1
    for c in range(4):
        end[c] = 0
    odd_row = 0
    row_end = stride
    for i in range(n):  # ascending pixels: follow the row without a division
        p = pixels[i]
        while p >= row_end:
            row_end += stride
            odd_row ^= 1
        c = odd_row * 2 + <int>(p & 1)
        cls[i] = c
        end[c] += 1
    j = 0
    for c in range(4):
        begin[c] = j
        j += end[c]
        end[c] = begin[c]
    for i in range(n):
        c = cls[i]
        by_class[end[c]] = pixels[i]
        end[c] += 1
    free(cls)
    for it in range(max_iter):
        changed = 0
        for c in range(4):
            j = begin[c]
            for i in range(begin[c], end[c]):
                p = by_class[i]
                by_class[j] = p  # kept pixels move to the front of their class
                j += 1
                if it > 0 and pad[p] == EDGE:
                    continue  # no neighbour removed since this pixel was last kept
                code = 0
                for k in range(8):
                    code = code | ((pad[p + ring[k]] != 0) << k)
                if not removable[code]:
                    pad[p] = EDGE
                    continue
                pad[p] = 0
                j -= 1
                changed = 1
                for k in range(8):
                    q = p + ring[k]
                    pad[q] = pad[q] | (DIRTY if pad[q] != 0 else 0)
            end[c] = j
        if not changed:
            break
    for c in range(4):  # marks set after a pixel's last decision
        for i in range(begin[c], end[c]):
            pad[by_class[i]] = EDGE
    free(by_class)
    return 0


def thin(unsigned char[:, ::1] padded, const unsigned char[::1] removable, int max_iter) -> None:
    """Thin a padded 0/1 edge map in place (its one-pixel border must be zero).

    Parameters
    ----------
    padded : uint8 (H+2)x(W+2), C-contiguous, 0/1
    removable : uint8 (256,), 1 where the 3x3 neighbourhood code makes the centre removable
    max_iter : maximum number of passes over the four classes
    """
    cdef Py_ssize_t h = padded.shape[0], w = padded.shape[1]
    cdef Vec pixels
    cdef int status = 0
    if removable.shape[0] != 256:
        raise ValueError("thin needs a removable table of 256 entries")
    if h < 3 or w < 3:
        return
    with nogil:
        _init(&pixels, 1024)
        if not pixels.failed:
            status = _collect(&padded[1, 1], h - 2, w - 2, w, &padded[0, 0], w, &pixels)
        if status == 0:
            status = _thin(&padded[0, 0], w, pixels.data, pixels.size, &removable[0], max_iter)
        free(pixels.data)
        status = -1 if pixels.failed else status
    if status < 0:
        raise MemoryError("thin: out of memory")


# ---------------------------------------------------------------------------------------------
# tracing and chains


cdef void _trace_outer(
    const unsigned char* pad, Py_ssize_t start, const Py_ssize_t* deltas, Vec* trace
) noexcept nogil:
    """Outer border of the component whose first pixel (raster order) is ``start``.

    Suzuki and Abe's border following as ``cv2.findContours`` runs it: ``deltas`` are the
    offsets of the directions E, NE, N, NW, W, SW, S, SE, twice. The first neighbour is
    searched clockwise from W, the following ones counterclockwise from the pixel we came from;
    the trace stops on returning to the start from that first neighbour.
    """
    cdef int s = 4
    cdef Py_ssize_t i0 = start, i1, i3, i4
    trace.size = 0
    while True:
        s = (s - 1) & 7
        i1 = i0 + deltas[s]
        if pad[i1] != 0 or s == 4:
            break
    if s == 4:  # a single pixel
        _push(trace, i0)
        return
    i3 = i0
    while True:
        while True:  # ends within 8 steps: the pixel we came from is nonzero
            s += 1
            i4 = i3 + deltas[s]
            if pad[i4] != 0:
                break
        s &= 7
        _push(trace, i3)
        if (i4 == i0 and i3 == i1) or trace.failed:
            break
        i3 = i4
        s = (s + 4) & 7


cdef Py_ssize_t _chain(
    unsigned char* mark, const Py_ssize_t* t, Py_ssize_t n, Py_ssize_t* out
) noexcept nogil:
    """Write the chain of trace ``t`` (``traces_to_chains``) to ``out``; return its length.

    ``mark`` holds SEEN at pixels emitted by earlier traces (they are not emitted again);
    pixels of this trace get SEEN. A trace with fewer than 3/4 of its points new (an open
    chain traced out and back) starts at its first turnaround ``t[i - 1] == t[i + 1]``.
    """
    cdef Py_ssize_t i, p, unique = 0, rotation = 0, count = 0
    for i in range(n):
        p = t[i]
        if mark[p] & (IN_TRACE | SEEN) == 0:
            mark[p] = mark[p] | IN_TRACE
            unique += 1
    if n > 2 and unique < 0.75 * n:
        # the first i with t[i - 1] == t[i + 1] (indices mod n); none: no rotation
        if t[n - 1] == t[1]:
            rotation = 0
        else:
            rotation = n - 1 if t[n - 2] == t[0] else 0
            for i in range(1, n - 1):
                if t[i - 1] == t[i + 1]:
                    rotation = i
                    break
    for i in range(n):
        p = t[i + rotation - (n if i + rotation >= n else 0)]
        if mark[p] & IN_TRACE:
            mark[p] = (mark[p] & ~IN_TRACE) | SEEN
            out[count] = p
            count += 1
    return count


cdef Py_ssize_t _component(
    unsigned char* pad, Py_ssize_t start, const Py_ssize_t* ring, Vec* stack
) noexcept nogil:
    """Mark the 8-connected component of ``start`` DONE; return its number of pixels."""
    cdef Py_ssize_t p, q, size = 1
    cdef unsigned int todo
    cdef unsigned char v
    cdef int k
    stack.size = 0
    pad[start] = pad[start] | DONE
    _push(stack, start)
    while stack.size > 0:
        stack.size -= 1
        p = stack.data[stack.size]
        todo = 0  # neighbours on an edge and not yet marked, as bits (no branch per neighbour)
        for k in range(8):
            v = pad[p + ring[k]]
            todo = todo | (<unsigned int>((v != 0) & ((v & DONE) == 0)) << k)
        while todo != 0:
            q = p + ring[_ctz(todo)]
            todo &= todo - 1
            pad[q] = pad[q] | DONE
            size += 1
            _push(stack, q)
    return size


# ---------------------------------------------------------------------------------------------
# per-point gradient and sub-pixel refinement


cdef inline float _magnitude(short a, short b) noexcept nogil:
    """float32 hypot of two int16 values (as numpy's: exact square sum, one rounding)."""
    cdef double fa = a, fb = b
    return <float>sqrt(fa * fa + fb * fb)


cdef inline void _sample(
    const short* gx, const short* gy, Py_ssize_t h, Py_ssize_t w, Py_ssize_t x, Py_ssize_t y,
    bint subpixel, double* out_point, float* out_grad,
) noexcept nogil:
    """Gradient at pixel (x, y) and, if ``subpixel``, its Devernay position (float32 steps).

    ``gx``, ``gy``: C-contiguous HxW. Along x or y (whichever is closer to the gradient), the
    vertex of the parabola through the magnitudes at the pixel and its two neighbours, if the
    pixel is a strict maximum there and both neighbours are inside the image; at most 0.5 px.
    """
    cdef Py_ssize_t at = y * w + x, step
    cdef short ax = gx[at], ay = gy[at]
    cdef bint along_x
    cdef float m0, mm, mp, denom, offset
    out_grad[0] = ax
    out_grad[1] = ay
    out_point[0] = x
    out_point[1] = y
    if not subpixel:
        return
    along_x = (ax if ax >= 0 else -ax) >= (ay if ay >= 0 else -ay)
    if along_x:
        if x < 1 or x + 1 >= w:
            return
        step = 1
    else:
        if y < 1 or y + 1 >= h:
            return
        step = w
    m0 = _magnitude(ax, ay)
    mm = _magnitude(gx[at - step], gy[at - step])
    mp = _magnitude(gx[at + step], gy[at + step])
    denom = mm - <float>2.0 * m0
    denom = denom + mp
    if not denom < 0:
        return
    offset = <float>0.5 * (mm - mp)
    offset = offset / denom
    offset = <float>0.5 if offset > <float>0.5 else offset
    offset = <float>-0.5 if offset < <float>-0.5 else offset
    if along_x:
        out_point[0] = <double>x + <double>offset
    else:
        out_point[1] = <double>y + <double>offset


def sample(
    const int[:, ::1] points, const short[:, ::1] gx, const short[:, ::1] gy, bint subpixel,
    double[:, ::1] out_points, float[:, ::1] out_gradients,
) -> None:
    """Gradient (and sub-pixel position) at integer points ``(x, y)`` inside the image.

    Parameters
    ----------
    points : int32 (N, 2), every point inside ``gx``
    gx, gy : int16 HxW gradient
    subpixel : refine the positions (else ``out_points`` = ``points``)
    out_points : float64 (N, 2), written
    out_gradients : float32 (N, 2), written
    """
    cdef Py_ssize_t n = points.shape[0], h = gx.shape[0], w = gx.shape[1], i
    if out_points.shape[0] != n or out_gradients.shape[0] != n or gy.shape[0] != h \
            or gy.shape[1] != w:
        raise ValueError("sample: outputs must have one row per point, gx and gy one shape")
    if n == 0:
        return
    with nogil:  # one thread: ~10 ns a point, too short to be worth a parallel region
        for i in range(n):
            _sample(&gx[0, 0], &gy[0, 0], h, w, points[i, 0], points[i, 1], subpixel,
                    &out_points[i, 0], &out_gradients[i, 0])


# ---------------------------------------------------------------------------------------------
# the batch entry points


cdef void _emit_pixels(
    const Py_ssize_t* chain_points, const Py_ssize_t* starts, Py_ssize_t n_chains, bint reverse,
    Py_ssize_t stride, Py_ssize_t shift, int[:, ::1] points, long long[::1] offsets,
) noexcept nogil:
    """Chains as (x, y) pixels with offsets, in the stored or in the reverse chain order."""
    cdef Py_ssize_t k, src, i, j = 0, p, y
    cdef double inverse = 1.0 / stride
    offsets[0] = 0
    for k in range(n_chains):
        src = n_chains - 1 - k if reverse else k
        for i in range(starts[src], starts[src + 1]):
            p = chain_points[i]
            y = _row_of(p, stride, inverse)
            points[j, 0] = <int>(p - y * stride - shift)
            points[j, 1] = <int>(y - shift)
            j += 1
        offsets[k + 1] = j


cdef void _sample_points(
    const Py_ssize_t* points, Py_ssize_t begin, Py_ssize_t end, Py_ssize_t stride,
    const short* gx, const short* gy, Py_ssize_t h, Py_ssize_t w, bint subpixel,
    double* out_points, float* out_gradients,
) noexcept nogil:
    """``_sample`` at the padded indices ``points[begin:end]`` (one-pixel border), written to
    rows ``begin:end`` of ``out_points`` and ``out_gradients`` (N x 2 each).

    The gradient at a point and at its neighbours above and below is prefetched AHEAD points
    early: a chain wanders over the image, so its points' rows are mostly not in cache and the
    loop would otherwise wait on memory.
    """
    cdef Py_ssize_t i, p, y
    cdef double inverse = 1.0 / stride
    for i in range(begin, end):
        if i + AHEAD < end:
            p = points[i + AHEAD]
            y = _row_of(p, stride, inverse) - 1  # image row and index of that point
            p = p - (y + 1) * stride - 1 + y * w
            _prefetch(gx + p)
            _prefetch(gy + p)
            if 0 < y < h - 1:
                _prefetch(gx + p - w)
                _prefetch(gy + p - w)
                _prefetch(gx + p + w)
                _prefetch(gy + p + w)
        p = points[i]
        y = _row_of(p, stride, inverse)
        _sample(gx, gy, h, w, p - y * stride - 1, y - 1, subpixel, out_points + 2 * i,
                out_gradients + 2 * i)


def link(
    const unsigned char[:, ::1] edges, unsigned char[:, ::1] work,
    const unsigned char[::1] removable, int max_iter, Py_ssize_t min_length,
    Py_ssize_t max_length, const short[:, ::1] gx=None, const short[:, ::1] gy=None,
    bint subpixel=False,
):
    """Thin, trace and chain the edge map; see the module docstring.

    Parameters
    ----------
    edges : uint8 HxW, nonzero on edges
    work : uint8 (H+2)x(W+2), all zero; left all zero
    removable : uint8 (256,) thinning table
    max_iter : thinning passes
    min_length, max_length : keep chains with that many pixels (max < 0: no limit)
    gx, gy : int16 HxW gradient, or None
    subpixel : with ``gx``, ``gy``: refine the points

    Returns
    -------
    Without a gradient ``(points, offsets)``: int32 (N, 2) pixels ``(x, y)``, int64 (K+1,).
    With one ``(points, offsets, gradients, closed)``: float64 (N, 2), int64 (K+1,),
    float32 (N, 2), bool (K,) (first and last pixel 8-neighbours, more than two pixels).
    """
    cdef Py_ssize_t h = edges.shape[0], w = edges.shape[1], stride = w + 2
    cdef Py_ssize_t i, k, p, n, size, n_chains = 0, total = 0, j, first, last
    cdef Py_ssize_t ring[8]
    cdef Py_ssize_t deltas[16]
    cdef bint with_gradient = gx is not None
    cdef unsigned char* pad
    cdef Vec pixels, trace, stack, chains, starts
    cdef int status = 0
    cdef Py_ssize_t* ordered = NULL
    cdef int[:, ::1] out_pixels
    cdef double[:, ::1] out_points
    cdef float[:, ::1] out_gradients
    cdef long long[::1] out_offsets
    cdef unsigned char[::1] out_closed
    if work.shape[0] != h + 2 or work.shape[1] != w + 2:
        raise ValueError("link: the work map must be (H+2)x(W+2)")
    if removable.shape[0] != 256:
        raise ValueError("link needs a removable table of 256 entries")
    if with_gradient and (
        gy is None or gx.shape[0] != h or gx.shape[1] != w or gy.shape[0] != h
        or gy.shape[1] != w
    ):
        raise ValueError("link: gx and gy must both have the shape of the edge map")
    pad = &work[0, 0]
    _ring(stride, ring)
    for k in range(8):  # E, NE, N, NW, W, SW, S, SE: the ring read backwards from E
        deltas[k] = ring[(10 - k) & 7]
        deltas[k + 8] = deltas[k]
    with nogil:
        _init(&pixels, 4096)
        _init(&trace, 4096)
        _init(&stack, 1024)
        _init(&starts, 256)
        chains.data = NULL
        chains.failed = 1
        status = -1
        if not (pixels.failed or trace.failed or stack.failed or starts.failed):
            status = _collect(&edges[0, 0], h, w, w, pad, stride, &pixels)
            if status == 0:
                status = _thin(pad, stride, pixels.data, pixels.size, &removable[0], max_iter)
        if status == 0:
            _init(&chains, pixels.size)
            status = -1 if chains.failed else 0
        if status == 0:
            _push(&starts, 0)
            for i in range(pixels.size):
                p = pixels.data[i]
                if pad[p] != EDGE:  # removed by thinning, or in a component already linked
                    continue
                size = _component(pad, p, ring, &stack)
                if size < min_length:  # a chain has at most as many pixels as its component
                    continue
                _trace_outer(pad, p, deltas, &trace)
                if trace.failed:
                    break
                n = _chain(pad, trace.data, trace.size, chains.data + total)
                if n >= min_length and (max_length < 0 or n <= max_length):
                    total += n
                    n_chains += 1
                    _push(&starts, total)
            if trace.failed or stack.failed or starts.failed:
                status = -1
        for i in range(pixels.size):
            pad[pixels.data[i]] = 0
        free(pixels.data)
        free(trace.data)
        free(stack.data)
    if status < 0:
        free(chains.data)
        free(starts.data)
        raise MemoryError("link: out of memory")
    try:
        offsets = np.empty(n_chains + 1, np.int64)
        out_offsets = offsets
        if not with_gradient:
            pixels_out = np.empty((total, 2), np.int32)
            out_pixels = pixels_out
            with nogil:
                _emit_pixels(chains.data, starts.data, n_chains, True, stride, 1, out_pixels,
                             out_offsets)
            return pixels_out, offsets
        points = np.empty((total, 2), np.float64)
        gradients = np.empty((total, 2), np.float32)
        closed = np.empty(n_chains, np.bool_)
        out_points = points
        out_gradients = gradients
        out_closed = closed.view(np.uint8)
        with nogil:
            ordered = <Py_ssize_t*>malloc((total + 1) * sizeof(Py_ssize_t))
            if ordered != NULL:
                out_offsets[0] = 0
                j = 0
                for k in range(n_chains):
                    i = n_chains - 1 - k
                    n = starts.data[i + 1] - starts.data[i]
                    memcpy(ordered + j, chains.data + starts.data[i], n * sizeof(Py_ssize_t))
                    first = ordered[j]
                    last = ordered[j + n - 1]
                    j += n
                    out_offsets[k + 1] = j
                    out_closed[k] = n > 2 and -1 <= first % stride - last % stride <= 1 \
                        and -1 <= first // stride - last // stride <= 1
                _sample_points(ordered, 0, total, stride, &gx[0, 0], &gy[0, 0], h, w, subpixel,
                               &out_points[0, 0], &out_gradients[0, 0])
        if ordered == NULL:
            raise MemoryError("link: out of memory")
        return points, offsets, gradients, closed
    finally:
        free(ordered)
        free(chains.data)
        free(starts.data)


def chains_from_traces(
    const int[:, ::1] points, const long long[::1] lengths, Py_ssize_t width,
    Py_ssize_t min_length, Py_ssize_t max_length,
):
    """``traces_to_chains`` on concatenated traces ``(x, y)`` with the given lengths.

    Returns int32 (N, 2) pixels and int64 (K+1,) offsets of the chains kept
    (``min_length <= n <= max_length``; ``max_length < 0``: no limit), in the order of the
    traces. A pixel is emitted only at its first visit over all traces, in trace order.
    """
    cdef Py_ssize_t n_traces = lengths.shape[0], m = points.shape[0], i, k, n, start = 0
    cdef Py_ssize_t top = 0, total = 0, n_chains = 0, stride = width
    cdef Py_ssize_t* lin
    cdef Py_ssize_t* chain_points
    cdef Vec starts
    cdef unsigned char[::1] mark
    cdef int[:, ::1] out_pixels
    cdef long long[::1] out_offsets
    for k in range(n_traces):
        start += lengths[k]
    if start != m:
        raise ValueError(f"chains_from_traces: lengths sum to {start}, not to {m} points")
    for i in range(m):
        if points[i, 0] < 0 or points[i, 1] < 0 or points[i, 0] >= width:
            raise ValueError("chains_from_traces: points must lie in 0 <= x < width, 0 <= y")
        top = max(top, points[i, 1] * width + points[i, 0])
    mark = np.zeros(top + 1, np.uint8)  # calloc'ed: only the pages touched cost
    lin = <Py_ssize_t*>malloc((m + 1) * sizeof(Py_ssize_t))
    chain_points = <Py_ssize_t*>malloc((m + 1) * sizeof(Py_ssize_t))
    _init(&starts, n_traces + 1)
    try:
        if lin == NULL or chain_points == NULL or starts.failed:
            raise MemoryError("chains_from_traces: out of memory")
        with nogil:
            for i in range(m):
                lin[i] = <Py_ssize_t>points[i, 1] * width + points[i, 0]
            _push(&starts, 0)
            start = 0
            for k in range(n_traces):
                n = _chain(&mark[0], lin + start, lengths[k], chain_points + total)
                start += lengths[k]
                if n >= min_length and (max_length < 0 or n <= max_length):
                    total += n
                    n_chains += 1
                    _push(&starts, total)
        pixels_out = np.empty((total, 2), np.int32)
        offsets = np.empty(n_chains + 1, np.int64)
        out_pixels = pixels_out
        out_offsets = offsets
        with nogil:
            _emit_pixels(chain_points, starts.data, n_chains, False, stride, 0, out_pixels,
                         out_offsets)
        return pixels_out, offsets
    finally:
        free(lin)
        free(chain_points)
        free(starts.data)
