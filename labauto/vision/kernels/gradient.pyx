# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Colour gradient kernel (eq. 2): 3x3 Sobel of the channel with the largest L1 gradient.

See :func:`labauto.vision.gradient.color_gradient` for the definition. Integer arithmetic with
the border of ``cv2.spatialGradient`` (mirrored without repeating the edge pixel, so the
derivative across the image border is 0), so each channel's result equals
``cv2.spatialGradient``; the per-pixel choice keeps the earlier channel on ties. Rows are shared
among threads.
"""

from cython.parallel cimport prange


cdef inline int _abs(int v) noexcept nogil:
    return v if v >= 0 else -v


cdef inline void _sobel_channel(
    const unsigned char* up, const unsigned char* mid, const unsigned char* down,
    Py_ssize_t l, Py_ssize_t c, Py_ssize_t r, int* dx, int* dy,
) noexcept nogil:
    """3x3 Sobel of one channel at one pixel (l, c, r: byte offsets of the three columns)."""
    cdef int ul = up[l], uc = up[c], ur = up[r]
    cdef int ml = mid[l], mr = mid[r]
    cdef int dl = down[l], dc = down[c], dr = down[r]
    dx[0] = (ur + 2 * mr + dr) - (ul + 2 * ml + dl)
    dy[0] = (dl + 2 * dc + dr) - (ul + 2 * uc + ur)


cdef inline void _strongest_at(
    const unsigned char* up, const unsigned char* mid, const unsigned char* down,
    Py_ssize_t l, Py_ssize_t c, Py_ssize_t r, short* out_x, short* out_y,
) noexcept nogil:
    """Sobel of the 3 channels at one pixel; write the strongest channel's (ties: earlier)."""
    cdef int x0, y0, x1, y1, x2, y2, s0, s1, s2, bx, by, bs
    _sobel_channel(up, mid, down, l, c, r, &x0, &y0)
    _sobel_channel(up, mid, down, l + 1, c + 1, r + 1, &x1, &y1)
    _sobel_channel(up, mid, down, l + 2, c + 2, r + 2, &x2, &y2)
    s0 = _abs(x0) + _abs(y0)
    s1 = _abs(x1) + _abs(y1)
    s2 = _abs(x2) + _abs(y2)
    bx = x1 if s1 > s0 else x0
    by = y1 if s1 > s0 else y0
    bs = s1 if s1 > s0 else s0
    out_x[0] = <short>(x2 if s2 > bs else bx)
    out_y[0] = <short>(y2 if s2 > bs else by)


cdef void _sobel_row(
    const unsigned char* up, const unsigned char* mid, const unsigned char* down,
    Py_ssize_t w, short* out_x, short* out_y,
) noexcept nogil:
    """One row: Sobel of the 3 interleaved channels, the strongest channel per pixel."""
    cdef Py_ssize_t x
    _strongest_at(up, mid, down, 3, 0, 3, out_x, out_y)  # mirrored border: x - 1 -> 1
    for x in range(1, w - 1):
        _strongest_at(up, mid, down, 3 * x - 3, 3 * x, 3 * x + 3, out_x + x, out_y + x)
    _strongest_at(up, mid, down, 3 * w - 6, 3 * w - 3, 3 * w - 6, out_x + w - 1, out_y + w - 1)


def max_channel_sobel(
    const unsigned char[:, :, ::1] image, short[:, ::1] gx, short[:, ::1] gy
) -> None:
    """Fill ``gx``, ``gy`` (int16 HxW) with the Sobel gradient of the strongest channel.

    Parameters
    ----------
    image : uint8 HxWx3 (at least 2x2), C-contiguous
    gx, gy : int16 HxW, C-contiguous, written in place
    """
    cdef Py_ssize_t h = image.shape[0], w = image.shape[1], y
    if h < 2 or w < 2 or image.shape[2] != 3 or gx.shape[0] != h or gx.shape[1] != w \
            or gy.shape[0] != h or gy.shape[1] != w:
        raise ValueError("max_channel_sobel needs an HxWx3 image (2x2 or more) and HxW outputs")
    for y in prange(h, nogil=True, schedule="static"):
        _sobel_row(
            &image[y - 1 if y > 0 else 1, 0, 0],
            &image[y, 0, 0],
            &image[y + 1 if y < h - 1 else h - 2, 0, 0],
            w,
            &gx[y, 0],
            &gy[y, 0],
        )
