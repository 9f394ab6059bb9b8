# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Colour gradient kernel (eq. 2): 3x3 Sobel of the channel with the largest L1 gradient.

See :func:`labauto.vision.gradient.color_gradient` for the definition. Integer arithmetic with
the border of ``cv2.spatialGradient`` (mirrored without repeating the edge pixel, so the
derivative across the image border is 0), so each channel's result equals
``cv2.spatialGradient``; the per-pixel choice keeps the earlier channel on ties.

Optionally the image is first blurred by a 3x3 Gaussian exactly as ``cv2.GaussianBlur`` blurs
8-bit images, so the result is bit for bit that of ``cv2.GaussianBlur(image, (3, 3), sigma)``
followed by the Sobel step: a separable filter with taps ``[t, 256 - 2 t, t] / 256`` in each
direction (``t`` from :func:`labauto.vision.gradient.gaussian_3x3_tap`), computed exactly in
integers (the vertical pass fits in 16 bits, the horizontal one needs 32) and rounded once to
8 bits, ``(v + 32768) >> 16``; the border is mirrored as above. The blurred image is never
stored: each thread blurs one row ahead of the Sobel step.

Every row of the (blurred) image is used by three output rows, so the per-row work is done once
per row and kept in a ring of three rows per thread:

1. blur the row, walking the interleaved BGR bytes (the same channel of the left and right
   neighbour is 3 bytes away);
2. split it into one plane per channel, padded by the mirrored pixel at each end;
3. per plane, the horizontal halves of the separable Sobel operator: ``smooth`` = [1 2 1] and
   ``diff`` = [-1 0 1] along x.

