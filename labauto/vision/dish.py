"""The petri dish on a plate image: validating the image and finding the agar disc.

``find_dish`` takes a Hough circle on a subsampled grey image as a first guess, moves it to the
dish's strongest circular edge and from there finds the agar's edge, along rays at full
resolution (see its docstring); the plate analysis ignores everything outside the dish shrunk by
a rim margin (wall, labels, pen marks on the rim).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from labauto.vision.image import as_image
from labauto.vision.median import median

_DISH_EDGE_CONTRAST = 18.0  # colour distance (grey levels) from the agar that marks its edge
_LINE_MM = 4.0  # a departure followed within this by ...
_AGAR_AGAIN_MM = 1.5  # ... this much of the agar's colour is a line across the agar
_INWARD = 0.08  # the agar's edge is searched from this share of the strongest edge inside it
_OUTWARD = 0.06  # ... to this share outside it
_AGAR_BAND = 0.045  # the agar's colour: the median over this share of the radius inside that
_STRONGEST_SPAN = (0.8, 1.25)  # the strongest edge is searched over these shares of the guess
_STEP_MM = 0.5  # ... as the largest change between the mean colours over this either side


@dataclass(frozen=True)
class Dish:
    """The dish found (or configured): ``center`` (x, y) and ``radius`` in pixels."""

    center: tuple[float, float]
    radius: float

    def to_dict(self) -> dict[str, Any]:
        """Return ``{"center": [x, y], "radius": r}``."""
        return {
            "center": [float(self.center[0]), float(self.center[1])],
            "radius": float(self.radius),
        }


def find_dish(image: np.ndarray, radius_range: tuple[float, float] = (0.30, 0.50)) -> Dish:
    """Find the petri dish: the agar disc inside the wall.

    Three steps, each on rays from the centre at full resolution:

    1. **First guess.** A Hough circle on a grey image subsampled to ~128 px
       (:func:`hough_dish`). Its centre is good to a millimetre or two, its radius is not: a
       dish shows several concentric circles (the lid's rim, the wall's two sides, the
       meniscus, ring lines of the lid seen through it) with nearly the same votes, and which
       one wins depends on where the subsampling's pixels fall. On the real photographs of
       ``benchmarks/bench_real_plates.py``, moving the image's origin by 5-23 px moved the
       radius found by this guess alone between 39 and 50 mm.
    2. **The dish's strongest edge** (:func:`_strongest_edge`): on every ray from 0.8 to 1.25
       times the radius, the place where the mean colour over the next 0.5 mm differs most
       from the mean over the last 0.5 mm; a robust circle fit to these places, taken twice
       (the second time round the first fit). It is the dish's wall against the background
       or the agar against the wall: one circle, whichever guess it starts from.
    3. **The agar's edge** (:func:`_refine_dish`), searched from 8 % of the strongest edge's
       radius inside it (~3.6 mm) to 6 % outside: the first place, going outward, where the
       colour departs from the agar's by more than 18 grey levels and stays so for about a
       millimetre (r / 45: the meniscus or the wall, not a thin line of the lid), and where
       the agar's colour does not come back: a departure followed, within ``_LINE_MM`` (4 mm),
       by ``_AGAR_AGAIN_MM`` (1.5 mm) of the agar's colour is a line across the agar (the
       lid's rim seen from above, a double line of the wall), and the agar goes on beyond it.
       The edge is located at half the height of that departure's first peak, with sub-pixel
       interpolation. A least-squares circle is fitted to the edge points of all rays,
       dropping outliers (labels, pen marks, colonies near the wall) in three rounds.

    The search of step 3 used to start from the Hough radius itself (40 px or 6 % inside it):
    the dish found then moved with the guess. Measured on the 68 real photographs of both sets,
    with the Hough guess taken on the image moved by 0 and 7 px and with its radius scaled by
    0.9 and 1.1: the radius found spread over a median of 6.9 mm per photo before (over more
    than 0.5 mm on all of them), 0.06 mm now (over more than 0.5 mm on 9 of them). Photos
    resampled to 7 and 4.5 px/mm now find the dish of the full-resolution photo, and the
    benchmark no longer depends on where the subsampling's pixels fall (figures in the
    README's Measured table). The agar's colour is the median over ``_AGAR_BAND`` (4.5 % of
    the radius, ~2 mm) inside the search's start, so that a line of the lid where the search
    starts is not taken for the agar. Limit: the agar disc and the wall's top are not
    concentric when the camera is not above the dish's centre (parallax), and where the
    strongest edge is the wall's outer side, 4-6 mm beyond the agar, the edge found lies on
    the wall on that side: against the dish the old search found from each full-resolution
    photo's own Hough guess, 34 of the 68 dishes are within 1 mm, 21 lie over 2 mm beyond it,
    none over 2 mm short of it.

    Limit: the edge points are hard decisions per ray (a departure of 18 levels that lasts), so a
    start moved by a tenth of a pixel can make some rays take another line of the rim (AGAR
    12028: 112 rays, 15 of them on a line ~3 mm inside the rest, kept or dropped by the
    outlier rounds). Over six one-pixel moves of each of the 68 real photos the centre found
    spreads by a median of 0.14 mm (over 0.25 mm on 22 photos), the radius by 0.06 mm (over 0.25
    mm on 11). Tried and not kept: starting the outlier rounds from the radii's densest 1-2.5 mm
    window (15-21 photos over 0.25 mm, the worst 3.5 -> 5-8 mm: two lines of nearly equal
    support then trade places); the circle of least median residual over triplets of rays a
    third of a turn apart (19-20); the median of 9 refinements started 0.5 px apart (13, at 9
    times the cost, but the counts moved as much: over 4 shifts AGAR 91 -> 93 colonies summed,
    median count error 7.3 -> 9.0 %). A steadier dish alone would not steady the counts: a
    fraction of a pixel in the centre moves them, through where the working copy's pixel grid
    and the usable area fall (phone and AGAR photos over 3 shifts: 170 colonies summed with the
    dish found, 155 with its radius held and only the centre found, none with the whole dish
    moved with the photo).

    Parameters
    ----------
    image : ndarray
        HxWx3 BGR uint8 image (HxW grey is accepted).
    radius_range : tuple of float
        Radius searched by the first guess, as fractions of ``min(height, width)``.

    Returns
    -------
    Dish

    Raises
    ------
    ValueError
        If the image is not valid or no dish is found.
    """
    img = as_image(image, color=True, min_side=64)
    guess = hough_dish(img, radius_range)
    if guess is None:
        raise ValueError("no petri dish found in the image; set PlateParams.region to the dish")
    cx, cy, r = guess
    for _ in range(2):
        cx, cy, r = _strongest_edge(img, cx, cy, r)
    reach = (_INWARD * r, _OUTWARD * r)
    step = max(1.0, r / 900)
    cx, cy, r = _refine_dish(img, cx, cy, r, 180, reach, step, agar_band=_AGAR_BAND * r)
    return Dish((cx, cy), r)


def hough_dish(
    image: np.ndarray, radius_range: tuple[float, float] = (0.30, 0.50)
) -> tuple[float, float, float] | None:
    """First guess of the dish: the strongest Hough circle on a grey image subsampled to ~128 px.

    Parameters
    ----------
    image : ndarray
        HxWx3 BGR uint8 image.
    radius_range : tuple of float
        Radius searched, as fractions of ``min(height, width)``.

    Returns
    -------
    tuple of float or None
        ``(cx, cy, r)`` in full-resolution pixels, or None when no circle is found.
    """
    h, w = image.shape[:2]
    step = max(1, min(h, w) // 128)
    small = cv2.resize(image, (w // step, h // step), interpolation=cv2.INTER_NEAREST)
    small = cv2.GaussianBlur(cv2.cvtColor(small, cv2.COLOR_BGR2GRAY), (5, 5), 1.0)
    circles = cv2.HoughCircles(
        small,
        cv2.HOUGH_GRADIENT,
        dp=1,
        minDist=max(small.shape),
        param1=60,
        param2=15,
        minRadius=int(radius_range[0] * min(h, w) / step),
        maxRadius=math.ceil(radius_range[1] * min(h, w) / step),
    )
    if circles is None:
        return None
    cx, cy, r = (float(v) * step for v in circles[0, 0])
    return cx, cy, r


def _refine_dish(
    img: np.ndarray,
    cx: float,
    cy: float,
    r: float,
    n_rays: int,
    reach: tuple[float, float],
    step: float,
    agar_band: float = 0.0,
) -> tuple[float, float, float]:
    """Refine a dish circle on the agar's edge along rays (see :func:`find_dish`).

    ``reach`` is how far inside and outside the circle the edge is searched (px). The agar's
    colour on every ray is the mean of its first 4 px, or, when ``agar_band`` (px) is given,
    the median over that much of the ray further in (a line of the lid where the search
    starts is then not taken for the agar).
    """
    theta = np.linspace(0.0, 2 * np.pi, n_rays, endpoint=False, dtype=np.float32)
    radii = np.arange(r - reach[0] - agar_band, r + reach[1] + step / 2, step, dtype=np.float32)
    map_x = (cx + np.cos(theta)[:, None] * radii[None, :]).astype(np.float32)
    map_y = (cy + np.sin(theta)[:, None] * radii[None, :]).astype(np.float32)
    prof = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    prof = prof.astype(np.float32)
    start = round(agar_band / step)
    if start > 0:  # the agar's colour from the band inside, the search beyond it
        ref = np.median(prof[:, :start], axis=1)
        prof, radii = prof[:, start:], radii[start:]
    else:
        ref = prof[:, : max(round(4.0 / step), 2)].mean(axis=1)  # at the rays' inner end
    diff = prof - ref[:, None, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    rows = np.arange(n_rays)
    # the edge is where the colour leaves the agar's for good: a departure that lasts at least
    # ~1 mm (r / 45) going outward, and after which the agar's colour does not come back for
    # _AGAR_AGAIN_MM within _LINE_MM; thin lines of the lid or the meniscus are passed
    px_per_mm = r / 45.0
    departed = dist >= _DISH_EDGE_CONTRAST
    run = max(round(px_per_mm / step), 1)
    lasting = _count_ahead(departed, run) == run
    again = max(round(_AGAR_AGAIN_MM * px_per_mm / step), 1)
    agar_again = _count_ahead(~departed, again) == again
    comes_back = _count_ahead(agar_again, max(round(_LINE_MM * px_per_mm / step), 1)) > 0
    edge = lasting & ~comes_back
    first = np.argmax(edge, axis=1)
    ok = edge[rows, first] & (first > 0)
    # height of the first peak: the largest distance within 3 px after the first crossing
    win = first[:, None] + np.arange(round(3.0 / step) + 1)[None, :]
    peak = dist[rows[:, None], np.minimum(win, dist.shape[1] - 1)].max(axis=1)
    half = np.maximum(peak / 2.0, _DISH_EDGE_CONTRAST / 2.0)
    # walk back from the first crossing to the half-height crossing
    idx = first.copy()
    for _ in range(round(3.0 / step)):
        back = ok & (idx > 1) & (dist[rows, idx - 1] >= half)
        idx = np.where(back, idx - 1, idx)
    d0, d1 = dist[rows, np.maximum(idx - 1, 0)], dist[rows, idx]
    frac = np.clip((half - d0) / np.maximum(d1 - d0, 1e-6), 0.0, 1.0)
    rr = radii[np.maximum(idx - 1, 0)] + frac * step
    px = (cx + np.cos(theta) * rr)[ok]
    py = (cy + np.sin(theta) * rr)[ok]
    return _robust_circle(px, py, (cx, cy, r))


def _strongest_edge(
    img: np.ndarray, cx: float, cy: float, r: float, n_rays: int = 180
) -> tuple[float, float, float]:
    """The dish's strongest circular edge near the circle ``(cx, cy, r)`` (see :func:`find_dish`).

    On every ray, over ``_STRONGEST_SPAN`` of ``r``, the place where the mean colour over the
    next ``_STEP_MM`` differs most (Euclidean, B, G, R) from the mean over the last
    ``_STEP_MM``; samples outside the image take no part. A robust circle through these places.
    """
    h, w = img.shape[:2]
    step = max(1.0, r / 900)
    theta = np.linspace(0.0, 2 * np.pi, n_rays, endpoint=False, dtype=np.float32)
    radii = np.arange(_STRONGEST_SPAN[0] * r, _STRONGEST_SPAN[1] * r, step, dtype=np.float32)
    map_x = (cx + np.cos(theta)[:, None] * radii[None, :]).astype(np.float32)
    map_y = (cy + np.sin(theta)[:, None] * radii[None, :]).astype(np.float32)
    prof = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    half = max(round(_STEP_MM * r / 45.0 / step), 1)  # r / 45: px per mm of a 90 mm dish
    n = radii.size
    # at the samples half .. n - half - 1: the sum of the next `half` samples minus the sum of
    # the last `half` (exact: integers in float32), over `half`
    step_kernel = np.repeat(np.array([[-1.0, 1.0]], np.float32), half, axis=1)
    sums = cv2.filter2D(prof.astype(np.float32), -1, step_kernel, anchor=(half, 0))
    change = sums[:, half : n - half] / half
    strength = np.sqrt(np.einsum("ijk,ijk->ij", change, change))
    seen = (map_x >= 0) & (map_x <= w - 1) & (map_y >= 0) & (map_y <= h - 1)
    strength[~seen[:, half : n - half]] = 0.0
    rr = radii[half + np.argmax(strength, axis=1)]
    return _robust_circle(cx + np.cos(theta) * rr, cy + np.sin(theta) * rr, (cx, cy, r))


def _robust_circle(
    px: np.ndarray, py: np.ndarray, fallback: tuple[float, float, float]
) -> tuple[float, float, float]:
    """A circle through the points, outliers (beyond 3 robust sigmas, at least 1 px) dropped in
    three rounds; ``fallback`` when there are fewer than 12 points."""
    if px.size < 12:
        return fallback
    keep = np.ones(px.size, bool)
    fit = fallback
    for _ in range(3):
        fit = _fit_circle(px[keep], py[keep])
        res = np.abs(np.hypot(px - fit[0], py - fit[1]) - fit[2])
        mad = median(res[keep])
        new_keep = res <= max(3.0 * 1.4826 * mad, 1.0)
        if new_keep.sum() < 12:
            break
        keep = new_keep
    return fit


def _count_ahead(flags: np.ndarray, length: int) -> np.ndarray:
    """How many of the next ``length`` samples (that one included, cut at the ray's end) hold
    ``flags`` (rays x samples, bool), at every sample."""
    n = flags.shape[1]
    window = np.cumsum(np.pad(flags.astype(np.int32), ((0, 0), (1, 0))), axis=1)
    start = np.arange(n)
    return window[:, np.minimum(start + length, n)] - window[:, start]


def _fit_circle(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Algebraic (Kasa) least-squares circle through points.

    Minimises the sum of ``(u^2 + v^2 - p u - q v - s)^2`` over the points' offsets ``(u, v)``
    from their mean (centred, so the normal equations are well conditioned): with the mean
    removed, ``s`` separates from ``(p, q)``, a 2x2 system solved in closed form.
    """
    mx, my = float(x.mean()), float(y.mean())
    u, v = x - mx, y - my
    rho = u * u + v * v
    suu, svv, suv = float(u @ u), float(v @ v), float(u @ v)
    sur, svr = float(u @ rho), float(v @ rho)
    det = suu * svv - suv * suv
    if not det > 0:  # all points on a line: no circle, keep their centre
        return mx, my, float(math.sqrt(rho.mean()))
    p = (sur * svv - svr * suv) / det
    q = (svr * suu - sur * suv) / det
    s = float(rho.mean())  # the mean of u and v is 0
    cx, cy = p / 2, q / 2
    return mx + cx, my + cy, float(math.sqrt(max(s + cx * cx + cy * cy, 0.0)))
