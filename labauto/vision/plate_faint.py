"""Faint colonies: wide, low-contrast bodies that eq. 1's threshold misses (plate analysis, step 2).

Translucent colonies on pale agar (the AGAR photographs are full of them) depart from the agar by
only 3-8 grey levels, below eq. 1's ``t`` (~25 levels) and barely above the agar's pixel noise;
worse, the fine local background (:func:`labauto.vision.plate_background.local_background`, which
follows the agar's drift over ~4 mm) takes their inside for agar. A colony of several millimetres
is, though, a coherent departure over hundreds of pixels, which smoothing lifts far above the
noise. Choices made here:

* **Coarse background.** The median of the image over cells of 1.6 mm in a window of 9 cells
  (~15 mm, three times the widest faint colony measured), so a colony cannot pull it to its own
  colour; linear interpolation back to the pixels. Under eq. 1's foreground the agar's colour
  (eq. 1's local background) stands in for the colonies found, so that a crowd of them (a
  bent chain along a streak) does not pull the median either, and the agar they enclose does
  not read as departing (AGAR figures unchanged: F1 +0.001).
* **Smoothed deviation.** The signed B, G, R differences from it are smoothed by a Gaussian of
  ``sigma_mm`` before their Euclidean norm is taken (smoothing the signed differences, not the
  squared ones, averages the noise away instead of accumulating it). The work is done on a copy
  at ~4 px/mm: faint colonies are at least ``min_diameter_mm`` (2 mm) across.
* **Threshold from the image.** A pixel is faint foreground when the norm exceeds ``factor``
  times its median over the agar (the agar's own smoothed noise), and at least 3 grey levels.
  Only the agar inside the outer ``margin_mm`` counts (the meniscus is the rim model's business).
* **The hue as well.** The agar's texture (its thickness, the lighting, reflections) is mostly
  a change of brightness, along the grey axis of B, G, R; many faint colonies differ from the
  agar in hue (yellower, less blue) more than in brightness. The deviation's part across the
  grey axis (each channel minus the mean of the three) is searched a second time, with the
  same factor over its own median and the same tests, and the bodies of both searches are
  joined. On six faint AGAR plates that part's median over the agar (boxed colonies left out)
  is 0.5-1.0 levels against 1.2-2.7 for the whole deviation, and a fifth to a half as much
  of the agar lies above the level of the colonies missed before (five plates). It found 84
  bodies, each holding a boxed colony. AGAR reported 1547 -> 1558, matched 1485
  -> 1501 (F1 0.865 -> 0.872), median count error 11.4 -> 10.8 %; at 7 px/mm F1 0.823 ->
  0.834, at 4.5 px/mm 0.758 -> 0.768; phone-counts median 2.9 -> 3.4 %, plates over 15 %
  2 -> 1 (a red print seen through the agar of IMG_2527 is taken for a colony). Factors 3-5
  gave F1 0.868-0.872.
* **Small hued colonies.** The hue search keeps bodies from ``min_hue_diameter_mm`` (1 mm)
  on, the search of the whole deviation only from ``min_diameter_mm`` (2 mm): the agar's
  texture is mostly brightness, so a millimetre-sized body departing in brightness is as
  often texture as a colony, one departing in hue seldom. Of the AGAR boxes missed before, 20
  lay in hue bodies under 2 mm (11761, 11924, 12033: small yellowish colonies). Measured
  (``benchmarks/bench_real_plates.py``), 1 mm against 2 mm: AGAR reported 1653 -> 1678,
  matched 1596 -> 1615 (F1 0.902 -> 0.906), plates over 15 % 13 -> 10; over 8 one-pixel
  shifts F1 0.901 -> 0.906 (0.896-0.904 -> 0.901-0.909), median count error 8.4 -> 7.6 %,
  plates over 15 % 13.6 -> 11.8; at 7 px/mm F1 0.892 -> 0.896 (median 10.8 -> 6.5 %), at
  4.5 px/mm 0.877 -> 0.882 (10.0 -> 10.7 %); phone-counts (white colonies) the same on every
  plate at every scale. 0.8 and 1.2 mm gave F1 0.907 and 0.905. Taking the whole deviation's
  bodies from 1 mm on as well: +1 matched for +8 reported, phone-counts 2.5 -> 3.1 %.
  A body under ``min_diameter_mm`` must depart ``_SMALL_CONTRAST`` (1.25) times the
  threshold (its median norm): a millimetre blotch of the agar's texture, or of the colour
  blocks of a strongly compressed JPEG, is as small. With the photos recompressed at quality
  40 (``--perturb jpeg:40``) the hue search from 1 mm had cost AGAR F1 0.896 -> 0.889 (51
  more reported, 10 more matched; 14618 +5, 11890 +3 false); with this rule 0.898.
  On the photos as taken it drops 2 bodies, none boxed (1626 matched either way; median count
  error 7.3 -> 5.7 %); 1.5 times dropped 4 matched ones.
* **Bodies.** Components are filled (ring-shaped colonies: dark edge, agar-coloured inside) and
  kept when they look like a colony or a small cluster, not a lighting drift: between
  ``min_diameter_mm`` and ``max_diameter_mm`` as a disc, solidity (area over convex hull) >= 0.9,
  roundness (area over the smallest enclosing circle) >= 0.6, and overlapping eq. 1's foreground
  by at most ``max_overlap`` of their area, so colonies found already are neither grown nor
  joined to their neighbours. The bodies then pass the same artefact and class tests as all
  others (ink, elongation, DES, waist).

* **An edge.** A colony has a boundary; a drift of the agar's colour (thickness, lighting, the
  generator's agar texture) changes over millimetres. The 75th percentile of the gradient norm
  (3x3 Sobel of the smoothed differences, per work pixel) in a 5-pixel band round the outline
  must be at least 0.25 times the body's contrast (its median norm); measured: faint colonies
  on the AGAR photographs 0.26-0.79, agar texture on the synthetic plates 0.16-0.23 (a 2.3 mm
  blotch of the generator's grain read 0.23 and passed the former limit of 0.22; 0.25 costs
  one matched AGAR colony of 1479). A large colony's edge may be wider than a millimetre and
  still sharp for its size: the limit is 1.5 over the body's radius (work pixels) where that is
  less, but never under 0.15. The large soft colonies of the AGAR photographs read 0.18-0.22
  at radii of 9-14 work pixels: AGAR matched 1481 -> 1485 (F1 0.857 -> 0.858), median count
  error 10.5 -> 10.0 %; phone-counts unchanged; the synthetic plates still show no texture
  body. A threshold from the lower quartile of the agar's norm (robust to a plate half covered
  by faint colonies, as 12031) found 20 more AGAR colonies but took the generator's textured
  agar (its norm spreads wider than the real agar's: median over lower quartile 1.9-2.0, the
  sparse AGAR plates 1.5-1.7) for colonies, so the median stays.
* **A body departing as a whole.** A small, strong speck (dust, 0.2-0.5 mm) is eq. 1's
  foreground but no colony; the smoothing spreads it into a faint disc of about a millimetre
  that overlaps it by less than ``max_overlap``. A faint colony departs over its whole body, so
  the median over the body of the unsmoothed departure, taken along the body's mean smoothed
  departure, must be at least ``_MIN_SPREAD`` (0.5) times its contrast; a speck's median is
  the agar's. With the hue search from 1 mm, the generator's dust on 4 of the 6 plates of
  ``benchmarks/bench_plate.py`` gave 1 false colony (4 with the dish given); this test leaves
  none, and changes nothing on the real photographs (at 0.5 and 0.7).

Measured on the real plates of ``benchmarks/bench_real_plates.py`` with the default ``factor``
4: AGAR recall 0.705 -> 0.730 at precision 0.908 -> 0.905 (F1 0.793 -> 0.808); phone-counts
within one colony per plate. Factor 3 finds a little more on the AGAR plates (F1 0.811) but
takes agar texture on 8 of 13 synthetic plates for colonies (contrast 1.2-1.4 times ``t``).
Varying ``sigma_mm`` 0.15-0.4, ``min_diameter_mm`` 1.5-3 or the window 9-13 cells moved AGAR F1
by at most 0.003.

Tried and not kept (AGAR F1 0.894 as it stands). The noise median taken only away from eq. 1's
foreground gave 0.895 and moved phone-counts 2.3 -> 2.7-3.0 %. Letting a body overlap eq. 1's
pieces that lie mostly inside it (as ring colonies do) gave 0.879: ordinary colonies' halos
then join their neighbours. Touching faint colonies split by a watershed of the distance
transform gave 0.892 with none more matched: the parts of 11924's chains are ragged
(solidity 0.25-0.7). An opening of 1-3 work pixels before the tests gave 0.887-0.894. A
second pass at 12 px/mm for colonies of 0.4-2 mm gave 0.893-0.896, about half its finds false.
Searching the rim's band as well (AGAR F1 0.910 as it stands; large faint colonies within
4 mm of the dish's edge are missed: 11924, 12031, 12033, 510), out to 0.5 or 1 mm from the
usable area's border, with eq. 1's background there (the rim's radial profile) in place of the
cell median: reported 1687 -> 1700 / 1697, matched 1626 -> 1631 / 1630 (F1 0.910 either way,
recall 2-4 mm inside the edge 0.75 -> 0.80), phone-counts 1.9 -> 2.1 %; the band's lines and
reflections gave false colonies on sparse plates (11890 +2, 11955 +1, 11773 +1).
Large faint colonies that overlap eq. 1's foreground by more than ``max_overlap`` (11773, 11884,
14130, 12033, 11955: 0.22-0.37 of their area) hold it in their cores (0.10-0.54 of the pixels at
least half their depth inside), not along their edge as a ring colony would: a body whose overlap
lies along its edge (at most 0.1 of its core, 0.5 of it all) allowed, reported +1, matched +0. Eq.
1's pixels there are specks the opening removes later; the overlap counted against eq. 1's
foreground opened by 0.75 mm: reported 1687 -> 1701, matched 1626 -> 1631 (F1 0.909), median count
error 5.7 -> 8.3 % (2026-12-07, seventh session). Of the 118 boxes of 4 mm and over whose centre
lies in no reported body (some still matched, by a body's centroid in the box; that session), 38
lie below the threshold of both searches, 27 in the rim's band, about 30 in components too large or
not round (touching faint colonies, texture) and 10 in ones overlapping eq. 1's foreground. Such
components cut again above 1.25, 1.5 and 2 (or 1.5, 2 and 3) times the threshold, each piece tested
as above: +1 matched, +2 reported. A second search smoothed by 0.6 or 1 mm for bodies from 4 mm
(more smoothing, less noise for a wide colony): +7 matched for +12 reported (phone-counts 4 -> 5
plates over 15 %), and +1 for +2; ``sigma_mm`` 0.5 or 0.8 alone: F1 0.908 and 0.903.
Eighth session (2026-12-07), against AGAR F1 0.910 and phone-counts 1.9 % with 4 plates over
15 %. ``factor`` 3: reported 1687 -> 1708, matched 1626 -> 1641 (F1 0.913), phone-counts 2.1 %
with 5 plates over 15 %, and 10 false colonies rather than 1 on 24 generated plates (seeds
1000-1023, six agars). Factor 3 or 3.5 only for bodies from 3 or 4 mm, the former threshold
below: F1 0.911-0.912 (+6 to +11 matched for +7 to +16 reported), phone-counts 5 plates over
15 %; both within the one-pixel jitter (F1 0.905-0.913). Solidity 0.8 and roundness 0.5: F1
0.909, phone-counts 2.2 %, 5 over; the edge limits 0.1 and 0.05: F1 0.912, phone-counts 2.3 %;
all relaxed at once (with factor 3): reported 1775, matched 1652 (F1 0.902), phone-counts
3.9 %, 6 over: 26 more boxed colonies among 88 more bodies, the most a classifier of these
candidates could win. The edge test waived for round, convex bodies from 4 mm (roundness
0.8-0.85, solidity 0.95): nothing changes on the photos as taken, and at exposure x0.6
(``--perturb gain:0.6``, where 72 more boxed colonies of 4 mm and over lie in no body) 7 come
back: 8386's soft colonies of 8-10 mm read 0.57-0.98 of the edge limit, 525's fail the overlap
or shape tests. Print left out of the smoothing (a normalised convolution without eq. 1's
ink-coloured pixels, which then no longer count as overlap): reported 1686, matched 1627 (F1
0.911); 510 keeps its 26 missed colonies of 4 mm and over: most lie below the threshold at
their centre (ring colonies: the inside is the agar's colour) or in the rim's band. A
scale-space blob search (differences of Gaussians of the signed difference for radii of
1.25-5 mm, maxima over space and scale, a disc overlapping eq. 1's foreground by at most 0.2):
at 6, 15 and 30 times its median over the agar it put a candidate on 20, 5 and 0 boxed
colonies that lie in no body, and 1992, 560 and 63 candidates on no boxed colony: the agar's
texture, print and the wall's lines respond as strongly as the colonies missed.

A learned pass, tried and not kept (AGAR F1 0.895 as it stands): a small U-Net (16-64
channels, 4 levels) on the work copy's signed difference from the coarse background, trained
on the AGAR boxes (ellipses inscribed in them, 800 steps of 8 crops of 128 px), its pixels
above a logit of 1 taken as bodies with the size and overlap tests above, run by OpenCV's
``dnn`` from ONNX. Plate-wise cross-validated (5 folds of 7-8 plates, each fold's plates
analysed with the model trained on the others): AGAR reported 1651 -> 1731, matched 1582 ->
1631 (F1 0.902), median count error 12.3 -> 7.1 % (11764 +5 matched, 11924 +6, 12031 +7; 510
+1 for 4 false). But on the photos it was not trained on it found what is not there: a model
of one fold put the phone-counts median at 4.0 % with 8 plates over 15 % (2.0 % and 4), and
it took the generator's agar texture and artefacts for 39 colonies on the 6 synthetic plates
of ``bench_plate`` (0 without it). With the solidity and roundness tests above, AGAR F1 0.899
and 8.8 %, phone-counts 2.0 % (a colony or two more on 9 plates), still the 39 synthetic
false colonies; and 50 ms more per plate on this machine's 2 cores.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np

from labauto.vision.median import median

_CELL_MM = 1.6  # cell of the coarse background
_MEDIAN_CELLS = 9  # its median window, in cells (~15 mm)
_WORK_PX_PER_MM = 4.0  # resolution of the smoothed deviation
_FLOOR = 3.0  # least threshold, grey levels (Euclidean over B, G, R)
_MIN_SOLIDITY = 0.9
_MIN_ROUNDNESS = 0.6
_MIN_EDGE = 0.25  # least edge gradient (per work pixel) relative to a body's contrast
_EDGE_RADII = 1.5  # ... or this over the body's radius (work pixels), if that is less ...
_LEAST_EDGE = 0.15  # ... but never less than this
_GREY = np.full((3, 3), 1 / 3, np.float32)  # cv2.transform: each channel to the mean of the three
_RING = np.ones((5, 5), np.uint8)  # the band round a body's outline where its edge is read
_MIN_SPREAD = 0.5  # least median unsmoothed departure of a body, relative to its contrast
_SMALL_CONTRAST = 1.25  # a body under the grey search's least size departs this much more


def faint_bodies(
    image: np.ndarray,
    usable: np.ndarray,
    foreground: np.ndarray,
    px_per_mm: float,
    *,
    factor: float = 4.0,
    sigma_mm: float = 0.25,
    min_diameter_mm: float = 2.0,
    max_diameter_mm: float = 12.0,
    min_hue_diameter_mm: float = 1.0,
    max_overlap: float = 0.2,
    margin_mm: float = 4.0,
    agar_colour: np.ndarray | None = None,
    chroma: bool = True,
) -> np.ndarray:
    """A mask (uint8, 0 / 255) of the faint bodies to add to eq. 1's ``foreground``.

    Parameters
    ----------
    image : ndarray
        HxWx3 BGR uint8 (the dish's bounding box, as analysed).
    usable : ndarray
        HxW uint8 mask of the usable agar.
    foreground : ndarray
        HxW uint8 mask of eq. 1's foreground.
    px_per_mm : float
        Scale of ``image``.
    factor, sigma_mm, min_diameter_mm, max_diameter_mm, max_overlap, margin_mm
        See the module docstring.
    min_hue_diameter_mm : float
        Least size (as a disc) of the bodies of the hue search ("Small hued colonies" in the
        module docstring).
    agar_colour : ndarray, optional
        HxWx3 BGR uint8: the agar's colour under eq. 1's foreground (its local background);
        the coarse background is estimated with it in place of the colonies found.
    chroma : bool
        Also search the deviation's part across the grey axis, its hue ("The hue as well" in
        the module docstring).
    """
    h, w = usable.shape
    empty = np.zeros((h, w), np.uint8)
    step = max(1, round(px_per_mm / _WORK_PX_PER_MM))
    ppm = px_per_mm / step
    if h < step or w < step:
        return empty  # smaller than one work pixel: nothing faint to find
    # whole blocks of step x step pixels (OpenCV's integer-factor path: ~10x faster); a last
    # partial row or column is left out
    sw, sh = max(w // step, 1), max(h // step, 1)
    whole = (slice(0, sh * step), slice(0, sw * step))
    img = cv2.resize(image[whole], (sw, sh), interpolation=cv2.INTER_AREA)
    agar = cv2.resize(usable[whole], (sw, sh), interpolation=cv2.INTER_NEAREST)
    fine = cv2.resize(foreground[whole], (sw, sh), interpolation=cv2.INTER_NEAREST)

    seen = img  # what the coarse background is the median of: the agar, not the colonies found
    if agar_colour is not None:
        seen = img.copy()
        under = cv2.resize(agar_colour[whole], (sw, sh), interpolation=cv2.INTER_AREA)
        cv2.copyTo(under, fine, seen)
    cell = max(round(_CELL_MM * ppm), 1)
    cells = cv2.resize(seen, (max(sw // cell, 1), max(sh // cell, 1)), interpolation=cv2.INTER_AREA)
    window = min(_MEDIAN_CELLS, 2 * ((min(cells.shape[:2]) - 1) // 2) + 1)
    cell_medians = cv2.medianBlur(cells, window) if window > 1 else cells
    background = cv2.resize(cell_medians, (sw, sh), interpolation=cv2.INTER_LINEAR)
    raw = cv2.subtract(img, background, dtype=cv2.CV_32F)
    diff = cv2.GaussianBlur(raw, (0, 0), sigma_mm * ppm)

    # the agar farther than margin_mm from its border (a distance transform: a wide erosion's
    # work in one pass)
    depth = cv2.distanceTransform(agar, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    inner = cv2.compare(depth, margin_mm * ppm, cv2.CMP_GT)
    disc = math.pi / 4 * ppm**2  # work pixels in a disc 1 mm across
    least = disc * min_diameter_mm**2
    limits = _Limits(factor, least, disc * max_diameter_mm**2, max_overlap, small_area=least)
    kept = _bodies_departing((diff, raw), inner, fine, limits)
    if chroma:  # the departure across the grey axis: a hue, whatever the brightness does
        hue = tuple(cv2.subtract(d, cv2.transform(d, _GREY)) for d in (diff, raw))
        limits = limits._replace(min_area=disc * min_hue_diameter_mm**2)
        kept += _bodies_departing(hue, inner, fine, limits)
    if not kept:
        return empty
    small_mask = np.zeros_like(fine)
    for outline in kept:  # one by one: outlines of the two passes may overlap
        cv2.drawContours(small_mask, [outline], -1, 255, cv2.FILLED)
    mask = cv2.resize(small_mask, (sw * step, sh * step), interpolation=cv2.INTER_LINEAR)
    empty[whole] = cv2.compare(mask, 127, cv2.CMP_GT)
    return empty


class _Limits(NamedTuple):
    """What a faint body must meet (areas in work pixels)."""

    factor: float  # the threshold over the agar's median norm
    min_area: float  # least and largest area
    max_area: float
    max_overlap: float  # largest share overlapping eq. 1's foreground
    small_area: float  # under this a body must reach _SMALL_CONTRAST times the threshold


def _bodies_departing(
    departure: tuple[np.ndarray, np.ndarray],
    inner: np.ndarray,
    fine: np.ndarray,
    limits: _Limits,
) -> list[np.ndarray]:
    """Outlines of the colony-like bodies where the norm of ``diff`` departs from the agar's.

    ``departure`` is ``(diff, raw)``: the signed difference from the coarse background (work
    pixels, 3 channels), smoothed and as it is. ``inner`` is the agar whose norm sets the
    threshold, ``fine`` eq. 1's foreground.
    """
    diff, raw = departure
    factor, min_area, max_area, max_overlap, small_area = limits
    norm = cv2.sqrt(cv2.transform(cv2.multiply(diff, diff), np.ones((1, 3), np.float32)))
    samples = norm[inner > 0]
    if samples.size == 0:
        return []
    t = max(_FLOOR, factor * median(samples))
    faint = cv2.bitwise_and(cv2.compare(norm, t, cv2.CMP_GT), inner)
    outlines, _ = cv2.findContours(faint, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    kept = []
    for outline in outlines:
        if not 0.5 * min_area <= cv2.contourArea(outline) <= 2.0 * max_area:
            continue  # far outside the size range: no need to fill it
        x, y, bw, bh = _padded_rect(outline, 2, faint.shape)
        body = np.zeros((bh, bw), np.uint8)
        cv2.drawContours(body, [outline], -1, 255, cv2.FILLED, offset=(-x, -y))
        area = cv2.countNonZero(body)
        if not min_area <= area <= max_area:
            continue
        window = (slice(y, y + bh), slice(x, x + bw))
        overlap = cv2.countNonZero(cv2.bitwise_and(body, fine[window]))
        if overlap > max_overlap * area:
            continue
        solidity = area / max(cv2.contourArea(cv2.convexHull(outline)), 1.0)
        _, radius = cv2.minEnclosingCircle(outline)
        if solidity < _MIN_SOLIDITY or area / (math.pi * radius * radius) < _MIN_ROUNDNESS:
            continue
        inside = body > 0
        contrast = median(norm[window][inside])
        if area < small_area and contrast < _SMALL_CONTRAST * t:
            continue  # small: a blotch of the agar's texture or of a JPEG's colour blocks
        ring = cv2.subtract(cv2.dilate(body, _RING), cv2.erode(body, _RING))
        sharpness = float(np.percentile(_edge_in(diff, (x, y, bw, bh))[ring > 0], 75))
        # the edge is at most a millimetre wide, or (a large colony) 1 / _EDGE_RADII of its
        # radius, with a floor
        least = max(min(_MIN_EDGE, _EDGE_RADII / math.sqrt(area / math.pi)), _LEAST_EDGE)
        if sharpness < least * contrast:
            continue  # no edge: a drift of the agar's colour, not a colony
        if _spread(diff[window][inside], raw[window][inside]) < _MIN_SPREAD * contrast:
            continue  # a speck smeared by the smoothing, not a body departing as a whole
        kept.append(outline)
    return kept


def _spread(smoothed: np.ndarray, raw: np.ndarray) -> float:
    """The median of a body's unsmoothed departure along its mean smoothed one (Nx3 each)."""
    along = smoothed.mean(axis=0)
    length = float(np.linalg.norm(along))
    return float(np.median(raw @ (along / length))) if length > 0 else 0.0


