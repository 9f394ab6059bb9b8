# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Colour gradient kernel (eq. 2): 3x3 Sobel of the channel with the largest L1 gradient.

See :func:`labauto.vision.gradient.color_gradient` for the definition. Integer arithmetic with
the border of ``cv2.spatialGradient`` (mirrored without repeating the edge pixel, so the
derivative across the image border is 0), so each channel's result equals
``cv2.spatialGradient``; the per-pixel choice keeps the earlier channel on ties.

Optionally the image is first blurred by a 3x3 Gaussian exactly as ``cv2.GaussianBlur`` blurs
8-bit images, so the result is bit for bit that of ``cv2.GaussianBlur(image, (3, 3), sigma)``
followed by the Sobel step: a separable filter with taps ``[t, 256 - 2 t, t] / 256`` in each
direction (``t`` from :func:`labauto.vision.gradient.gaussian_3x3_tap`, ``c = 256 - 2 t``),
computed exactly in integers and rounded once to 8 bits, ``(S + 32768) >> 16``; the border is
mirrored as above. The blurred image is never stored: each thread blurs one row ahead of the
Sobel step. Both passes run on 16-bit lanes (the full SIMD width):

* vertical: ``V = t (up + down) + c mid <= 255 * 256``, kept as its high and low bytes ``V =
  256 Vh + Vl`` (two 16-bit arrays, split once here rather than three times in the next pass);
* horizontal, with ``A``, ``B``, ``C`` the values ``V`` of the left, centre and right
  neighbour: ``S = t (A + C) + c B = 256 H + L`` with ``H = t (Ah + Ch) + c Bh`` and ``L = t
  (Al + Cl) + c Bl``, both at most ``255 * 256``, and, by nested floor division, ``(S + 32768)
  >> 16 == (H + 128 + (L >> 8)) >> 8`` exactly, where ``H + 128 + (L >> 8) <= (S >> 8) + 128
  < 65536`` (no 32-bit lanes needed).

