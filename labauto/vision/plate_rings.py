"""Ring colonies: a round edge with little body inside (plate analysis, step 2).

Some translucent colonies on pale agar (AGAR plate 510 is full of them) differ from the agar
only at their edge: a thin darker ring round an inside of nearly the agar's own colour. Eq. 1's
threshold and the faint pass (:mod:`labauto.vision.plate_faint`), which look for a departure of
the body, find at most a crescent of them. Their edge, though, is a closed circle whose
gradients all point along its radius: the DES property the paper builds on, here read with the
circular Hough transform. Choices made here:

* **Circles.** ``cv2.HoughCircles`` with ``HOUGH_GRADIENT_ALT`` (Canny edges, circle votes along
  the gradient, each candidate scored by how complete and how round its edge is) on the grey
  image resampled to 4 px/mm and smoothed by a Gaussian of 1 work pixel (0.25 mm). Diameters
  ``min_diameter_mm``-``max_diameter_mm``; ``canny_high`` is Canny's upper threshold (grey
  levels of the 3x3 Sobel), ``perfectness`` the least score (``param2``). On the AGAR
  photographs F1 stayed within 0.835-0.846 over ``canny_high`` 20-45 and ``perfectness``
  0.7-0.9 (at 6 px/mm), and within 0.839-0.843 at 4, 6 and 8 px/mm. ``canny_high`` 45 rather
  than 30 halves the time on the generator's noisy agar and takes none of its texture for a
  ring; 60 would save another ~3 ms but found 32 rather than 37 colonies on plate 510.
* **An edge, not texture.** The circle's edge (the median over 48 angles of the largest radial
  gradient within 1 px of it) must be at least ``_MIN_EDGE`` (2) times the agar's texture (the
  median gradient norm over the agar). The generator's blotchy agar at a webcam's scale gave
  a circle at 1.56 times, a pickable "colony"; colonies found already read 7-31 times. On the
  AGAR photographs the rule drops 9 of the 1488 colonies matched (1.3-1.6 times would drop
  1, 1.8 times 5): the price of a margin over what the texture gave.
* **Inside the agar.** A circle must lie whole on the usable area, ``margin_mm`` (1 mm) inside
  its border: arcs of the meniscus and the wall also vote for circles.
* **New, not found already.** A circle whose disc eq. 1's foreground covers by more than
  ``max_found`` (a fifth) is a colony found already (or a bubble, glare, a label: strong
  contrast that eq. 1 sees, so the artefact tests have it); one that overlaps a disc accepted
  before by more than 5 % is the same ring again (circles come strongest first).
* **Pieces and neighbours.** Foreground pieces lying mostly (half their area or more) inside
  the disc are pieces of this colony (its crescent, its darker centre) and join it; the others
  are neighbours, and the disc keeps 2 px away from them so it never joins two colonies.

The filled disc is added to the foreground, and the body then passes the same artefact and
class tests as every other (ink, elongation, DES, waist).

Measured with ``benchmarks/bench_real_plates.py``, the pass on against off (``find_rings``):
AGAR 1577 -> 1612 colonies reported, 1446 -> 1479 matched (F1 0.835 -> 0.846); plate 510
found 16 -> 34 of 69 boxed, 11924 19 -> 23; over-counted more: 13895 19 -> 21 (19 boxed),
14512 14 -> 18 (15). The median count error moved 10.0 -> 11.8 % (plates near the median went
over their truth); phone-counts 2.9 % either way. It costs 7-10 ms per 1.3-Mpixel
plate of the generator (``benchmarks/bench_plate.py``), most of it in ``cv2.HoughCircles``.
The centre is the Hough circle's, within one accumulator cell (1.5 work pixels, ~0.4 mm).
Not found: rings under 2 mm, rings cut by another body, and the large soft-edged colonies of
plates 12031 and 11924 (their edge spreads over a millimetre or more: no Canny edge). A second
search at 2-4 px/mm (Canny 6-20, perfectness 0.3-0.8) did not find them either: it kept 0-5
circles on 12031, whose missed large colonies stayed 19-20; AGAR F1 0.892-0.895 against 0.894.
Swept again on the pipeline of 2026-12-07 (F1 0.910, eighth session): ``canny_high`` 30-60 with
``perfectness`` 0.7-0.8 gave F1 0.910-0.911, median count error 5.7-6.5 %, phone-counts
1.9-2.1 %.
A blurred red blot seen through the agar of phone photo IMG_2525 (6.6 mm) comes in as a ring
colony. A ring's inside of the agar's grey, which the blot's is not, does not tell them apart:
the rings found on the AGAR photographs read -11 to +12 grey levels from the agar round them
at their centre and -17 to +14 on their edge, the blot -7 and 0 (ninth session).
"""

from __future__ import annotations

import cv2
import numpy as np

from labauto.vision.median import median

_WORK_PX_PER_MM = 4.0  # resolution of the circle search
_SIGMA_PX = 1.0  # smoothing, work pixels
_REPEAT = 0.05  # a circle overlapping an accepted one by more than this is the same ring
_PART = 0.5  # a piece with at least this share of its area in the disc is part of it
_GAP = np.ones((5, 5), np.uint8)  # the disc keeps 2 px away from its neighbours
_MIN_EDGE = 2.0  # least edge strength of a ring, in units of the agar's texture gradient