An output row then takes the ring's rows above, at and below it, ``dx = diff_up + 2 diff_mid +
diff_down`` and ``dy = smooth_down - smooth_up``, and picks the channel with the largest ``|dx|
+ |dy|``, in one pass over contiguous planes (splitting the channels once per row costs less
than shuffling interleaved derivatives). All sums fit in 16 bits (``|dx| + |dy| <= 8 * 255``),
so every loop vectorises on 16-bit lanes, except the blur's horizontal pass (32 bits). Each
thread takes one contiguous block of rows; only the rows just above and below a block are done
twice.
"""

from cython.parallel cimport parallel, prange
from libc.stdint cimport uintptr_t
from libc.stdlib cimport abs as c_abs, free, malloc

cdef extern from *:
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
    const unsigned short* v, Py_ssize_t lo, Py_ssize_t hi, Py_ssize_t left, Py_ssize_t right,
    unsigned int tap, unsigned int centre, unsigned char* out,
) noexcept nogil:
    """Horizontal pass of bytes ``lo..hi - 1``, rounded to 8 bits; neighbours ``i + left/right``."""
    cdef Py_ssize_t i
    for i in range(lo, hi):
        out[i] = <unsigned char>((tap * (v[i + left] + v[i + right]) + centre * v[i] + 32768) >> 16)


cdef void _blur_row(
    const unsigned char* up, const unsigned char* mid, const unsigned char* down,
    Py_ssize_t w, unsigned int tap, unsigned short* v, unsigned char* out,
) noexcept nogil:
    """One row of the 3x3 Gaussian: vertical pass into ``v`` (16 bits), horizontal into ``out``."""
    cdef Py_ssize_t i, n = 3 * w
    cdef unsigned int centre = 256 - 2 * tap
    for i in range(n):  # at most 256 * 255: fits in 16 bits
        v[i] = <unsigned short>(tap * (up[i] + down[i]) + centre * mid[i])
    _blur_bytes(v, 0, 3, 3, 3, tap, centre, out)
    _blur_bytes(v, 3, n - 3, -3, 3, tap, centre, out)
    _blur_bytes(v, n - 3, n, -3, -3, tap, centre, out)


cdef void _split_channels(
    const unsigned char* row, Py_ssize_t w, Py_ssize_t stride, unsigned char* planes
) noexcept nogil:
    """Interleaved BGR ``row`` to three planes ``stride`` apart, each padded by its mirror."""
    cdef Py_ssize_t x, c
    cdef unsigned char* p0 = planes + 1
    cdef unsigned char* p1 = planes + stride + 1
    cdef unsigned char* p2 = planes + 2 * stride + 1
    for x in range(w):
        p0[x] = row[3 * x]
        p1[x] = row[3 * x + 1]
        p2[x] = row[3 * x + 2]
    for c in range(3):
        planes[c * stride] = planes[c * stride + 2]
        planes[c * stride + w + 1] = planes[c * stride + w - 1]


cdef void _sobel_halves(
    const unsigned char* padded, Py_ssize_t w, short* smooth, short* diff
) noexcept nogil:
    """[1 2 1] and [-1 0 1] along the padded plane row (its pixel ``x`` at ``padded[x + 1]``)."""
    cdef Py_ssize_t x
    for x in range(w):
        smooth[x] = <short>(padded[x] + 2 * padded[x + 1] + padded[x + 2])
    for x in range(w):
        diff[x] = <short>(padded[x + 2] - padded[x])


cdef void _prepare_row(
    const unsigned char* image, Py_ssize_t h, Py_ssize_t w, Py_ssize_t y, unsigned int tap,
    unsigned short* v, unsigned char* blurred, unsigned char* planes, Py_ssize_t stride,
    short* halves,
) noexcept nogil:
    """Steps 1-3 for row ``y`` (from -1 to ``h``, mirrored): ``halves`` gets, ``stride`` apart,
    smooth and diff of channel 0, then of channel 1, then of channel 2."""
    cdef Py_ssize_t c, n = 3 * w
    cdef const unsigned char* row
    y = _mirror(y, h)
    row = image + y * n
    if tap > 0:
        _blur_row(image + _mirror(y - 1, h) * n, row, image + _mirror(y + 1, h) * n,
                  w, tap, v, blurred)
        row = blurred
    _split_channels(row, w, stride, planes)
    for c in range(3):
        _sobel_halves(planes + c * stride, w, halves + 2 * c * stride,
                      halves + (2 * c + 1) * stride)


cdef void _strongest_channel(
    const short* up, const short* mid, const short* down, Py_ssize_t stride, Py_ssize_t w,
    short_out out_x, short_out out_y,
) noexcept nogil:
    """Per pixel, the Sobel derivatives of the channel with the largest L1 norm (ties: earlier).

    ``up``, ``mid``, ``down``: the halves (see :func:`_prepare_row`) of the rows above, at and
    below the output row.
    """
    cdef Py_ssize_t x, s = stride
    cdef short x0, x1, x2, y0, y1, y2, n0, n1, n2, bx, by, bn
    for x in range(w):
        x0 = <short>(up[s + x] + 2 * mid[s + x] + down[s + x])
        x1 = <short>(up[3 * s + x] + 2 * mid[3 * s + x] + down[3 * s + x])
        x2 = <short>(up[5 * s + x] + 2 * mid[5 * s + x] + down[5 * s + x])
        y0 = <short>(down[x] - up[x])
        y1 = <short>(down[2 * s + x] - up[2 * s + x])
        y2 = <short>(down[4 * s + x] - up[4 * s + x])
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
    cdef unsigned short* v = <unsigned short*>work
    cdef unsigned char* blurred = work + _align(6 * w)
    cdef unsigned char* planes = blurred + _align(3 * w)
    cdef short* up = <short*>(planes + 3 * stride)  # the ring: halves of three rows
    cdef short* mid = up + 6 * stride
    cdef short* down = mid + 6 * stride
    cdef short* done
    _prepare_row(image, h, w, y0 - 1, tap, v, blurred, planes, stride, up)  # the block's halo
    _prepare_row(image, h, w, y0, tap, v, blurred, planes, stride, mid)
    for y in range(y0, y1):
        _prepare_row(image, h, w, y + 1, tap, v, blurred, planes, stride, down)
        _strongest_channel(up, mid, down, stride, w, gx + y * w, gy + y * w)
        done = up  # move the ring down by one row
        up = mid
        mid = down
        down = done


cdef inline Py_ssize_t _work_size(Py_ssize_t w) noexcept nogil:
    """Bytes of one thread's buffers: blur (16-bit pass, 8-bit row), planes, ring of halves."""
    cdef Py_ssize_t stride = _align(w + 2)
    return _align(6 * w) + _align(3 * w) + 3 * stride + 18 * stride * sizeof(short)


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
