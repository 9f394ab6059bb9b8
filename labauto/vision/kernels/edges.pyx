# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
# distutils: extra_compile_args = -fno-math-errno -fno-trapping-math
"""Edge linking kernel (section 3.1): thinning, outer border tracing, ordered chains, sub-pixel.

See :mod:`labauto.vision.edges` for the definitions. One call of :func:`link` goes from a Canny
edge map to the finished chains:

1. collecting (``_collect``): a row's edge pixels are found 64 at a time (a bit mask of the
   nonzero bytes, then its set bits: an edge map is ~1 % edges, in short runs, and a per-byte
   loop spends its time on mispredicted branches), set in a zeroed padded work map (one-pixel
   zero border, so a 3x3 neighbourhood needs no bounds check) and listed row by row;
2. thinning (``_thin``), as ``thin_edges``: pixels decided in checkerboard classes, class by
   class and pass by pass. A pixel's decision reads only its row and the two next to it, so
   one sweep down the rows decides a row's two classes of pass ``it`` together ("row step"
   ``K = 2 it + row parity``) once the rows above and below are at step ``K - 1`` and not yet
   at ``K + 1``: row ``y`` takes step ``K`` in round ``y + 2 K``. Every pixel is then decided on
   the same neighbourhood as in the class-by-class order, so the result is the same, with the
   work confined to a few rows. A decision looks the 3x3 neighbourhood up as a 9-bit index
   (three 4-byte loads, no loop over the neighbours). In pass ``it > 0`` only pixels next to a
   removal (marked DIRTY) are decided again: the others would be kept as before;
3. every 8-connected component is marked from where it is met (flood fill, which also finds
   its first pixel in raster order), then gets the outer border trace of Suzuki and Abe, step
   for step as ``cv2.findContours`` (``RETR_CCOMP``, ``CHAIN_APPROX_NONE``) follows it, and the
   trace becomes a chain (``traces_to_chains``: rotated to its first turnaround if traced out
   and back, each pixel at its first visit). Chains are listed in reverse raster order of the
   components' first pixels, as ``findContours`` lists them;
4. optionally the gradient at every point and the Devernay sub-pixel position (float32
   arithmetic, as the numpy formulation of ``refine_subpixel``): a scalar loop gathers the
   gradients a point needs, with those of the point AHEAD further prefetched (a chain wanders
   over the image: without the prefetch the loop mostly waits on memory), then a vectorised
   loop does the arithmetic.

One thread does it all: on a 2-core machine shared with OpenCV a pipeline that sampled the
chains on a second thread while the first linked them was 1.8x slower (issue 16).

Buffers that depend on the number of edge pixels live in a :class:`Workspace` the caller keeps
between calls (blocks that large are handed back to the system when freed, so fresh ones cost
page faults), and the work map is left all zero again (only the touched pixels are cleared), so
the caller keeps one per image size too.
"""

from libc.math cimport sqrt
from libc.stdlib cimport free, malloc, realloc
from libc.string cimport memcpy

import numpy as np

cdef enum:
    BLOCK = 64  # sampling: points gathered, then computed vectorised, at a time
    AHEAD = 16  # sampling: prefetch the gradient rows of the point this far ahead


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


cdef inline void _clear(Vec* v) noexcept nogil:
    v.size = 0
    v.failed = 0


cdef inline int _grow(void** buffer, Py_ssize_t* cap, Py_ssize_t size, size_t item) noexcept nogil:
    """Make ``*buffer`` (``*cap`` items of ``item`` bytes) hold at least ``size`` items, keeping
    its contents; -1 when out of memory (the buffer is kept)."""
    cdef Py_ssize_t grown_cap = cap[0] if cap[0] > 16 else 16
    cdef void* grown
    if size <= cap[0]:
        return 0
    while grown_cap < size:
        grown_cap = 2 * grown_cap
    grown = realloc(buffer[0], grown_cap * item)
    if grown == NULL:
        return -1
    buffer[0] = grown
    cap[0] = grown_cap
    return 0


cdef inline Py_ssize_t _row_of(Py_ssize_t p, Py_ssize_t stride, double inverse) noexcept nogil:
    """``p // stride`` for 0 <= p < 2**50 without an integer division (``inverse = 1 / stride``).

    The float estimate is off by at most one either way; two compares correct it.
    """
    cdef Py_ssize_t y = <Py_ssize_t>(<double>p * inverse)
    y -= y * stride > p
    y += (y + 1) * stride <= p
    return y


