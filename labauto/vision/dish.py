"""The petri dish on a plate image: validating the image and finding the agar disc.

``find_dish`` takes a Hough circle on a subsampled grey image as a first guess and refines it on
the agar's edge along rays at full resolution (see its docstring); the plate analysis ignores
everything outside the dish shrunk by a rim margin (wall, labels, pen marks on the rim).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from labauto.vision.image import as_image

_DISH_EDGE_CONTRAST = 18.0  # colour distance (grey levels) from the agar that marks its edge
_LINE_MM = 4.0  # a departure followed within this by ...
_AGAR_AGAIN_MM = 1.5  # ... this much of the agar's colour is a line across the agar
_OUTWARD = 0.12  # the rays reach this share of the first guess's radius outside it


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

    A Hough circle on a grey image subsampled to ~128 px gives a first guess. Along rays at full
    resolution the agar's edge is the first place, going outward, where the colour departs from
    the agar's by more than 18 grey levels and stays so for about a millimetre (r / 45: the
    meniscus or the wall, not a thin line of the lid), and where the agar's colour does not come
    back: a departure followed, within ``_LINE_MM`` (4 mm), by ``_AGAR_AGAIN_MM`` (1.5 mm) of
    the agar's colour is a line across the agar (the lid's rim seen from above, a double line
    of the wall), and the agar goes on beyond it. The edge is located at half the height of
    that departure's first peak, with sub-pixel interpolation. A least-squares circle is fitted
    to the edge points of all rays (from 40 px, and at least 6 % of the radius, inside the
    first guess to 12 % of it outside), dropping outliers (labels, pen marks, colonies near the
    wall) in three rounds.

    The AGAR photographs are why: on several, the Hough circle and the first lasting departure
    sit on dark lines 5-10 % inside the agar's edge, with boxed colonies in the agar beyond
    (42 of 1886 outside the dish found). With the rule, 22 lie outside; AGAR F1 0.883 ->
    0.886, median count error 11.4 -> 10.5 %, phone-counts 3.4 % either way. On the same
    photos resampled to 4.5 px/mm, F1 0.829 -> 0.847 and count error 12.5 -> 11.4 %; at
    7 px/mm, F1 0.859 -> 0.857 and count error 13.0 -> 15.0 % (16 -> 19 plates over 15 %:
    the scale read from a larger dish moves plates of large faint colonies, 8386 and 5212,
    either way). Fitting a second time round the first fit made it worse (phone-counts
    3.4 -> 4.3 %).

    Parameters
    ----------
    image : ndarray
        HxWx3 BGR uint8 image (HxW grey is accepted).
    radius_range : tuple of float
        Radius searched, as fractions of ``min(height, width)``.

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
    # 40 px, and at least 6 % of the radius (~2.7 mm on any image), inside; 12 % outside: the
    # Hough circle of a high-resolution photo may sit on a line of the lid a few millimetres
    # inside the agar's edge
    reach = (max(40.0, 0.06 * r), max(40.0, _OUTWARD * r))
    cx, cy, r = _refine_dish(img, cx, cy, r, n_rays=180, reach=reach, step=max(1.0, r / 900))
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
) -> tuple[float, float, float]:
    """Refine a dish circle on the agar's edge along rays (see :func:`find_dish`).

    ``reach`` is how far inside and outside the circle the rays go (px).
    """
    theta = np.linspace(0.0, 2 * np.pi, n_rays, endpoint=False, dtype=np.float32)
    radii = np.arange(r - reach[0], r + reach[1] + step / 2, step, dtype=np.float32)
    map_x = (cx + np.cos(theta)[:, None] * radii[None, :]).astype(np.float32)
    map_y = (cy + np.sin(theta)[:, None] * radii[None, :]).astype(np.float32)
    prof = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    prof = prof.astype(np.float32)
    n_ref = max(round(4.0 / step), 2)
    ref = prof[:, :n_ref].mean(axis=1)  # agar colour at the inner end of every ray
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
    if px.size < 12:
        return cx, cy, r
    keep = np.ones(px.size, bool)
    fit = (cx, cy, r)
    for _ in range(3):
        fit = _fit_circle(px[keep], py[keep])
        res = np.abs(np.hypot(px - fit[0], py - fit[1]) - fit[2])
        mad = np.median(res[keep])
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