Every row of the (blurred) image is used by three output rows, so the per-row work is done once
per row and kept in a ring of three rows per thread: blur the row, walking the interleaved BGR
bytes (the same channel of the left and right neighbour is 3 bytes away), and split it into one
16-bit plane per channel, padded by the mirrored pixel at each end. An output row then takes the
ring's rows above (``u``), at (``m``) and below (``d``) it and computes, per channel and pixel
``x`` (``x - 1``, ``x``, ``x + 1`` at plane indices ``x``, ``x + 1``, ``x + 2``), the 3x3 Sobel
operator from the two diagonal differences ``p = d[x + 2] - u[x]`` and ``q = u[x + 2] - d[x]``:
``dx = p + q + 2 (m[x + 2] - m[x])`` and ``dy = p - q + 2 (d[x + 1] - u[x + 1])``; then it picks
the channel with the largest ``|dx| + |dy|``. That is one pass over nine contiguous planes (no
stored Sobel halves: reading the planes directly costs fewer instructions and keeps the ring at
nine 16-bit rows, 24 kB for 1280 pixels). All sums fit in 16 bits (``|dx| + |dy| <= 8 * 255``),
so every loop vectorises on 16-bit lanes. Each thread takes one contiguous block of rows; only
the rows just above and below a block are done twice.
"""

from cython.parallel cimport parallel, prange
from libc.stdint cimport uintptr_t
from libc.stdlib cimport abs as c_abs, free, malloc

cdef extern from *:
    """
    /* _strongest_channel stays out of line. GCC would inline it into its only caller, where its
       loop, with 13 pointers live (9 planes, 2 outputs, index, end), shares the registers with
       the row loop's variables: GCC spilled 11 of them (17 % more instructions in the loop) */
    #if defined(__GNUC__)
    #define LABAUTO_NOINLINE __attribute__((noinline))
    #elif defined(_MSC_VER)
    #define LABAUTO_NOINLINE __declspec(noinline)
    #else
    #define LABAUTO_NOINLINE
    #endif
    static LABAUTO_NOINLINE void labauto_strongest_channel(
        const short*, const short*, const short*, const short*, const short*, const short*,
        const short*, const short*, const short*, Py_ssize_t, short*, short*);
    """
    # an output row no input row overlaps: lets gcc vectorise a loop reading many rows
    ctypedef short* short_out "short *__restrict__"


cdef inline short _abs(short v) noexcept nogil:
    return <short>c_abs(v)


cdef inline Py_ssize_t _mirror(Py_ssize_t y, Py_ssize_t h) noexcept nogil:
    """Row ``y`` (from -1 to ``h``) mirrored into the image without repeating the edge row."""
    return 1 if y < 0 else (h - 2 if y >= h else y)


cdef inline Py_ssize_t _align(Py_ssize_t n) noexcept nogil:
    """``n`` rounded up to a multiple of 64 (a cache line)."""
    return (n + 63) // 64 * 64


cdef void _blur_bytes(
    const unsigned short* vh, const unsigned short* vl, Py_ssize_t lo, Py_ssize_t hi,
    Py_ssize_t left, Py_ssize_t right, unsigned int tap, unsigned int centre, unsigned char* out,
) noexcept nogil:
    """Horizontal pass of bytes ``lo..hi - 1``, rounded to 8 bits; neighbours ``i + left/right``.

    ``vh``, ``vl``: high and low bytes of the vertical pass. ``(H + 128 + (L >> 8)) >> 8`` equals
    ``(256 H + L + 32768) >> 16`` (see the module docstring); every step fits in 16 bits.
    """
    cdef Py_ssize_t i
    cdef unsigned short high, low
    for i in range(lo, hi):
        high = <unsigned short>(tap * (vh[i + left] + vh[i + right]) + centre * vh[i] + 128)
        low = <unsigned short>(tap * (vl[i + left] + vl[i + right]) + centre * vl[i])
        out[i] = <unsigned char>(<unsigned short>(high + (low >> 8)) >> 8)


cdef void _blur_row(
    const unsigned char* up, const unsigned char* mid, const unsigned char* down,
    Py_ssize_t w, unsigned int tap, unsigned short* vh, unsigned short* vl, unsigned char* out,
) noexcept nogil:
    """One row of the 3x3 Gaussian: vertical pass into ``vh``, ``vl`` (high, low byte of each
    16-bit sum), horizontal pass into ``out``."""
    cdef Py_ssize_t i, n = 3 * w
    cdef unsigned int centre = 256 - 2 * tap
    cdef unsigned short v
    for i in range(n):
        v = <unsigned short>(tap * (up[i] + down[i]) + centre * mid[i])  # <= 256 * 255
        vh[i] = v >> 8
        vl[i] = v & 255
    _blur_bytes(vh, vl, 0, 3, 3, 3, tap, centre, out)
    _blur_bytes(vh, vl, 3, n - 3, -3, 3, tap, centre, out)
    _blur_bytes(vh, vl, n - 3, n, -3, -3, tap, centre, out)


cdef void _split_channels(
    const unsigned char* row, Py_ssize_t w, Py_ssize_t stride, short* planes
) noexcept nogil:
    """Interleaved BGR ``row`` to three 16-bit planes ``stride`` apart, each padded by its mirror
    (pixel ``x`` of a plane at ``plane[x + 1]``)."""
    cdef Py_ssize_t x, c
    cdef short* p0 = planes + 1
    cdef short* p1 = planes + stride + 1
    cdef short* p2 = planes + 2 * stride + 1
    for x in range(w):
        p0[x] = row[3 * x]
        p1[x] = row[3 * x + 1]
        p2[x] = row[3 * x + 2]
    for c in range(3):
        planes[c * stride] = planes[c * stride + 2]
        planes[c * stride + w + 1] = planes[c * stride + w - 1]


cdef void _prepare_row(
    const unsigned char* image, Py_ssize_t h, Py_ssize_t w, Py_ssize_t y, unsigned int tap,
    unsigned short* vh, unsigned short* vl, unsigned char* blurred, Py_ssize_t stride,
    short* planes,
) noexcept nogil:
    """Row ``y`` (from -1 to ``h``, mirrored), blurred if ``tap`` > 0, into ``planes``."""
    cdef Py_ssize_t n = 3 * w
    cdef const unsigned char* row
    y = _mirror(y, h)
    row = image + y * n
    if tap > 0:
        _blur_row(image + _mirror(y - 1, h) * n, row, image + _mirror(y + 1, h) * n,
                  w, tap, vh, vl, blurred)
        row = blurred
    _split_channels(row, w, stride, planes)


cdef void _strongest_channel "labauto_strongest_channel"(
    const short* u0, const short* u1, const short* u2, const short* m0, const short* m1,
    const short* m2, const short* d0, const short* d1, const short* d2, Py_ssize_t w,
    short_out out_x, short_out out_y,
) noexcept nogil:
    """Per pixel, the Sobel derivatives of the channel with the largest L1 norm (ties: earlier).

    ``u0``-``u2``, ``m0``-``m2``, ``d0``-``d2``: the padded planes (see :func:`_split_channels`)
    of channels 0-2 in the rows above, at and below the output row; passed one by one, each
    gets a register of its own (with an index and a constant offset in every load).
    """
    cdef Py_ssize_t x
    cdef short p0, p1, p2, q0, q1, q2, x0, x1, x2, y0, y1, y2, n0, n1, n2, bx, by, bn
    for x in range(w):
        # 3x3 Sobel of each channel; p, q: the two diagonal differences (module docstring)
        p0 = <short>(d0[x + 2] - u0[x])
        q0 = <short>(u0[x + 2] - d0[x])
        x0 = <short>(p0 + q0 + 2 * (m0[x + 2] - m0[x]))
        y0 = <short>(p0 - q0 + 2 * (d0[x + 1] - u0[x + 1]))
        p1 = <short>(d1[x + 2] - u1[x])
        q1 = <short>(u1[x + 2] - d1[x])
        x1 = <short>(p1 + q1 + 2 * (m1[x + 2] - m1[x]))
        y1 = <short>(p1 - q1 + 2 * (d1[x + 1] - u1[x + 1]))
        p2 = <short>(d2[x + 2] - u2[x])
        q2 = <short>(u2[x + 2] - d2[x])
        x2 = <short>(p2 + q2 + 2 * (m2[x + 2] - m2[x]))
        y2 = <short>(p2 - q2 + 2 * (d2[x + 1] - u2[x + 1]))
        n0 = <short>(_abs(x0) + _abs(y0))
        n1 = <short>(_abs(x1) + _abs(y1))
        n2 = <short>(_abs(x2) + _abs(y2))
        bx = x1 if n1 > n0 else x0
        by = y1 if n1 > n0 else y0
        bn = n1 if n1 > n0 else n0
        out_x[x] = x2 if n2 > bn else bx
        out_y[x] = y2 if n2 > bn else by


cdef void _gradient_block(
    const unsigned char* image, Py_ssize_t h, Py_ssize_t w, Py_ssize_t y0, Py_ssize_t y1,
    unsigned int tap, unsigned char* work, short* gx, short* gy,
) noexcept nogil:
    """Rows ``y0..y1 - 1`` of ``gx``, ``gy``, with the buffers in ``work`` (see
    :func:`_work_size`, 64-byte aligned)."""
    cdef Py_ssize_t y, stride = _align(w + 2)
    cdef unsigned short* vh = <unsigned short*>work
    cdef unsigned short* vl = <unsigned short*>(work + _align(6 * w))
    cdef unsigned char* blurred = work + 2 * _align(6 * w)
    cdef short* up = <short*>(blurred + _align(3 * w))  # the ring: planes of three rows
    cdef short* mid = up + 3 * stride
    cdef short* down = mid + 3 * stride
    cdef short* done
    _prepare_row(image, h, w, y0 - 1, tap, vh, vl, blurred, stride, up)  # the block's halo
    _prepare_row(image, h, w, y0, tap, vh, vl, blurred, stride, mid)
    for y in range(y0, y1):
        _prepare_row(image, h, w, y + 1, tap, vh, vl, blurred, stride, down)
        _strongest_channel(up, up + stride, up + 2 * stride, mid, mid + stride, mid + 2 * stride,
                           down, down + stride, down + 2 * stride, w, gx + y * w, gy + y * w)
        done = up  # move the ring down by one row
        up = mid
        mid = down
        down = done


cdef inline Py_ssize_t _work_size(Py_ssize_t w) noexcept nogil:
    """Bytes of one thread's buffers: blur (two 16-bit arrays, 8-bit row), ring of 16-bit planes."""
    cdef Py_ssize_t stride = _align(w + 2)
    return 2 * _align(6 * w) + _align(3 * w) + 9 * stride * sizeof(short)


