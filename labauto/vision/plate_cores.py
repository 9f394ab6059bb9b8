"""Colonies in a clump, counted by their cores over several levels (plate analysis, step 5).

The distance transform of step 5 (:func:`labauto.vision.plate_bodies.merged_counts`) counts
the colonies of a merged body by the waists of its outline. Colonies that overlap by more than
about half their width leave no waist: a compact clump of three or four reads as one or two
(AGAR plate 518 is full of them). Each colony, though, is a dome: its departure from the agar
is largest at its centre and falls towards its edge, so above some level of the departure the
clump falls apart into one round core per colony. This is the multi-threshold idea of OpenCFU
(Geissmann 2013), applied inside each merged body. Choices made here:

* **The departure.** The square root of eq. 1's deviation (the colour distance from the agar's
  local background), smoothed by a Gaussian of ``_SIGMA_RATIO`` (0.08) times the plate's
  single-colony radius (at least half a pixel), so that a colony's own grain gives no cores.
* **Levels.** ``_LEVELS`` (12) levels per body, at the 5th to the 95th percentile of its own
  departure: a faint clump and a dark one are cut alike.
* **A core** is a connected part of the body above a level that looks like a colony's centre:
  at least ``_CORE_RADIUS_RATIO`` (0.35) times the plate's single-colony radius as a disc,
  filling at least ``_CORE_FILL`` (0.85) of the ellipse inscribed in its bounding box, and no
  more than 1 / ``_CORE_ASPECT`` (0.6) times as long as wide. Read from the components'
  statistics, all bodies at once on the bodies' shared canvas (:class:`Bodies`), one pass per
  level.
* **A dome to cut.** A body whose smoothed departure rises by less than ``least_range``
  from its 5th to its 95th percentile has no dome, only noise or texture, and is not cut:
  :mod:`labauto.vision.plate` passes half of eq. 1's threshold as a colour distance
  (``sqrt(color_threshold) / 2``, 12 grey levels by default). Large faint colonies read as
  clumps of four otherwise (AGAR plate 11761 at 7 px/mm).
* **The count** of a body is the most cores found at any one level; a merged body counts the
  larger of that and its distance transform's count, so the cores never lower a count.
  Bodies with printed characters across them are left out: a dot of print is a round core.

Measured (``benchmarks/bench_real_plates.py``): see :mod:`labauto.vision.plate` step 5. Each
constant moved alone (``_CORE_FILL`` 0.8 or 0.9, ``_CORE_RADIUS_RATIO`` 0.3 or 0.45,
``_LEVELS`` 20, ``_SIGMA_RATIO`` 0.15) moves AGAR matched by -6 to +2 of 1626 (F1 0.908-0.911)
and phone-counts' median by -0.1 to +0.6 points: within a pixel's jitter. Also measured and not
kept (2026-12-07, seventh session): counting the most cores none of which holds another over
all levels (a part counts 1 when it is a core, or what the parts above it count, whichever is
more), so that colonies whose domes part at different levels all count. AGAR: the same count
on every plate (in a clump of 518 looked at, two colonies that overlap stay one long core,
0.57-0.8 of its ellipse, at every level); phone-counts: 10 plates up by 1-9 (IMG_2532
667 -> 676 for 680), their absolute errors summed 106 -> 99, the median 1.9 % either way but
over 4 one-pixel shifts 2.3 -> 2.5 %; at 7 px/mm AGAR +3 matched for +7 reported, median
count error 7.3 -> 9.2 %.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from labauto.vision.plate_bodies import Bodies

_SIGMA_RATIO = 0.08  # smoothing of the departure, times the single-colony radius
_LEVELS = 12  # levels per body, from its 5th to its 95th percentile
_CORE_RADIUS_RATIO = 0.35  # a core is at least this times the single-colony radius, as a disc
_CORE_FILL = 0.85  # ... fills this much of the ellipse inscribed in its bounding box ...
_CORE_ASPECT = 0.6  # ... and is at least this wide for its length


def core_counts(
    bodies: Bodies, departure: np.ndarray, which: np.ndarray, single_r: float, least_range: float
) -> np.ndarray:
    """The most colony-like cores of each body over its levels (0 where ``which`` is false).

    Parameters
    ----------
    bodies : Bodies
        The bodies and their masks on the shared canvas.
    departure : ndarray
        HxW float32 over the ROI: eq. 1's deviation (summed squared colour difference).
    which : ndarray of bool
        The bodies to count.
    single_r : float
        The plate's single-colony radius (px): the median inscribed radius of its DES bodies.
    least_range : float
        Least rise of a body's smoothed departure from its 5th to its 95th percentile (colour
        distance, grey levels) for it to be cut into cores at all.
    """
    counts = np.zeros(len(bodies.index), np.intp)
    if single_r <= 0:
        return counts
    least_area = math.pi * (_CORE_RADIUS_RATIO * single_r) ** 2
    which = which & (bodies.area >= 2 * least_area)  # room for two cores at least
    if not which.any():
        return counts
    # a smaller canvas of only these bodies' slots, as wide as the widest of them
    rows, first_row, width = bodies.slots_of(which)
    row_body = bodies.row_body[rows]
    inside = bodies.mask[rows, :width] > 0
    canvas = np.zeros(inside.shape, np.float32)
    sigma = max(_SIGMA_RATIO * single_r, 0.5)
    reach = math.ceil(4 * sigma) + 1  # beyond OpenCV's kernel: the same as over the whole ROI
    height, width_roi = departure.shape
    for b in np.flatnonzero(which).tolist():
        r = first_row[b]
        t, lft, h, w = bodies.top[b], bodies.left[b], bodies.height[b], bodies.width[b]
        y0, x0 = max(t - reach, 0), max(lft - reach, 0)
        y1, x1 = min(t + h + reach, height), min(lft + w + reach, width_roi)
        distance = cv2.GaussianBlur(cv2.sqrt(departure[y0:y1, x0:x1]), (0, 0), sigma)
        canvas[r : r + h, :w] = distance[t - y0 : t - y0 + h, lft - x0 : lft - x0 + w]
    inside &= row_body[:, None] >= 0
    ys, xs = np.nonzero(inside)
    body = row_body[ys]  # non-decreasing: the canvas holds the bodies row after row
    values = canvas[ys, xs]
    # each body's values in order: one sort of a key that puts the bodies apart
    order = np.argsort(body * (float(values.max(initial=0.0)) + 1.0) + values)
    body, values = body[order], values[order]
    first = np.searchsorted(body, np.arange(len(which)))
    size = np.bincount(body, minlength=len(which))
    quantiles = np.linspace(0.05, 0.95, _LEVELS)
    levels = np.full((_LEVELS, len(which)), np.inf, np.float32)
    has = size > 0
    at = first[has] + np.floor(quantiles[:, None] * (size[has] - 1)).astype(np.intp)
    levels[:, has] = values[at]
    rise = np.zeros(len(which), np.float32)
    rise[has] = levels[-1, has] - levels[0, has]
    levels[:, rise < least_range] = np.inf  # no dome to cut: noise and texture
    for level in levels:
        row_level = level[np.maximum(row_body, 0)]
        above = (inside & (canvas > row_level[:, None])).view(np.uint8)
        n, _, stats, _ = cv2.connectedComponentsWithStats(above, connectivity=8)
        if n <= 1:
            continue
        top, w, h, area = (stats[1:, k] for k in (1, 2, 3, 4))
        core = area >= least_area
        core &= area >= _CORE_FILL * math.pi / 4 * w * h
        core &= np.minimum(w, h) >= _CORE_ASPECT * np.maximum(w, h)
        found = np.bincount(row_body[top[core]], minlength=len(which))
        counts = np.maximum(counts, found)
    return counts
