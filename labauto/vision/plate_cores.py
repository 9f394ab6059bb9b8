"""Colonies in a clump, counted by their cores over several levels (plate analysis, step 5).

The distance transform of step 5 (:func:`labauto.vision.plate_counts.merged_counts`) counts
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
  statistics, all bodies at once on the bodies' shared canvas (:class:`Bodies`): only the
  bodies with a dome (below), on the canvas cut to them, one pass per level and band of like
  widths (:mod:`labauto.vision.plate_canvas`); each body's levels come from a partial sort of
  its own values. On the 15-Mpixel AGAR plate 525 (25 clumps of large colonies) this took the
  cores from 36 to 24 ms (median of 15, taking turns; ninth session), with the same counts on
  every plate; on the crowded phone photos (104-163 clumps) they stay at 11-17 ms.
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
from labauto.vision.plate_canvas import bands_of

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
    # each body's departure, smoothed over its crop's neighbourhood (so as over the whole ROI),
    # and its levels; only the bodies with a dome to cut go on to be labelled
    sigma = max(_SIGMA_RATIO * single_r, 0.5)
    reach = math.ceil(4 * sigma) + 1  # beyond OpenCV's kernel: the same as over the whole ROI
    height, width_roi = departure.shape
    at_quantile = np.linspace(0.05, 0.95, _LEVELS)
    levels = np.full((_LEVELS, len(which)), np.inf, np.float32)
    smoothed: dict[int, np.ndarray] = {}
    for b in np.flatnonzero(which).tolist():
        t, lft, h, w = bodies.top[b], bodies.left[b], bodies.height[b], bodies.width[b]
        y0, x0 = max(t - reach, 0), max(lft - reach, 0)
        y1, x1 = min(t + h + reach, height), min(lft + w + reach, width_roi)
        distance = cv2.GaussianBlur(cv2.sqrt(departure[y0:y1, x0:x1]), (0, 0), sigma)
        distance = distance[t - y0 : t - y0 + h, lft - x0 : lft - x0 + w]
        values = distance[bodies.mask[bodies.row[b] : bodies.row[b] + h, :w] > 0]
        if values.size == 0:
            continue
        at = np.floor(at_quantile * (values.size - 1)).astype(np.intp)
        level = np.partition(values, at)[at]
        if level[-1] - level[0] >= least_range:  # else no dome to cut: noise and texture
            levels[:, b] = level
            smoothed[b] = distance
    dome = np.zeros(len(which), bool)
    dome[list(smoothed)] = True
    if not dome.any():
        return counts
    # a smaller canvas of only these bodies' slots, in bands (:mod:`plate_canvas`)
    rows, first_row, width = bodies.slots_of(dome)
    row_body = bodies.row_body[rows]
    inside = (bodies.mask[rows, :width] > 0) & (row_body[:, None] >= 0)
    canvas = np.zeros(inside.shape, np.float32)
    for b, distance in smoothed.items():
        r = first_row[b]
        canvas[r : r + distance.shape[0], : distance.shape[1]] = distance
    bands = bands_of(first_row[dome], bodies.slot[dome], bodies.width[dome], len(row_body))
    for level in levels:
        above = (inside & (canvas > level[np.maximum(row_body, 0)][:, None])).view(np.uint8)
        for r0, r1, band_width in bands:
            part = above[r0:r1, :band_width]
            n, _, stats, _ = cv2.connectedComponentsWithStats(part, connectivity=8)
            if n <= 1:
                continue
            top, w, h, area = (stats[1:, k] for k in (1, 2, 3, 4))
            core = area >= least_area
            core &= area >= _CORE_FILL * math.pi / 4 * w * h
            core &= np.minimum(w, h) >= _CORE_ASPECT * np.maximum(w, h)
            found = np.bincount(row_body[top[core] + r0], minlength=len(which))
            counts = np.maximum(counts, found)
    return counts