def max_channel_sobel(
    const unsigned char[:, :, ::1] image, short[:, ::1] gx, short[:, ::1] gy, int num_threads=1,
    int blur_tap=0,
) -> None:
    """Fill ``gx``, ``gy`` (int16 HxW) with the Sobel gradient of the strongest channel.

    Parameters
    ----------
    image : uint8 HxWx3 (at least 2x2), C-contiguous
    gx, gy : int16 HxW, C-contiguous, two separate arrays, written in place
    num_threads : int
        Threads sharing the rows, one contiguous block each (see
        :func:`labauto.vision.kernels.threads`).
    blur_tap : int
        Outer tap ``t`` (0-64) of the 3x3 Gaussian applied first, in 1/256: the kernel is ``[t,
        256 - 2 t, t] / 256`` in each direction, rounded as ``cv2.GaussianBlur`` rounds (see
        :func:`labauto.vision.gradient.gaussian_3x3_tap`); 0 for no blur.
    """
    cdef Py_ssize_t h = image.shape[0], w = image.shape[1], t, blocks
    cdef unsigned char* memory
    cdef unsigned int tap
    if h < 2 or w < 2 or image.shape[2] != 3 or gx.shape[0] != h or gx.shape[1] != w \
            or gy.shape[0] != h or gy.shape[1] != w:
        raise ValueError("max_channel_sobel needs an HxWx3 image (2x2 or more) and HxW outputs")
    if num_threads < 1:
        raise ValueError(f"num_threads must be >= 1, got {num_threads}")
    if blur_tap < 0 or blur_tap > 64:
        raise ValueError(f"blur_tap must be in 0..64, got {blur_tap}")
    tap = blur_tap
    blocks = min(num_threads, h)
    with nogil, parallel(num_threads=num_threads):
        memory = <unsigned char*>malloc(_work_size(w) + 63)  # per thread
        if memory != NULL:
            for t in prange(blocks, schedule="static", chunksize=1):
                _gradient_block(
                    &image[0, 0, 0], h, w, t * h // blocks, (t + 1) * h // blocks, tap,
                    <unsigned char*>(_align(<uintptr_t>memory)), &gx[0, 0], &gy[0, 0],
                )
            free(memory)