def ring_circles(
    image: np.ndarray,
    usable: np.ndarray,
    px_per_mm: float,
    *,
    canny_high: float = 45.0,
    perfectness: float = 0.8,
    min_diameter_mm: float = 2.0,
    max_diameter_mm: float = 12.0,
) -> np.ndarray:
    """The circles ``(x, y, r)`` (image pixels, strongest first) whose edge stands out.

    The circle search, on the image alone (no foreground; :func:`ring_bodies` then tests the
    circles against it): plate analysis runs it in a thread of its own beside eq. 1's
    segmentation.

    Parameters
    ----------
    image : ndarray
        HxWx3 BGR uint8 (the dish's bounding box, as analysed).
    usable : ndarray
        HxW uint8 mask of the usable agar (the texture's reference).
    px_per_mm : float
        Scale of ``image``.
    canny_high, perfectness, min_diameter_mm, max_diameter_mm
        See the module docstring.
    """
    none = np.zeros((0, 3), np.float64)
    scale = min(_WORK_PX_PER_MM / px_per_mm, 1.0)
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)  # then resampled: a third of the work
    small = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    if min(small.shape[:2]) < 8:
        return none
    grey = cv2.GaussianBlur(small, (0, 0), _SIGMA_PX)
    ppm = px_per_mm * scale
    circles = cv2.HoughCircles(
        grey,
        cv2.HOUGH_GRADIENT_ALT,
        dp=1.5,
        minDist=min_diameter_mm * ppm,
        param1=canny_high,
        param2=perfectness,
        minRadius=max(round(min_diameter_mm * ppm / 2), 3),
        maxRadius=max(round(max_diameter_mm * ppm / 2), 4),
    )
    if circles is None:
        return none
    agar = cv2.resize(usable, (grey.shape[1], grey.shape[0]), interpolation=cv2.INTER_NEAREST)
    return circles[0][_stands_out(grey, agar, circles[0])] / scale


def ring_bodies(
    usable: np.ndarray,
    foreground: np.ndarray,
    circles: np.ndarray,
    px_per_mm: float,
    *,
    max_found: float = 0.2,
    margin_mm: float = 1.0,
) -> np.ndarray:
    """``foreground`` (uint8 0 / 255) with the ring colonies of ``circles`` filled in.

    Parameters
    ----------
    usable : ndarray
        HxW uint8 mask of the usable agar.
    foreground : ndarray
        HxW uint8 mask of eq. 1's (and the faint pass's) foreground; not changed.
    circles : ndarray
        :func:`ring_circles` of the image.
    px_per_mm : float
        Scale of the image.
    max_found, margin_mm
        See the module docstring.
    """
    out = foreground.copy()
    h, w = usable.shape
    margin = margin_mm * px_per_mm
    accepted = np.zeros((h, w), np.uint8)
    for x, y, r in circles.tolist():
        cx, cy, radius = round(x), round(y), round(r)
        reach = round(r + margin) + 1  # the disc and its margin; a neighbour's reach beyond
        x0, y0, x1, y1 = cx - 2 * reach, cy - 2 * reach, cx + 2 * reach + 1, cy + 2 * reach + 1
        if min(cx - reach, cy - reach) < 0 or cx + reach >= w or cy + reach >= h:
            continue
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        centre = (cx - x0, cy - y0)
        disc = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.circle(disc, centre, round(r + margin), 255, -1)
        if cv2.countNonZero(cv2.bitwise_and(disc, cv2.bitwise_not(usable[y0:y1, x0:x1]))):
            continue  # not whole on the agar
        disc[:] = 0
        cv2.circle(disc, centre, radius, 255, -1)
        inside = disc > 0
        area = int(np.count_nonzero(inside))
        if np.count_nonzero(accepted[y0:y1, x0:x1][inside]) > _REPEAT * area:
            continue
        crop = foreground[y0:y1, x0:x1]
        n, labels = cv2.connectedComponents(crop, connectivity=8)
        covered = np.bincount(labels[inside], minlength=n)
        covered[0] = 0
        if covered.sum() > max_found * area:
            continue
        neighbours = (covered > 0) & (covered < _PART * np.bincount(labels.ravel(), minlength=n))
        if neighbours.any():
            near = cv2.dilate(neighbours[labels].astype(np.uint8), _GAP)
            disc[near > 0] = 0
        accepted[y0:y1, x0:x1][inside] = 255
        out[y0:y1, x0:x1] |= disc
    return out


def _stands_out(grey: np.ndarray, agar: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """True for every circle ``(x, y, r)`` whose edge stands out from the agar's texture.

    The edge strength is the median over 48 angles of the largest radial gradient within 1 px
    of the circle; the agar's texture is the median gradient norm over ``agar`` (3x3 Sobel,
    levels per work pixel). A circle needs ``_MIN_EDGE`` times the texture.
    """
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    on_agar = cv2.magnitude(gx, gy)[agar > 0]
    texture = median(on_agar) if on_agar.size else 0.0
    h, w = grey.shape
    theta = np.linspace(0.0, 2 * np.pi, 48, endpoint=False)
    cos, sin = np.cos(theta)[None, :, None], np.sin(theta)[None, :, None]
    x, y, r = (circles[:, k, None, None] for k in range(3))
    radius = r + np.array([-1.0, 0.0, 1.0])[None, None, :]
    px = np.clip(np.rint(x + radius * cos), 0, w - 1).astype(np.intp)
    py = np.clip(np.rint(y + radius * sin), 0, h - 1).astype(np.intp)
    radial = np.abs(gx[py, px] * cos + gy[py, px] * sin).max(axis=2)
    return np.median(radial, axis=1) >= _MIN_EDGE * texture