ctypedef struct Buffers:  # see Workspace
    Vec pixels  # padded indices of the edge pixels, row by row (of the top band)
    Vec chains  # chain pixels, chain after chain (room for all pixels: never moved while shared)
    Vec found  # (first pixel, start in chains, length) per chain, sorted by first pixel
    Vec ordered  # chain pixels in output order (sampled straight into the outputs)
    Vec trace
    Vec stack
    Py_ssize_t* row_start  # pixels of padded row y: pixels[row_start[y]:row_start[y + 1]]
    Py_ssize_t row_cap
    unsigned long long* masks  # one row's bit masks of edge pixels
    Py_ssize_t mask_cap


cdef int _prepare(Buffers* b, Py_ssize_t h, Py_ssize_t w) noexcept nogil:
    """Room for the per-row tables of an HxW map; empty lists. -1 when out of memory."""
    _clear(&b.pixels)  # (after a failed call too: a buffer that failed to grow is kept)
    _clear(&b.chains)
    _clear(&b.found)
    _clear(&b.ordered)
    _clear(&b.trace)
    _clear(&b.stack)
    if _grow(<void**>&b.row_start, &b.row_cap, h + 3, sizeof(Py_ssize_t)) < 0 \
            or _grow(<void**>&b.masks, &b.mask_cap, (w + 63) // 64, sizeof(long long)) < 0:
        return -1
    return 0


cdef int _reserve_links(Buffers* b) noexcept nogil:
    """Room in the chain buffers for every collected pixel; -1 when out of memory."""
    cdef Py_ssize_t n = b.pixels.size
    if _reserve(&b.chains, n) < 0 or _reserve(&b.ordered, n) < 0:
        return -1
    return 0


cdef class Workspace:
    """Buffers of :func:`link` kept between calls (one per thread: a workspace is not shared).

    Their size follows the number of edge pixels. Allocated afresh on every call they would
    cost page faults: the allocator hands blocks that large back to the system when freed.
    """

    cdef Buffers b

    def __cinit__(self):
        _init(&self.b.pixels, 4096)
        _init(&self.b.chains, 4096)
        _init(&self.b.found, 256)
        _init(&self.b.ordered, 4096)
        _init(&self.b.trace, 4096)
        _init(&self.b.stack, 1024)
        self.b.row_start = NULL
        self.b.row_cap = 0
        self.b.masks = NULL
        self.b.mask_cap = 0
        if self.b.pixels.failed or self.b.chains.failed \
                or self.b.found.failed or self.b.ordered.failed \
                or self.b.trace.failed or self.b.stack.failed:
            raise MemoryError("Workspace: out of memory")

    def __dealloc__(self):
        free(self.b.pixels.data)
        free(self.b.chains.data)
        free(self.b.found.data)
        free(self.b.ordered.data)
        free(self.b.trace.data)
        free(self.b.stack.data)
        free(self.b.row_start)
        free(self.b.masks)


# ---------------------------------------------------------------------------------------------
# 3x3 neighbourhoods as bit masks


cdef extern from *:
    """
    #include <string.h>
    static inline int labauto_ctz64(unsigned long long v) { return __builtin_ctzll(v); }

    /* bit k set where p[k] != 0, for the n <= 64 bytes p[0..n-1] (a plain loop the compiler
       vectorises) */
    static inline unsigned long long labauto_nonzero_tail(const unsigned char* p, Py_ssize_t n) {
        unsigned long long found = 0;
        for (Py_ssize_t k = 0; k < n; k++) found |= (unsigned long long)(p[k] != 0) << k;
        return found;
    }
    static inline unsigned long long labauto_nonzero64(const unsigned char* p) {
        return labauto_nonzero_tail(p, 64);
    }

    /* four bytes from p (any alignment), byte k in bits 8k..8k+7 */
    static inline unsigned labauto_load4(const unsigned char* p) {
        unsigned v;
        memcpy(&v, p, 4);
    #if __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
        v = __builtin_bswap32(v);
    #endif
        return v;
    }

    /* a macro, not a function: GCC drops calls of a function whose only effect is a prefetch */
    #define labauto_prefetch(p) __builtin_prefetch(p)
    /* the 9-bit neighbourhood index bit of the ring N, NE, E, SE, S, SW, W, NW (the removable
       table's code) and of the tracer's directions E, NE, N, NW, W, SW, S, SE */
    static const int labauto_ring_bits[8] = {3, 6, 7, 8, 5, 2, 1, 0};
    static const int labauto_direction_bits[8] = {7, 6, 3, 0, 1, 2, 5, 8};
    """
    unsigned long long _nonzero64 "labauto_nonzero64"(const unsigned char* p) noexcept nogil
    unsigned long long _nonzero_tail "labauto_nonzero_tail"(
        const unsigned char* p, Py_ssize_t n) noexcept nogil
    int _ctz "labauto_ctz64"(unsigned long long v) noexcept nogil
    unsigned _load4 "labauto_load4"(const unsigned char* p) noexcept nogil
    void _prefetch "labauto_prefetch"(const void* address) noexcept nogil
    const int* RING_BITS "labauto_ring_bits"
    const int* DIRECTION_BITS "labauto_direction_bits"


# A 3x3 neighbourhood as a 9-bit index: bit 3 c + r is column x - 1 + c, row y - 1 + r (bit 4
# is the centre). Three 4-byte loads give the three rows, the bits are gathered with shifts; a
# table by this index replaces the loop over the eight neighbours.

cdef inline unsigned _edges9(const unsigned char* pad, Py_ssize_t p, Py_ssize_t stride) \
        noexcept nogil:
    """9-bit index of the edge pixels (bit 0 of the map) around padded index ``p``.

    Reads only bytes of the padded map: ``p - stride - 1 .. p - stride + 2``, ``p - 1 .. p + 2``
    and ``p + stride - 2 .. p + stride + 1``. (Not for maps just written nearby: a 4-byte load
    over a byte stored a moment ago waits for the store.)
    """
    cdef unsigned t = (_load4(pad + p - stride - 1) & 0x010101u) \
        | ((_load4(pad + p - 1) & 0x010101u) << 1) \
        | ((_load4(pad + p + stride - 2) & 0x01010100u) >> 6)
    return (t & 7u) | ((t >> 5) & 0x38u) | ((t >> 10) & 0x1C0u)


cdef void _removable9(const unsigned char* removable, unsigned char* removable9) noexcept nogil:
    """The thinning table by 9-bit index (``removable`` is indexed by the ring code: bit k for
    N, NE, E, SE, S, SW, W, NW)."""
    cdef int index, k, code
    for index in range(512):
        code = 0
        for k in range(8):
            code = code | (((index >> RING_BITS[k]) & 1) << k)
        removable9[index] = removable[code]


# ---------------------------------------------------------------------------------------------
# gradient and sub-pixel refinement of a pixel


# Gradient and Devernay position of pixels, BLOCK at a time: ``_gather`` takes a pixel's
# gradients, ``_flush`` computes the gathered ones into rows ``done..`` of the outputs.
ctypedef struct Sampler:
    const short* gx  # H x W
    const short* gy
    Py_ssize_t h
    Py_ssize_t w
    bint subpixel
    double* points  # N x 2: (x, y), refined
    float* gradients  # N x 2: (gx, gy)
    Py_ssize_t done  # outputs written
    int count  # gathered, not yet computed
    short ax[BLOCK]  # gradient at the pixel
    short ay[BLOCK]
    short bx[BLOCK]  # at its neighbour before along the chosen axis (x - 1 or y - 1)
    short by[BLOCK]
    short cx[BLOCK]  # and after
    short cy[BLOCK]
    int px[BLOCK]
    int py[BLOCK]
    unsigned char along_x[BLOCK]


cdef inline float _magnitude(short a, short b) noexcept nogil:
    """float32 hypot of two int16 values (as numpy's: exact square sum, one rounding)."""
    cdef double fa = a, fb = b
    return <float>sqrt(fa * fa + fb * fb)


cdef void _flush(Sampler* s) noexcept nogil:
    """Compute the gathered pixels (see ``_gather``) into the outputs.

    Along x or y (whichever is closer to the gradient; x on ties), the vertex of the parabola
    through the magnitudes at the pixel and its two neighbours, if the pixel is a strict
    maximum there; at most 0.5 px. Float32 steps as ``refine_subpixel``. Written without
    branches, so that it vectorises.
    """
    cdef int i, n = s.count
    cdef float m0, mm, mp, denom, offset, dx, dy
    cdef double* points = s.points + 2 * s.done
    cdef float* gradients = s.gradients + 2 * s.done
    for i in range(n):
        gradients[2 * i] = s.ax[i]
        gradients[2 * i + 1] = s.ay[i]
    if not s.subpixel:
        for i in range(n):
            points[2 * i] = s.px[i]
            points[2 * i + 1] = s.py[i]
    else:
        for i in range(n):
            m0 = _magnitude(s.ax[i], s.ay[i])
            mm = _magnitude(s.bx[i], s.by[i])
            mp = _magnitude(s.cx[i], s.cy[i])
            denom = mm - <float>2.0 * m0
            denom = denom + mp
            offset = <float>0.5 * (mm - mp)
            offset = offset / denom
            offset = <float>0.5 if offset > <float>0.5 else offset
            offset = <float>-0.5 if offset < <float>-0.5 else offset
            offset = offset if denom < 0 else <float>0.0
            dx = offset if s.along_x[i] else <float>0.0
            dy = <float>0.0 if s.along_x[i] else offset
            points[2 * i] = <double>s.px[i] + <double>dx
            points[2 * i + 1] = <double>s.py[i] + <double>dy
    s.done += n
    s.count = 0


cdef inline void _gather(Sampler* s, Py_ssize_t x, Py_ssize_t y) noexcept nogil:
    """Take the gradients pixel (x, y) needs; compute the block when it is full.

    The neighbours are those along x or y, whichever is closer to the gradient. A pixel without
    both of them inside the image uses its own gradient for them: the parabola is then flat
    (its denominator exactly 0) and the pixel stays where it is, as required.
    """
    cdef Py_ssize_t at = y * s.w + x, off
    cdef short a = s.gx[at], b = s.gy[at]
    cdef bint horizontal = (a if a >= 0 else -a) >= (b if b >= 0 else -b)
    cdef int i = s.count
    if horizontal:
        off = 1 if 1 <= x < s.w - 1 else 0
    else:
        off = s.w if 1 <= y < s.h - 1 else 0
    s.ax[i] = a
    s.ay[i] = b
    s.bx[i] = s.gx[at - off]
    s.by[i] = s.gy[at - off]
    s.cx[i] = s.gx[at + off]
    s.cy[i] = s.gy[at + off]
    s.px[i] = <int>x
    s.py[i] = <int>y
    s.along_x[i] = horizontal
    s.count = i + 1
    if s.count == BLOCK:
        _flush(s)


cdef inline void _prefetch_pixel(const Sampler* s, Py_ssize_t x, Py_ssize_t y) noexcept nogil:
    """Prefetch the gradient at (x, y) and above and below it."""
    cdef Py_ssize_t at = y * s.w + x
    _prefetch(s.gx + at)
    _prefetch(s.gy + at)
    if 0 < y < s.h - 1:
        _prefetch(s.gx + at - s.w)
        _prefetch(s.gy + at - s.w)
        _prefetch(s.gx + at + s.w)
        _prefetch(s.gy + at + s.w)


cdef inline void _prefetch_point(
    const Sampler* s, Py_ssize_t p, Py_ssize_t stride, Py_ssize_t shift, double inverse
) noexcept nogil:
    """``_prefetch_pixel`` of a point given as a linear index (rows ``stride`` apart,
    ``inverse = 1 / stride``, a border of ``shift``)."""
    cdef Py_ssize_t y = _row_of(p, stride, inverse)
    _prefetch_pixel(s, p - y * stride - shift, y - shift)


cdef void _sample_run(
    Sampler* s, const Py_ssize_t* points, Py_ssize_t n, Py_ssize_t stride, Py_ssize_t shift
) noexcept nogil:
    """Sample ``n`` points given as linear indices (rows ``stride`` apart, a border of
    ``shift``) into rows ``s.done..`` of the sampler's outputs, prefetching AHEAD points early."""
    cdef Py_ssize_t i, p, y
    cdef double inverse = 1.0 / stride
    for i in range(n):
        if i + AHEAD < n:
            _prefetch_point(s, points[i + AHEAD], stride, shift, inverse)
        p = points[i]
        y = _row_of(p, stride, inverse)
        _gather(s, p - y * stride - shift, y - shift)
    _flush(s)


# ---------------------------------------------------------------------------------------------
# collecting and thinning


cdef inline Py_ssize_t _collect_row(
    const unsigned char* row, Py_ssize_t w, unsigned char* pad, Py_ssize_t at, Py_ssize_t* out,
    unsigned long long* masks,
) noexcept nogil:
    """Set EDGE in ``pad`` at ``at + x`` for every nonzero ``row[x]`` (x < w) and list those
    padded indices in ``out`` (room for ``w``): first the even ones, then the odd ones (the
    row's two checkerboard classes), each ascending. Returns how many.

    64 pixels at a time: a bit mask of the nonzero ones (kept in ``masks``, room for
    ``(w + 63) // 64``), then its set bits of one parity, lowest first. Most blocks of an edge
    map are empty and cost one test.
    """
    cdef Py_ssize_t x, b, n = 0, q, blocks = (w + 63) // 64
    cdef unsigned long long found, even
    cdef int parity
    for b in range(blocks):
        x = 64 * b
        masks[b] = _nonzero64(row + x) if x + 64 <= w else _nonzero_tail(row + x, w - x)
    even = 0x5555555555555555 if at % 2 == 0 else 0xAAAAAAAAAAAAAAAA  # at + x + k even
    for parity in range(2):
        for b in range(blocks):
            found = masks[b] & (even if parity == 0 else ~even)
            while found != 0:
                q = at + 64 * b + _ctz(found)
                pad[q] = EDGE
                out[n] = q
                n += 1
                found &= found - 1
    return n


cdef inline void _thin_row(
    unsigned char* pad, Py_ssize_t stride, const Py_ssize_t* pixels, Py_ssize_t begin,
    Py_ssize_t end, const unsigned char* removable9, const Py_ssize_t* offsets9,
    bint first_pass,
) noexcept nogil:
    """One row step of the thinning: decide the row's pixels ``pixels[begin:end]`` (its even
    class, then its odd class, as ``_collect_row`` lists them).

    Pixels of one class are never neighbours, so deciding them one after the other in place is
    deciding them at once. Removed pixels (0) are skipped; after the first pass so are pixels
    kept since no neighbour was removed (EDGE without DIRTY): the table would answer the same.
    A removal marks the neighbours DIRTY; a kept pixel is set back to plain EDGE (only if it was
    DIRTY: a store there would hold up the next pixel's loads).
    """
    cdef Py_ssize_t i, p, q
    cdef unsigned around
    cdef unsigned char v
    for i in range(begin, end):
        p = pixels[i]
        v = pad[p]
        if v == 0 or (v == EDGE and not first_pass):
            continue
        around = _edges9(pad, p, stride)
        if not removable9[around]:
            if v != EDGE:
                pad[p] = EDGE
            continue
        pad[p] = 0
        around &= ~16u  # the neighbours
        while around != 0:
            q = p + offsets9[_ctz(around)]
            around &= around - 1
            pad[q] = pad[q] | DIRTY


cdef int _collect(
    const unsigned char* edges, Py_ssize_t r0, Py_ssize_t r1, Py_ssize_t w, Py_ssize_t step,
    unsigned char* pad, Py_ssize_t stride, Vec* pixels, Py_ssize_t* row_start,
    unsigned long long* masks,
) noexcept nogil:
    """Set EDGE at every nonzero pixel of image rows ``r0..r1 - 1`` of ``edges`` (rows ``step``
    bytes apart; padded rows ``r0 + 1..r1``) in the padded map and list them in ``pixels``, row
    by row (in a row: even padded indices, then odd); padded row ``y`` is
    ``pixels[row_start[y]:row_start[y + 1]]``. Returns -1 when out of memory.
    """
    cdef Py_ssize_t r
    pixels.size = 0
    row_start[r0 + 1] = 0
    for r in range(r0, r1):
        if _reserve(pixels, pixels.size + w) < 0:
            return -1
        pixels.size += _collect_row(edges + r * step, w, pad, (r + 1) * stride + 1,
                                    pixels.data + pixels.size, masks)
        row_start[r + 2] = pixels.size
    return 0


cdef void _thin(
    unsigned char* pad, Py_ssize_t stride, Py_ssize_t h, int max_iter, const Buffers* ws,
    const unsigned char* removable9,
) noexcept nogil:
    """The thinning (see the module docstring): in round ``r`` every padded row ``y`` with
    ``y + 2 K = r`` takes row step ``K`` (``K = 2 it + y % 2``, ``it < max_iter``); the rows'
    pixels are listed in ``ws.pixels``."""
    cdef Py_ssize_t offsets9[9]
    cdef Py_ssize_t r, y, k, steps = 2 * max(max_iter, 0)
    for k in range(9):
        offsets9[k] = (k % 3 - 1) * stride + k // 3 - 1
    for r in range(2, h + 2 * steps):
        k = r & 1  # row step K of padded row r - 2 K: K has the parity of the row, so of r
        while k < steps:
            y = r - 2 * k
            if y < 1:
                break
            if y <= h:
                _thin_row(pad, stride, ws.pixels.data, ws.row_start[y], ws.row_start[y + 1],
                          removable9, offsets9, k < 2)
            k += 2


def thin(unsigned char[:, ::1] padded, const unsigned char[::1] removable, int max_iter) -> None:
    """Thin a padded 0/1 edge map in place (its one-pixel border must be zero).

    Parameters
    ----------
    padded : uint8 (H+2)x(W+2), C-contiguous, 0/1
    removable : uint8 (256,), 1 where the 3x3 neighbourhood code makes the centre removable
    max_iter : maximum number of passes over the four classes
    """
    cdef Py_ssize_t h = padded.shape[0], w = padded.shape[1], i
    cdef unsigned char* pad
    cdef unsigned char removable9[512]
    cdef Workspace workspace
    cdef Buffers* ws
    cdef int status = 0
    if removable.shape[0] != 256:
        raise ValueError("thin needs a removable table of 256 entries")
    if h < 3 or w < 3:
        return
    workspace = Workspace()
    ws = &workspace.b
    pad = &padded[0, 0]
    with nogil:
        _removable9(&removable[0], removable9)
        status = _prepare(ws, h - 2, w - 2)
        if status == 0:
            status = _collect(&padded[1, 1], 0, h - 2, w - 2, w, pad, w, &ws.pixels, ws.row_start,
                              ws.masks)
        if status == 0:
            _thin(pad, w, h - 2, max_iter, ws, removable9)
        for i in range(ws.pixels.size):  # drop the DIRTY marks
            pad[ws.pixels.data[i]] = pad[ws.pixels.data[i]] != 0
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
    the trace stops on returning to the start from that first neighbour. (A probe loop: its
    exits are mostly predicted, so the loads of the next steps start early; a lookup of the
    neighbourhood's bit mask instead makes every step wait for the last.)
    """
    cdef Vec t = trace[0]  # (a local copy: its fields stay in registers; given back below)
    cdef int s = 4
    cdef Py_ssize_t i0 = start, i1, i3, i4
    t.size = 0
    while True:
        s = (s - 1) & 7
        i1 = i0 + deltas[s]
        if pad[i1] != 0 or s == 4:
            break
    if s == 4:  # a single pixel
        _push(&t, i0)
        trace[0] = t
        return
    i3 = i0
    while True:
        while True:  # ends within 8 steps: the pixel we came from is nonzero
            s += 1
            i4 = i3 + deltas[s]
            if pad[i4] != 0:
                break
        s &= 7
        _push(&t, i3)
        if (i4 == i0 and i3 == i1) or t.failed:
            break
        i3 = i4
        s = (s + 4) & 7
    trace[0] = t


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
    unsigned char* pad, const Py_ssize_t* ring, Py_ssize_t start, Vec* stack_buffer,
    Py_ssize_t* first,
) noexcept nogil:
    """Mark the 8-connected component of ``start`` DONE; return its number of pixels and set
    ``first`` to its smallest padded index.

    The stack and the ring offsets are local copies (the stack is given back at the end): the
    marks are byte stores, which may alias anything, so values behind a pointer would be read
    again from memory after every mark. Byte loads here, not ``_edges9``: marks just stored
    would hold up wider loads.
    """
    cdef Vec stack = stack_buffer[0]
    cdef Py_ssize_t around[8]  # (a local copy too: registers)
    cdef Py_ssize_t p, q, size = 1, smallest = start
    cdef unsigned todo
    cdef unsigned char v
    cdef int k
    for k in range(8):
        around[k] = ring[k]
    stack.size = 0
    pad[start] = pad[start] | DONE
    _push(&stack, start)
    while stack.size > 0:
        stack.size -= 1
        p = stack.data[stack.size]
        todo = 0  # neighbours on an edge and not yet marked, as bits (no branch per neighbour)
        for k in range(8):
            v = pad[p + around[k]]
            todo = todo | (<unsigned>((v != 0) & ((v & DONE) == 0)) << k)
        while todo != 0:
            q = p + around[_ctz(todo)]
            todo &= todo - 1
            pad[q] = pad[q] | DONE
            smallest = q if q < smallest else smallest
            size += 1
            _push(&stack, q)
    stack_buffer[0] = stack
    first[0] = smallest
    return size


cdef int _link_chains(
    unsigned char* pad, Py_ssize_t stride, Buffers* ws, Py_ssize_t min_length,
    Py_ssize_t max_length,
) noexcept nogil:
    """Trace and chain every component of the thinned map (``ws.pixels``) with at least
    ``min_length`` pixels (a chain has at most as many pixels as its component); keep the
    chains of ``min_length`` to ``max_length`` points (``max_length < 0``: no limit).

    The chains' pixels go to ``ws.chains`` (room reserved for all pixels), one chain after the
    other; ``ws.found`` gets three values per chain, sorted by the first: the component's first
    pixel (smallest padded index), where the chain starts in ``ws.chains`` and its length;
    Returns -1 when out of memory.

    Components are met row by row (``pixels`` lists a row's even indices before its odd ones):
    all of a component's pixels lie in or below the row it is met in, so its first pixel is the
    smallest index of the flood fill, and only components met in one row can be out of order.
    """
    cdef Py_ssize_t deltas[16]
    cdef Py_ssize_t ring[8]
    cdef Py_ssize_t i, k, p, n, size, first, total = 0
    cdef Py_ssize_t n_pixels  # (locals: the marks are byte stores, which may alias anything
    cdef const Py_ssize_t* pixels  # behind a pointer)
    cdef Py_ssize_t* chains = ws.chains.data
    cdef Vec* found = &ws.found
    cdef unsigned char v
    cdef int status = 0
    for k in range(8):  # E, NE, N, NW, W, SW, S, SE
        deltas[k] = (DIRECTION_BITS[k] % 3 - 1) * stride + DIRECTION_BITS[k] // 3 - 1
        deltas[k + 8] = deltas[k]
        ring[k] = deltas[k]
    n_pixels = ws.pixels.size
    pixels = ws.pixels.data
    for i in range(n_pixels):
        p = pixels[i]
        v = pad[p]
        if v == 0 or v & DONE:  # removed by thinning, or in a component marked
            continue
        size = _component(pad, ring, p, &ws.stack, &first)
        if size < min_length or ws.stack.failed:
            continue
        _trace_outer(pad, first, deltas, &ws.trace)
        if ws.trace.failed or _reserve(found, found.size + 3) < 0:
            break
        n = _chain(pad, ws.trace.data, ws.trace.size, chains + total)
        if n < min_length or (max_length >= 0 and n > max_length):
            continue
        k = found.size  # insert by first pixel (only within this row's components)
        while k > 0 and found.data[k - 3] > first:
            found.data[k] = found.data[k - 3]
            found.data[k + 1] = found.data[k - 2]
            found.data[k + 2] = found.data[k - 1]
            k -= 3
        found.data[k] = first
        found.data[k + 1] = total
        found.data[k + 2] = n
        found.size += 3
        total += n
    ws.chains.size = total
    if ws.stack.failed or ws.trace.failed or found.failed:
        status = -1
    return status


# ---------------------------------------------------------------------------------------------
# the batch entry points


cdef void _emit_pixels(
    const Py_ssize_t* chain_points, Py_ssize_t n, Py_ssize_t stride, Py_ssize_t shift,
    int* points,
) noexcept nogil:
    """``n`` points given as linear indices (row ``stride``, a border of ``shift``) as (x, y)
    rows of ``points``."""
    cdef Py_ssize_t i, p, y
    cdef double inverse = 1.0 / stride
    for i in range(n):
        p = chain_points[i]
        y = _row_of(p, stride, inverse)
        points[2 * i] = <int>(p - y * stride - shift)
        points[2 * i + 1] = <int>(y - shift)


cdef inline void _start_sampler(
    Sampler* s, const short* gx, const short* gy, Py_ssize_t h, Py_ssize_t w, bint subpixel,
    double* points, float* gradients,
) noexcept nogil:
    s.gx = gx
    s.gy = gy
    s.h = h
    s.w = w
    s.subpixel = subpixel
    s.points = points
    s.gradients = gradients
    s.done = 0
    s.count = 0


def link(
    const unsigned char[:, ::1] edges, unsigned char[:, ::1] work,
    const unsigned char[::1] removable, int max_iter, Py_ssize_t min_length,
    Py_ssize_t max_length, const short[:, ::1] gx=None, const short[:, ::1] gy=None,
    bint subpixel=False, Workspace workspace=None,
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
    workspace : buffers kept between calls (None: fresh ones)

    Returns
    -------
    Without a gradient ``(points, offsets)``: int32 (N, 2) pixels ``(x, y)``, int64 (K+1,).
    With one ``(points, offsets, gradients, closed)``: float64 (N, 2), int64 (K+1,),
    float32 (N, 2), bool (K,) (first and last pixel 8-neighbours, more than two pixels).
    """
    cdef Py_ssize_t h = edges.shape[0], w = edges.shape[1], stride = w + 2
    cdef Py_ssize_t i, k, n, at, n_chains, total, first, last
    cdef bint with_gradient = gx is not None
    cdef unsigned char* pad
    cdef unsigned char removable9[512]
    cdef Buffers* ws
    cdef Sampler sampler
    cdef int status = 0
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
    if workspace is None:
        workspace = Workspace()
    ws = &workspace.b
    pad = &work[0, 0]
    with nogil:
        _removable9(&removable[0], removable9)
        status = _prepare(ws, h, w)
        if status == 0:
            status = _collect(&edges[0, 0], 0, h, w, w, pad, stride, &ws.pixels, ws.row_start,
                              ws.masks)
        if status == 0:
            _thin(pad, stride, h, max_iter, ws, removable9)
            status = _reserve_links(ws)
        if status == 0:
            status = _link_chains(pad, stride, ws, min_length, max_length)
        for i in range(ws.pixels.size):
            pad[ws.pixels.data[i]] = 0
    if status < 0:
        raise MemoryError("link: out of memory")
    n_chains = ws.found.size // 3  # output order: the reverse of ``found``
    total = ws.chains.size
    offsets = np.empty(n_chains + 1, np.int64)
    out_offsets = offsets
    with nogil:
        out_offsets[0] = 0
        for k in range(n_chains):
            out_offsets[k + 1] = out_offsets[k] + ws.found.data[3 * (n_chains - 1 - k) + 2]
    if not with_gradient:
        pixels_out = np.empty((total, 2), np.int32)
        out_pixels = pixels_out
        with nogil:
            for k in range(n_chains):
                _emit_pixels(ws.chains.data + ws.found.data[3 * (n_chains - 1 - k) + 1],
                             out_offsets[k + 1] - out_offsets[k], stride, 1,
                             &out_pixels[out_offsets[k], 0])
        return pixels_out, offsets
    points = np.empty((total, 2), np.float64)
    gradients = np.empty((total, 2), np.float32)
    closed = np.empty(n_chains, np.bool_)
    out_closed = closed.view(np.uint8)
    if total > 0:
        out_points = points
        out_gradients = gradients
        with nogil:
            for k in range(n_chains):
                at = ws.found.data[3 * (n_chains - 1 - k) + 1]
                n = out_offsets[k + 1] - out_offsets[k]
                # the pixels in output order, sampled below in one run
                memcpy(ws.ordered.data + out_offsets[k], ws.chains.data + at,
                       n * sizeof(Py_ssize_t))
                first = ws.chains.data[at]
                last = ws.chains.data[at + n - 1]
                out_closed[k] = n > 2 and -1 <= first % stride - last % stride <= 1 \
                    and -1 <= first // stride - last // stride <= 1
            _start_sampler(&sampler, &gx[0, 0], &gy[0, 0], h, w, subpixel,
                           &out_points[0, 0], &out_gradients[0, 0])
            _sample_run(&sampler, ws.ordered.data, total, stride, 1)
    return points, offsets, gradients, closed


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
    cdef Sampler sampler
    if out_points.shape[0] != n or out_gradients.shape[0] != n or gy.shape[0] != h \
            or gy.shape[1] != w:
        raise ValueError("sample: outputs must have one row per point, gx and gy one shape")
    if n == 0:
        return
    with nogil:
        _start_sampler(&sampler, &gx[0, 0], &gy[0, 0], h, w, subpixel, &out_points[0, 0],
                       &out_gradients[0, 0])
        for i in range(n):
            if i + AHEAD < n:
                _prefetch_pixel(&sampler, points[i + AHEAD, 0], points[i + AHEAD, 1])
            _gather(&sampler, points[i, 0], points[i, 1])
        _flush(&sampler)


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
            for k in range(n_chains + 1):
                out_offsets[k] = starts.data[k]
            if total > 0:
                _emit_pixels(chain_points, total, stride, 0, &out_pixels[0, 0])
        return pixels_out, offsets
    finally:
        free(lin)
        free(chain_points)
        free(starts.data)
