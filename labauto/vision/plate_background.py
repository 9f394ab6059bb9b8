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

**The exposure.** ``t`` is in grey levels, so the camera's exposure moves it against the
colonies: the AGAR photographs exposed at 0.6 times (``bench_real_plates.py --perturb
gain:0.6``) give F1 0.860 and a median count error of 13.6 % (0.910 and 5.7 % as taken). A
camera known to be darker or brighter than those photos is served by ``color_threshold``
scaled by the square of the exposure: 216 at 0.6 times gives F1 0.903 (10.0 %), 1014 at 1.3
times 0.910 (9.5 %; 0.891 and 8.8 % at 600). The exposure cannot be read from one photo
without confusing it with the agar's colour, and ``t`` stays fixed. Measured and not kept
(2026-12-07, seventh session; AGAR F1 / median count error, phone-counts median / plates over
15 %; 0.910 / 5.7 %, 1.9 % / 4 as it stands):

* ``t`` times the square of the agar's brightness (the mean of eq. 1's background over the
  usable area) over 160, the pale AGAR plates' (Weber's law): 0.878 / 8.3 %, 6.5 % / 11; at
  0.6 times 0.856. The mean grey within 0.8 of the dish's radius is 129-207 on the 4000-px
  AGAR photos and 48-86 on the 2048-px ones and the phone photos, whose white colonies stand
  far above it: their ``t`` fell to about a fifth, and they were over-counted.
* ``t`` times the square of the photo's white point (the 99.9th percentile of the brightest
  channel over the dish's bounding box, every fourth pixel) over 215: 0.908 / 5.7 %, 3.3 % / 4;
  at 0.6 times 0.880 / 12.1 %, at 1.3 times (the factor allowed up to 2) 0.907 / 5.7 %. The
  phone photos' white points (145-201 over the whole photo, against 183-255 on the AGAR
  photos) are their dark scenes, not a short exposure.
* The agar's noise as the yardstick (``noise_factor``; the median of ``dev`` over the agar,
  2-35 levels squared over the plates of both sets): ``t`` is 17-300 times that median, so no
  one factor fits.
* ``t`` times the square of the plate's strongest contrasts (the 99.9th percentile of
  ``sqrt(dev)`` over the usable area: colonies, print, the wall's lines) over a reference,
  never more than 1 (eighth session). They read 122-267 levels on the 67 photos as taken and
  75-161 at 0.6 times: a reference of 120 leaves every photo as taken alone and gives 0.879 /
  9.1 % at 0.6 times (phone-counts 2.3 %). But that reference is the least of these sets:
  150 and 180, which lower ``t`` on the photos as taken whose contrasts are modest, give 0.907
  and 0.894 there (phone-counts 2.8 % at 180). The measure is the plate's content as much as
  its exposure, and a plate of other sets with modest contrasts would lose the same way.

Also measured and not kept: the deviation's part across the grey axis (its hue) weighted ``k``
times its part along it (the agar's texture is mostly brightness, many faint colonies differ
in hue): ``k`` 2 gave AGAR matched +1 for +2 reported, phone-counts 1.9 -> 2.7 %; ``k`` 4 -3
matched for +28 reported (F1 0.901, 8.5 %).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.vision.median import median

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
_RIM_LINE_MM = 1.0  # the profile is a running median over this much radius: no thin lines
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
    image: np.ndarray, rim: tuple[float, float, float], band_px: float, px_per_mm: float = 0.0
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
    The sector medians are then a running median over ``_RIM_LINE_MM`` (1 mm) of radius
    (``px_per_mm`` given; 0 leaves it out): a median keeps the meniscus' ramps and steps where
    they are and takes out what is narrower than half its window, the lid's and the wall's
    thin ring lines. In the profile, such a line had been part of the agar's colour, and a
    colony crossing it was cut in two along it (AGAR plates 5207 and 5270: a crescent of a
    colony counted as a second one); now the line is foreground, opened away as any thin line,
    and the colony stays whole. Measured (``benchmarks/bench_real_plates.py``): AGAR reported
    1643 -> 1646, matched 1582 -> 1590 (F1 0.897 -> 0.900; recall within 2 mm of the dish's
    edge 0.46 -> 0.54), median count error 9.1 -> 8.8 %; phone-counts 2.0 -> 2.5 % (the
    plates' absolute count errors summed 182 -> 171); at 7 px/mm F1 0.887 -> 0.890, phone-counts
    3.5 -> 3.9 % (summed errors 182 -> 181); at 4.5 px/mm F1 0.874 -> 0.877, phone-counts
    4.1 % either way. A median over 0.6 mm gave F1 0.898 and phone-counts 2.7 %, over 1.5 mm
    0.901 / 0.889 / 0.876 at the three scales with phone-counts 2.1 / 4.0 / 3.8 %.
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
    window = 2 * round(_RIM_LINE_MM * px_per_mm / 2) + 1  # odd
    if 1 < window < n_r:  # a running median along the radius, the ends repeated
        half = window // 2
        padded = np.pad(medians, ((0, 0), (half, half), (0, 0)), mode="edge")
        runs = np.lib.stride_tricks.sliding_window_view(padded, window, axis=1)
        medians = np.median(runs, axis=-1).astype(np.float32)
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
