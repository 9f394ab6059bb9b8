"""The agar's own colour, locally, and what departs from it (paper eq. 1, step 2 of plate analysis).

Eq. 1 of the paper marks a pixel as object when its colour departs from the background's mean
by more than a threshold. On a real plate the "background" is the agar, whose colour drifts
across the dish (lighting, agar depth, the meniscus at the wall) and which the analysis does not
know in advance. Choices made here:

* **Background, from the dish itself.** On a grid of cells of ``cell_px`` pixels (about 0.8 mm)
  a 31x31 median of the cells (~25 mm, wider than the largest colonies) and a 5x5 one
  (following the agar's finer drift) each mark the cells that depart from them by more than half the
  threshold; those are masked out, the mask is grown by one cell, and the remaining agar is
  spread back over the masked cells by a normalised Gaussian convolution; cells far from any
  agar (a colony wider than a few millimetres) take the wider convolution's value, and failing
  that the dish's mean agar colour. The result is resized
  back to full size (a smooth field: a shift of a fraction of a cell does not matter).
* **Deviation.** ``dev`` is the summed squared difference over B, G, R from that background
  (optionally weighted), in grey levels squared, as eq. 1.
* **Threshold from the image.** Eq. 1's ``t`` is the larger of ``color_threshold`` and
  ``noise_factor`` times the agar's own noise (the median of ``dev`` over the agar, a robust
  mean of chi-square distributed values). Faint colonies are taken with hysteresis: a body of
  pixels above ``low_ratio * t`` is kept when it holds at least one pixel above ``t``; its
  outline then sits where it departs from the agar, not at the threshold's contour.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.vision.median import median
from labauto.vision.plate_ink import INK_PIXEL_DARKER

_SQUARES = (np.arange(256, dtype=np.float32) ** 2).reshape(1, 256)
_ONES_3 = np.ones((1, 3), np.float32)  # cv2.transform: sum of the three channels
_WIDE_MEDIAN_CELLS = 31  # ~25 mm at 0.8 mm cells: wider than the largest colonies


def local_background(
    image: np.ndarray, usable: np.ndarray, cell_px: int, threshold: float
) -> np.ndarray:
    """The agar's colour at every pixel of ``image`` (uint8, HxWx3), estimated on the dish.

    Parameters
    ----------
    image : ndarray
        HxWx3 BGR uint8 image (the dish's bounding box).
    usable : ndarray
        HxW uint8 mask (255 on the agar whose colour counts).
    cell_px : int
        Side of a background cell in pixels (the estimate's detail is about 4 cells).
    threshold : float
        Eq. 1 threshold (grey levels squared); cells departing by half of it are not agar.
    """
    h, w = usable.shape
    s = max(int(cell_px), 1)
    sh, sw = -(-h // s), -(-w // s)
    # whole cells by area averaging (OpenCV's integer-factor path); a last partial row or
    # column of cells takes its neighbour's value
    fh, fw = max(h // s, 1), max(w // s, 1)
    whole = image[: min(fh * s, h), : min(fw * s, w)]
    if s % 2 == 0 and s > 2:  # halving first takes OpenCV's fast 2x path (~2x faster overall)
        whole = cv2.resize(whole, (fw * s // 2, fh * s // 2), interpolation=cv2.INTER_AREA)
    small = cv2.resize(whole, (fw, fh), interpolation=cv2.INTER_AREA)
    small = cv2.copyMakeBorder(small, 0, sh - fh, 0, sw - fw, cv2.BORDER_REPLICATE)
    valid = np.zeros((sh, sw), np.uint8)  # a cell's centre pixel; 0 past the image's edge
    centres = usable[s // 2 :: s, s // 2 :: s]
    valid[: centres.shape[0], : centres.shape[1]] = centres
    outlier = np.zeros((sh, sw), np.uint8)
    # the wide median on cells twice as large (the same ~25 mm, a quarter of the work)
    half = cv2.resize(small, (max(sw // 2, 1), max(sh // 2, 1)), interpolation=cv2.INTER_AREA)
    for grid, ksize in ((half, _WIDE_MEDIAN_CELLS // 2), (small, 5)):
        ksize = min(ksize | 1, 2 * ((min(grid.shape[:2]) - 1) // 2) + 1)  # odd, inside the grid
        med = cv2.medianBlur(grid, ksize) if ksize > 1 else grid
        if grid is half:
            med = cv2.resize(med, (sw, sh), interpolation=cv2.INTER_NEAREST)
        off_median = cv2.transform(cv2.LUT(cv2.absdiff(small, med), _SQUARES), _ONES_3)
        outlier |= cv2.compare(off_median, threshold * 0.5, cv2.CMP_GT)
    outlier = cv2.dilate(outlier, np.ones((3, 3), np.uint8))
    agar = cv2.bitwise_and(valid, cv2.bitwise_not(outlier))  # 255 on the agar used
    if cv2.countNonZero(agar) < 4:
        agar = valid
    if cv2.countNonZero(agar) < 1:
        agar = np.full_like(valid, 255)
    weight = cv2.multiply(agar, 1.0 / 255.0, dtype=cv2.CV_32F)  # 0 or 1
    weighted = cv2.multiply(small, cv2.merge((weight, weight, weight)), dtype=cv2.CV_32F)
    mean_agar = np.array(cv2.mean(small, agar)[:3], np.float32)
    bg_small = np.empty(small.shape, np.float32)
    bg_small[:] = mean_agar
    filled = np.zeros((sh, sw), bool)
    for sigma in (2.0, 6.0):  # near agar first, then wider for the middle of big colonies
        num = cv2.GaussianBlur(weighted, (0, 0), sigma)
        den = cv2.GaussianBlur(weight, (0, 0), sigma)
        here = (den > 0.05) & ~filled
        np.divide(num, den[..., None], out=bg_small, where=here[..., None])
        filled |= here
    bg_small = cv2.convertScaleAbs(bg_small)
    return cv2.resize(bg_small, (w, h), interpolation=cv2.INTER_LINEAR)


def deviation(
    image: np.ndarray, background: np.ndarray, weights: tuple[float, float, float]
) -> np.ndarray:
    """Summed (weighted) squared difference over B, G, R from the background (float32, HxW)."""
    diff = cv2.absdiff(image, background)
    if tuple(weights) == (1.0, 1.0, 1.0):
        # the plain sum of squares: the squares in float32, summed over the channels (exact
        # integers below 2^24; ~2x quicker than accumulating the split channels)
        return cv2.transform(cv2.multiply(diff, diff, dtype=cv2.CV_32F), _ONES_3)
    return cv2.transform(cv2.LUT(diff, _SQUARES), np.asarray(weights, np.float32).reshape(1, 3))


def adaptive_threshold(
    dev: np.ndarray, usable: np.ndarray, floor: float, noise_factor: float
) -> float:
    """Eq. 1's ``t``: ``max(floor, noise_factor * median(dev on the agar))``.

    The median over the usable area is the agar's noise level: colonies cover far less than
    half of it on any plate worth analysing.
    """
    if noise_factor <= 0:
        return float(floor)
    step = max(1, int(np.sqrt(dev.size / 250_000)))  # ~250k samples are plenty for a median
    samples = dev[::step, ::step][usable[::step, ::step] > 0]
    if samples.size == 0:
        return float(floor)
    return float(max(floor, noise_factor * median(samples)))


def hysteresis(dev: np.ndarray, usable: np.ndarray, high: float, low: float) -> np.ndarray:
    """Pixels above ``low`` connected (8-neighbourhood) to a pixel above ``high``, in ``usable``.

    Returns a uint8 mask (0 / 255).
    """
    weak = cv2.bitwise_and(cv2.compare(dev, low, cv2.CMP_GT), usable)
    if low >= high:
        return weak
    n, labels = cv2.connectedComponents(weak, connectivity=8)
    if n <= 1:
        return weak
    strong = labels[(dev > high) & (weak > 0)]
    keep = np.zeros(n, np.uint8)
    keep[np.unique(strong)] = 255
    keep[0] = 0
    return keep[labels]


_RIM_SECTORS = 18  # sectors of 20 degrees: the radial profile is a median over each
_RIM_ANGLES = 720  # angles sampled round the band (40 per sector)
_PIXEL = np.dtype((np.void, 3))  # one BGR uint8 pixel as a single item


@dataclass(frozen=True)
class RimProfile:
    """The band's pixels and the dish's radial profile at them (:func:`rim_profile`).

    ``index`` holds the flat pixel indices (``row * width + column``) of the band, ``lookup``
    the profile's B, G, R at each (one row of ``3 n`` float32) and ``weight`` its blending
    weight, repeated for the three channels (the same layout).
    """

    index: np.ndarray
    lookup: np.ndarray
    weight: np.ndarray


def rim_profile(
    image: np.ndarray, rim: tuple[float, float, float], band_px: float
) -> RimProfile | None:
    """The dish's own radial profile over the outer band, to replace the background there.

    Near the wall the agar's colour changes within a millimetre or two (the meniscus: a bright
    or dark ring), faster than the cell estimate can follow; eq. 1 then sees the ring as one
    body that swallows every colony touching it. The meniscus is (nearly) the same all round,
    so the band is unwrapped to polar coordinates (``cv2.remap``, 1 px per radius step, 720
    angles) and, in each 20-degree sector, the median over the angles at every radius is the
    background there: colonies cover less than half of a sector's arc at any radius (the arc
    is ~14 mm at the edge of a 90 mm dish). Sectors of 10 degrees took colonies of 7 mm and
    more in the band for the background and cut them into crescents; with 20 degrees, AGAR F1
    0.842 -> 0.845, median count error 16.7 -> 14.0 %, phone-counts 2.9 -> 2.7 % (12 sectors:
    F1 0.845, 16.2 % and 3.1 %).
    Sector medians are interpolated between sector centres (cyclically), looked up at every
    pixel of the band, and blended in over the outer ``band_px`` of the circle
    ``rim = (cx, cy, r)`` (full weight in the outer two thirds of the band, ramping over its
    inner third) by :func:`with_radial_rim`. It needs only the image, so plate analysis takes it
    in a thread beside the cell estimate of :func:`local_background`. None when the band
    holds no pixel of the image.
    """
    h, w = image.shape[:2]
    cx, cy, r = (float(v) for v in rim)
    r0 = max(r - band_px - 2.0, 0.0)
    n_r, n_t = max(math.ceil(r + 2.0 - r0), 2), _RIM_ANGLES
    theta = np.arange(n_t, dtype=np.float32) * np.float32(2 * np.pi / n_t)
    radii = r0 + np.arange(n_r, dtype=np.float32)
    map_x = (cx + np.cos(theta)[:, None] * radii[None, :]).astype(np.float32)
    map_y = (cy + np.sin(theta)[:, None] * radii[None, :]).astype(np.float32)
    band = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    per = n_t // _RIM_SECTORS
    medians = np.median(band.reshape(_RIM_SECTORS, per, n_r, 3), axis=1).astype(np.float32)
    # sector centres, cyclically: row k of ``ring`` is the centre of sector k - 1
    ring = np.concatenate((medians[-1:], medians, medians[:1]))
    # the band's pixels, as (radius, angle) into the sector-median table
    points = cv2.findNonZero(_annulus(h, w, cx, cy, r0 + 2.0, r + 2.0))
    if points is None:
        return None
    xs, ys = points.reshape(-1, 2).T
    dist, angle = (
        v.ravel()
        for v in cv2.cartToPolar(
            xs.astype(np.float32) - np.float32(cx), ys.astype(np.float32) - np.float32(cy)
        )
    )  # angle in [0, 2 pi)
    # row of ``ring``: sector k's centre (angle (k + 0.5) * 10 deg) is row k + 1
    sector = angle * np.float32(_RIM_SECTORS / (2 * np.pi)) + np.float32(0.5)
    lookup = _bilinear(ring, dist - np.float32(r0), sector)
    weight = (dist - np.float32(r - band_px)) * np.float32(1.0 / max(band_px / 3.0, 1.0))
    np.clip(weight, 0.0, 1.0, out=weight)
    return RimProfile(
        index=ys.astype(np.intp) * w + xs,
        lookup=lookup.reshape(1, -1),
        weight=np.repeat(weight, 3).reshape(1, -1),
    )


def with_radial_rim(background: np.ndarray, profile: RimProfile | None) -> np.ndarray:
    """``background`` with its outer band blended towards the dish's radial profile.

    ``profile`` is :func:`rim_profile` of the image (None: ``background`` as it is). Only the
    band's pixels are touched.
    """
    if profile is None:
        return background
    out = background.copy()
    # one 3-byte item per pixel: gathering and scattering whole pixels is ~4x faster so
    pixels = out.reshape(-1).view(_PIXEL)
    here = np.take(pixels, profile.index).view(np.uint8).reshape(1, -1).astype(np.float32)
    # here + (lookup - here) * weight over flat rows of B, G, R values (numpy's broadcast of
    # the weight over rows of three is ~4x slower)
    step = cv2.subtract(profile.lookup, here)
    here = cv2.add(here, cv2.multiply(step, profile.weight))
    np.put(pixels, profile.index, cv2.convertScaleAbs(here).reshape(-1).view(_PIXEL))
    return out


def _bilinear(table: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``table`` (rows x cols x 3) sampled at ``(x, y)`` (col, row), bilinear, edges clamped.

    ``cv2.remap`` does the same but limits its output to 32767 rows or columns; the band of a
    large dish holds more pixels, so they go through it as rows of 4096.
    """
    n = x.size
    cols = 4096
    rows = -(-n // cols)
    pad = rows * cols - n
    mx = np.pad(x.astype(np.float32), (0, pad)).reshape(rows, cols)
    my = np.pad(y.astype(np.float32), (0, pad)).reshape(rows, cols)
    out = cv2.remap(table, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1, table.shape[2])[:n]


def _annulus(h: int, w: int, cx: float, cy: float, r_in: float, r_out: float) -> np.ndarray:
    """uint8 mask of the ring ``r_in <= |p - c| < r_out`` (drawn, 1/16 px precision)."""
    mask = np.zeros((h, w), np.uint8)
    centre = (round(cx * 16), round(cy * 16))
    cv2.circle(mask, centre, round(r_out * 16), 255, -1, cv2.LINE_8, 4)
    cv2.circle(mask, centre, round(max(r_in, 0.0) * 16), 0, -1, cv2.LINE_8, 4)
    return mask


_FRAGMENT_RATIO = 0.5  # a piece is a fragment when the opening took this much around it


def open_thin_lines(fg: np.ndarray, size: int) -> np.ndarray:
    """``fg`` opened with a disc of ``size`` px, without the fragments of thick strokes.

    The opening removes what is thinner than the disc: the lid's and the wall's edges, hairs,
    scratches, so that colonies touching them come apart from them. A thick pen stroke or a
    label's bar is not removed whole: the opening leaves pieces where it is widest. A piece is
    such a fragment when the pixels the opening removed within ``size`` px around it outnumber
    ``_FRAGMENT_RATIO`` of its own area (a colony that a line crossed loses a few line pixels
    around it; a piece of a stroke is flanked by the rest of the stroke) and is dropped.
    Limit: a stroke nearly as wide as the disc, or a blot on it wider than ~1.3 times the
    stroke, leaves pieces this rule keeps; black and blue ones are caught later as ink
    (:mod:`labauto.vision.plate_ink`).
    """
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    opened = cv2.morphologyEx(fg, cv2.MORPH_OPEN, disc)
    removed = cv2.compare(fg, opened, cv2.CMP_GT)
    if not removed.any():
        return opened
    # labels without statistics, the areas counted at the pieces' own pixels: several times
    # quicker than connectedComponentsWithStats over the whole image
    n, labels = cv2.connectedComponents(opened, connectivity=8)
    if n <= 1 or n > np.iinfo(np.uint16).max:
        return opened
    xs, ys = cv2.findNonZero(opened).reshape(-1, 2).T
    piece = labels[ys, xs]
    area = np.bincount(piece, minlength=n)
    # the piece within ``size`` px of every removed pixel (16-bit dilation of the labels)
    around = cv2.dilate(labels.astype(np.uint16), disc)
    rx, ry = cv2.findNonZero(removed).reshape(-1, 2).T
    near = np.bincount(around[ry, rx], minlength=n)
    fragment = near > _FRAGMENT_RATIO * area
    fragment[0] = False
    if fragment.any():
        dropped = fragment[piece]
        opened[ys[dropped], xs[dropped]] = 0
    return opened


_HUE_SHARE = 0.5  # an erased body is kept when its departure is at least this much hue
_DOT_SPAN = 1.5  # a lone dot is at most this many opening discs across ...
_DOT_CLEAR = 2.5  # ... with no other foreground within this many discs of its centre


def with_erased_colonies(
    fg: np.ndarray, opened: np.ndarray, image: np.ndarray, background: np.ndarray, disc_px: int
) -> np.ndarray:
    """``opened`` with the bodies of ``fg`` that the opening erased whole and that look like
    small colonies put back: those whose colour departs from the agar mostly in hue, and lone
    dots.

    The opening (:func:`open_thin_lines`, a disc of ``disc_px``) also erases colonies narrower
    than its disc (under ~0.8 mm), and a small colony whose core alone passes eq. 1 is narrower
    still. Lines and printed dots are erased with them. A body erased whole touches nothing
    the opening kept, so putting it back joins nothing; the size, shape and ink tests then
    judge it as any other body.

    * **Hued.** Lines and printed dots are mostly grey or black: they take a like share of
      every channel away, while a pigmented colony shifts the agar's hue. The mean departure
      (B, G, R) of an erased body from the agar's colour behind it is split into its part along
      the grey axis and the rest (each channel minus the mean of the three); the body comes
      back when the rest is at least ``_HUE_SHARE`` of the whole. Measured on the AGAR
      photographs: matched 1501 -> 1539, reported 1558 -> 1599 (on nine plates; 11761 +11,
      11924 +9, 12031 +6, 12028 +4), F1 0.872 -> 0.883, plates over 15 % count error 16 -> 15;
      at 7 px/mm F1 0.848 -> 0.859, at 4.5 px/mm 0.805 -> 0.816; phone-counts unchanged. Hue
      shares of 0.3 and 0.7 gave F1 0.881 and 0.882.
    * **Lone dots.** A grey or white colony under a millimetre is a dot: at most
      ``_DOT_SPAN`` discs across, no more than twice as long as wide, filling at least half of
      its bounding box. Printed dots come in rows of characters, a line's pieces along it:
      a dot comes back only when the foreground within ``_DOT_CLEAR`` discs of its centre
      (a square window) holds no more than half its own area besides it. Putting back every
      erased compact body (no colour, no neighbours) found 80 more colonies but let hundreds of
      printed dots through (precision 0.69). A colony under a millimetre is thin and lets
      light through; a dot that lets through ``INK_PIXEL_DARKER`` (25 %) less light than
      its agar or more is opaque, dust or a full stop, and stays erased (the AGAR dots
      holding a boxed colony let through 9-18 % less; the generator's dust 23-40 %).
      Measured (``benchmarks/bench_real_plates.py``): AGAR matched 1553 -> 1567, reported
      1621 -> 1644 (F1 0.886 -> 0.888; 734 +8, 518 +2), median count error 10.5 -> 11.5 %;
      phone-counts median 3.4 -> 3.0 %; at 7 px/mm F1 0.856 -> 0.860, phone-counts 5.3 ->
      4.8 %; at 4.5 px/mm F1 0.847 -> 0.852, phone-counts 6.6 -> 7.2 %. Clearances of 1.5-4
      discs gave F1 0.887-0.888 (measured before the opacity test).
    """
    removed = cv2.compare(fg, opened, cv2.CMP_GT)
    points = cv2.findNonZero(removed)
    if points is None:
        return opened
    n, labels = cv2.connectedComponents(fg, connectivity=8)
    survived = np.zeros(n, bool)
    kept = cv2.findNonZero(opened)
    if kept is not None:
        kx, ky = kept.reshape(-1, 2).T
        survived[labels[ky, kx]] = True
    x, y = points.reshape(-1, 2).T
    label = labels[y, x]
    erased = ~survived[label]
    if not erased.any():
        return opened
    x, y, label = x[erased], y[erased], label[erased]
    colour, agar = (_label_means(im, x, y, label, n) for im in (image, background))
    departure = colour - agar
    hue = departure - departure.mean(axis=1, keepdims=True)
    hued = np.linalg.norm(hue, axis=1) >= _HUE_SHARE * np.linalg.norm(departure, axis=1)
    # a colony under a millimetre is thin and lets light through; dust and printed dots are
    # opaque: they let through as little light as ink does
    opaque = colour.sum(axis=1) <= (1.0 - INK_PIXEL_DARKER) * agar.sum(axis=1)
    keep = hued | (_lone_dots(fg, x, y, label, disc_px, n) & ~opaque)
    keep = keep[label]
    if not keep.any():
        return opened
    out = opened.copy()
    out[y[keep], x[keep]] = 255
    return out


def _label_means(
    image: np.ndarray, x: np.ndarray, y: np.ndarray, label: np.ndarray, n: int
) -> np.ndarray:
    """Mean B, G, R of ``image`` over the pixels ``(x, y)`` of each of ``n`` labels (n x 3)."""
    values = image[y, x].astype(np.float64)
    count = np.maximum(np.bincount(label, minlength=n), 1)
    sums = [np.bincount(label, values[:, c], minlength=n) for c in range(3)]
    return np.stack(sums, axis=1) / count[:, None]


def _lone_dots(
    fg: np.ndarray, x: np.ndarray, y: np.ndarray, label: np.ndarray, disc_px: int, n: int
) -> np.ndarray:
    """Per label (``n`` of them, ``fg``'s components): its pixels ``(x, y)`` make a lone
    dot (see :func:`with_erased_colonies`)."""
    order = np.argsort(label, kind="stable")
    ids, starts, area = np.unique(label[order], return_index=True, return_counts=True)
    xs, ys = x[order], y[order]
    x0, x1 = np.minimum.reduceat(xs, starts), np.maximum.reduceat(xs, starts)
    y0, y1 = np.minimum.reduceat(ys, starts), np.maximum.reduceat(ys, starts)
    bw, bh = x1 - x0 + 1, y1 - y0 + 1
    long, short = np.maximum(bw, bh), np.minimum(bw, bh)
    dot = (long <= _DOT_SPAN * disc_px) & (2 * short >= long) & (2 * area >= bw * bh)
    # the foreground in a square of 2 * _DOT_CLEAR discs round the dot's centre, by an
    # integral image (rows and columns of the integral are one past the pixel's)
    h, w = fg.shape
    half = int(_DOT_CLEAR * disc_px)
    cx, cy = (x0 + x1) // 2, (y0 + y1) // 2
    ax0, ax1 = np.clip(cx - half, 0, w), np.clip(cx + half + 1, 0, w)
    ay0, ay1 = np.clip(cy - half, 0, h), np.clip(cy + half + 1, 0, h)
    total = cv2.integral(cv2.compare(fg, 0, cv2.CMP_GT) // 255)
    around = total[ay1, ax1] - total[ay0, ax1] - total[ay1, ax0] + total[ay0, ax0] - area
    lone = np.zeros(n, bool)
    lone[ids] = dot & (2 * around <= area)
    return lone
