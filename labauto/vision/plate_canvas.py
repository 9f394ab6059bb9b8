"""The bodies' shared canvas cut into bands of like widths (plate analysis, steps 3-5).

:class:`labauto.vision.plate_bodies.Bodies` lays every body's crop on one canvas, each crop
below the one before, so that one OpenCV call treats all bodies at once. The canvas is as wide
as the widest crop, and a call pays for all of it: on the phone photo IMG_2523 one 563-px piece
of the lid's ring line among 364 bodies at most 51 px wide makes a canvas of 5.44 Mpx for
0.67 Mpx of crops. The steps over all bodies therefore run band by band: a band is a run of
consecutive crops (whole canvas rows, the gap rows after them included) as wide as its widest
crop. A crop starts a new band when the current one would, with it, leave more than
``_BAND_WASTE`` canvas pixels empty beside its crops (a few times what the OpenCV calls of
one more band cost); a plate of crops of like widths keeps one band or a few. IMG_2523's
canvas becomes 6 bands of 0.92 Mpx in all.

Measured, taking turns with the code before (median of 7 analyses, twice each; the steps
over some of the bodies also cut the canvas to the widest of those, which strokes seldom
are): IMG_2523 192-193 -> 137-143 ms, IMG_2531 80-81 -> 66-68 ms, the other photos and the
generator's plates as before (``bench_plate``: 38.3 against 38.2 ms); every colony of the 67
photos and of 14 generated plates the same, at their size and at a fifth of it, and with a
band for nearly every crop.

Each helper gives exactly what the plain call gives on the whole canvas: crops are ``PAD`` px
of background away from their box on every side and never share a row, and nothing outside
the bands is foreground. So the 5x5 closing, which reaches 2 px, sees the same pixels in a
band as on the canvas; a pixel's distance transform is its distance to the nearest background,
which lies in its own crop; and connected components, numbered band after band, keep the
canvas's raster order.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

Band = tuple[int, int, int]  # first canvas row, the row after the last, width
_BAND_WASTE = 50_000  # canvas pixels a band may leave empty before a crop starts a new one


def bands_of(row: np.ndarray, slot: np.ndarray, width: np.ndarray, n_rows: int) -> list[Band]:
    """The bands of a canvas whose crops start at ``row``, take ``slot`` rows and are
    ``width`` px wide (module docstring)."""
    bands: list[Band] = []
    start, widest, used = 0, int(width[0]), int(slot[0] * width[0])
    for b in range(1, len(row)):
        rows, w, area = int(row[b] - row[start] + slot[b]), int(width[b]), int(slot[b] * width[b])
        if rows * max(widest, w) - (used + area) > _BAND_WASTE:  # the band's empty pixels
            bands.append((int(row[start]), int(row[b]), widest))
            start, widest, used = b, w, area
        else:
            widest, used = max(widest, w), used + area
    bands.append((int(row[start]), n_rows, widest))
    return bands


def on_bands(op: Callable[..., np.ndarray], bands: list[Band], *canvases: np.ndarray) -> np.ndarray:
    """``op`` of the canvases, band by band (each canvas cut to the band), into one canvas
    of the first's shape, zero outside the bands."""
    if len(bands) == 1:  # the whole canvas
        return op(*(canvas[:, : bands[0][2]] for canvas in canvases))
    parts = [op(*(canvas[r0:r1, :w] for canvas in canvases)) for r0, r1, w in bands]
    out = np.zeros(canvases[0].shape, parts[0].dtype)
    for (r0, r1, w), part in zip(bands, parts, strict=True):
        out[r0:r1, :w] = part
    return out


def components(image: np.ndarray, bands: list[Band], connectivity: int) -> tuple[int, np.ndarray]:
    """``cv2.connectedComponents`` of ``image``, band by band, numbered on across the bands."""
    labels = np.zeros(image.shape, np.int32)
    n = 1
    for r0, r1, w in bands:
        k, part = cv2.connectedComponents(image[r0:r1, :w], connectivity=connectivity)
        if k > 1:
            labels[r0:r1, :w] = np.where(part > 0, part + (n - 1), 0)
        n += k - 1
    return n, labels


def nonzero(image: np.ndarray, bands: list[Band]) -> tuple[np.ndarray, np.ndarray]:
    """``x, y`` of the nonzero pixels of ``image`` in raster order, band by band."""
    points = []
    for r0, r1, w in bands:
        found = cv2.findNonZero(image[r0:r1, :w])
        if found is not None:
            points.append(found.reshape(-1, 2) + np.array([0, r0], np.int32))
    if not points:
        empty = np.zeros(0, np.intp)
        return empty, empty
    xs, ys = np.concatenate(points).T
    return xs.astype(np.intp), ys.astype(np.intp)


def per_row(
    reduce: Callable[[np.ndarray], np.ndarray], canvas: np.ndarray, bands: list[Band]
) -> np.ndarray:
    """``reduce`` (a reduction along axis 1) of every canvas row, band by band."""
    return np.concatenate([reduce(canvas[r0:r1, :w]) for r0, r1, w in bands])
