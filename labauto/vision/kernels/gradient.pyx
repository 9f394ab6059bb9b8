# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Colour gradient kernel (eq. 2): 3x3 Sobel of the channel with the largest L1 gradient.

See :func:`labauto.vision.gradient.color_gradient` for the definition. Integer arithmetic with
the border of ``cv2.spatialGradient`` (mirrored without repeating the edge pixel, so the
derivative across the image border is 0), so each channel's result equals
``cv2.spatialGradient``; the per-pixel choice keeps the earlier channel on ties.

Each row is done in two vectorisable passes: (1) the Sobel derivatives of all three channels at
once, walking the interleaved row byte by byte (the same channel of the left and right neighbour
is 3 bytes away), into two small row buffers; (2) per pixel, the channel with the largest
``|dx| + |dy|``. Rows are shared among threads.
"""

from cython.parallel cimport parallel, prange
from libc.stdlib cimport free, malloc


cdef inline int _abs(int v) noexcept nogil:
    return v if v >= 0 else -v


cdef void _sobel_bytes(
    const unsigned char* up, const unsigned char* mid, const unsigned char* down,
    Py_ssize_t lo, Py_ssize_t hi, Py_ssize_t left, Py_ssize_t right, short* dx, short* dy,
) noexcept nogil:
    """Derivatives of the interleaved bytes ``lo..hi - 1``; neighbours at ``i + left/right``."""
    cdef Py_ssize_t i
    for i in range(lo, hi):  # two loops, not one: each vectorises (few pointers to alias-check)
        dx[i] = <short>((up[i + right] + 2 * mid[i + right] + down[i + right])
                        - (up[i + left] + 2 * mid[i + left] + down[i + left]))
    for i in range(lo, hi):
        dy[i] = <short>((down[i + left] + 2 * down[i] + down[i + right])
                        - (up[i + left] + 2 * up[i] + up[i + right]))


cdef void _strongest_channel(
    const short* dx, const short* dy, Py_ssize_t w, short* out_x, short* out_y
) noexcept nogil:
    """Per pixel, the derivatives of the channel with the largest L1 norm (ties: earlier)."""
    cdef Py_ssize_t x
    cdef int x0, x1, x2, y0, y1, y2, s0, s1, s2, bs, bx, by
    for x in range(w):
        x0 = dx[3 * x]
        x1 = dx[3 * x + 1]
        x2 = dx[3 * x + 2]
        y0 = dy[3 * x]
        y1 = dy[3 * x + 1]
        y2 = dy[3 * x + 2]
        s0 = _abs(x0) + _abs(y0)
        s1 = _abs(x1) + _abs(y1)
        s2 = _abs(x2) + _abs(y2)
        bx = x1 if s1 > s0 else x0
        by = y1 if s1 > s0 else y0
        bs = s1 if s1 > s0 else s0
        out_x[x] = <short>(x2 if s2 > bs else bx)
        out_y[x] = <short>(y2 if s2 > bs else by)


cdef void _sobel_row(
    const unsigned char* up, const unsigned char* mid, const unsigned char* down,
    Py_ssize_t w, short* row_dx, short* row_dy, short* out_x, short* out_y,
) noexcept nogil:
    """One image row: both passes; the first and last pixel mirror their missing neighbour."""
    _sobel_bytes(up, mid, down, 0, 3, 3, 3, row_dx, row_dy)
    _sobel_bytes(up, mid, down, 3, 3 * w - 3, -3, 3, row_dx, row_dy)
    _sobel_bytes(up, mid, down, 3 * w - 3, 3 * w, -3, -3, row_dx, row_dy)
    _strongest_channel(row_dx, row_dy, w, out_x, out_y)


def max_channel_sobel(
    const unsigned char[:, :, ::1] image, short[:, ::1] gx, short[:, ::1] gy, int num_threads=1
) -> None:
    """Fill ``gx``, ``gy`` (int16 HxW) with the Sobel gradient of the strongest channel.

    Parameters
    ----------
    image : uint8 HxWx3 (at least 2x2), C-contiguous
    gx, gy : int16 HxW, C-contiguous, written in place
    num_threads : int
        Threads sharing the rows (see :func:`labauto.vision.kernels.threads`).
    """
    cdef Py_ssize_t h = image.shape[0], w = image.shape[1], y
    cdef short* row_dx
    cdef short* row_dy
    if h < 2 or w < 2 or image.shape[2] != 3 or gx.shape[0] != h or gx.shape[1] != w \
            or gy.shape[0] != h or gy.shape[1] != w:
        raise ValueError("max_channel_sobel needs an HxWx3 image (2x2 or more) and HxW outputs")
    if num_threads < 1:
        raise ValueError(f"num_threads must be >= 1, got {num_threads}")
    with nogil, parallel(num_threads=num_threads):
        row_dx = <short*>malloc(6 * w * sizeof(short))  # per thread: dx and dy of one row
        row_dy = row_dx + 3 * w
        if row_dx != NULL:
            for y in prange(h, schedule="static"):
                _sobel_row(
                    &image[y - 1 if y > 0 else 1, 0, 0],
                    &image[y, 0, 0],
                    &image[y + 1 if y < h - 1 else h - 2, 0, 0],
                    w,
                    row_dx,
                    row_dy,
                    &gx[y, 0],
                    &gy[y, 0],
                )
            free(row_dx)