def _edge_in(diff: np.ndarray, rect: tuple[int, int, int, int]) -> np.ndarray:
    """:func:`_gradient_norm` of ``diff`` within ``rect`` (x, y, w, h), as over the whole image.

    It is taken on the rectangle grown by the Sobel's 1 px wherever the image has it, so that
    only the image's own border is reflected: the same values as on the whole image, for only
    the few candidates that reach this test.
    """
    x, y, bw, bh = rect
    x0, y0 = max(x - 1, 0), max(y - 1, 0)
    x1, y1 = min(x + bw + 1, diff.shape[1]), min(y + bh + 1, diff.shape[0])
    edge = _gradient_norm(diff[y0:y1, x0:x1])
    return edge[y - y0 : y - y0 + bh, x - x0 : x - x0 + bw]


def _gradient_norm(image: np.ndarray) -> np.ndarray:
    """Euclidean norm over the channels of the 3x3 Sobel gradient, in levels per pixel."""
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    squares = cv2.add(cv2.multiply(gx, gx), cv2.multiply(gy, gy))
    return cv2.sqrt(cv2.transform(squares, np.ones((1, 3), np.float32)))


def _padded_rect(
    outline: np.ndarray, pad: int, shape: tuple[int, int]
) -> tuple[int, int, int, int]:
    """The outline's bounding rectangle grown by ``pad`` pixels, inside an image of ``shape``."""
    x, y, bw, bh = cv2.boundingRect(outline)
    x0, y0 = max(x - pad, 0), max(y - pad, 0)
    x1, y1 = min(x + bw + pad, shape[1]), min(y + bh + pad, shape[0])
    return x0, y0, x1 - x0, y1 - y0
