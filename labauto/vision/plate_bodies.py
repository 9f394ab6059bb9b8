"""The bodies of a plate: artefact tests, masks, holes, inscribed radii and waists.

Steps 3-4 of :mod:`labauto.vision.plate` (its docstring gives the rules): every object that
passes the contour's moment tests becomes a body whose mask lies on one shared canvas
(:class:`Bodies`), so each measure is one OpenCV or numpy call over all bodies. What is read
from the bodies afterwards lives beside: their mixed-colony scores
(:mod:`labauto.vision.plate_mixed`), their colony counts (:mod:`labauto.vision.plate_counts`)
and the cores of clumps (:mod:`labauto.vision.plate_cores`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.vision.plate_canvas import Band, bands_of, components, nonzero, on_bands, per_row
from labauto.vision.plate_params import PlateParams

PAD = 3  # margin (px) around a body's mask; bodies this close to the usable border are dropped
HOLE_SHARE = 0.1  # a hole under this share of its body's filled contour is part of the body
MIN_SINGLES = 3  # single colonies a plate needs before their median area is a yardstick
_DISC5 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
_GAP = 2  # empty canvas rows between two bodies' crops (the 5x5 filters reach 2 px)


@dataclass
class Bodies:
    """The objects that passed the moment tests, with their masks on one shared canvas.

    Every body's crop (its bounding box grown by ``PAD`` on every side) is copied to the
    canvas at column 0 and an even row, below the previous one with ``_GAP`` empty rows
    between them. No canvas row holds two bodies, so one OpenCV call (closing, distance
    transform, dilation, connected components) treats all bodies at once and gives, inside
    every crop, exactly what it gives on the crop alone (the crop's rim of ``PAD`` px and the
    gap rows are background), and a per-body reduction is a reduction over a range of rows.
    The canvas is as wide as the widest crop, so one long stroke among many small bodies
    makes it mostly empty: the steps over all bodies (closing, holes, distance transform)
    run band by band (:mod:`labauto.vision.plate_canvas`), and those over some of them
    (concavities, merged counts, mixed scores, cores) on the canvas cut to the widest of
    those.

    Attributes
    ----------
    index : ndarray of int
        Contour index of each body.
    top, left : ndarray of int
        The crop's origin (ROI pixels).
    height, width : ndarray of int
        The crop's size.
    row : ndarray of int
        The canvas row of the crop's first row (even).
    row_body : ndarray of int
        The body of every canvas row, -1 in the gaps.
    mask : ndarray of uint8
        Canvas of the bodies' masks (0 or 1).
    dt : ndarray of float32
        Their distance transform (3x3 L2 chamfer).
    area : ndarray of float
        Pixels in each body's mask.
    r_in : ndarray of float
        Largest inscribed radius (``dt``'s maximum in each crop).
    stroke : ndarray of bool
        Area above ``max_fill_ratio`` inscribed discs: a pen stroke (artefact).
    concavity : ndarray of float
        Depth of the deepest concavity over ``r_in`` (``inf`` where not measured).
    elongation : ndarray of float
        Axis ratio ``sqrt(l1 / l2)`` of the contour's second moments.
    """

    index: np.ndarray
    top: np.ndarray
    left: np.ndarray
    height: np.ndarray
    width: np.ndarray
    row: np.ndarray
    row_body: np.ndarray
    mask: np.ndarray
    dt: np.ndarray
    area: np.ndarray
    r_in: np.ndarray
    stroke: np.ndarray
    concavity: np.ndarray
    elongation: np.ndarray

    @property
    def slot(self) -> np.ndarray:
        """Canvas rows each body takes: its crop and the gap rows after it."""
        return np.diff(np.append(self.row, len(self.row_body)))

    def slots_of(self, which: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """A smaller canvas of only the bodies where ``which`` is true (the layout's rules
        still hold): which canvas rows it keeps, each body's first row on it (0 for the
        others), and its width, the widest of those bodies' crops (a stroke left out no
        longer widens it)."""
        slot = self.slot
        rows = which[np.repeat(np.arange(len(slot)), slot)]
        first_row = np.zeros(len(slot), np.intp)
        first_row[which] = np.cumsum(slot[which]) - slot[which]
        return rows, first_row, int(self.width[which].max(initial=1))


def moment_test(contour: np.ndarray, params: PlateParams) -> tuple[str | None, float]:
    """Artefact tests of step 3 that need only the contour: the reject reason (or None) and
    the elongation ``sqrt(l1 / l2)`` of the second moments."""
    m = cv2.moments(contour)
    mu20, mu02, mu11 = m["mu20"], m["mu02"], m["mu11"]
    half_trace = (mu20 + mu02) / 2.0
    spread = math.sqrt(((mu20 - mu02) / 2.0) ** 2 + mu11 * mu11)
    elongation = math.sqrt((half_trace + spread) / max(half_trace - spread, 1e-9))
    area = m["m00"] + len(contour) / 2.0 + 1.0  # polygon through pixel centres + half-pixel rim
    if area < params.min_colony_area_px:
        return "dust", elongation
    if area > params.max_colony_area_px:
        return "large", elongation
    if 2.0 * area / max(cv2.arcLength(contour, True), 1.0) < params.min_width_px:
        return "thin", elongation
    if elongation > params.max_elongation:
        return "elongated", elongation
    return None, elongation


def measure_bodies(
    contours: list[np.ndarray],
    fg: np.ndarray | None,
    need_concavity: np.ndarray,
    params: PlateParams,
    rejected: dict[str, int],
) -> Bodies:
    """Artefact tests (module docstring, step 3) and waists of all contours.

    Contours failing a moment test are counted in ``rejected``; the others become bodies.
    A body's mask is its filled contour, restricted to the foreground ``fg`` (so a closed loop
    of pen ink is not taken for a solid body) and closed with a 5x5 disc (so a crack of a pixel
    or two where two species' colours meet at the edge does not read as a waist); a hole under
    ``HOLE_SHARE`` (a tenth) of the filled contour is filled again. Colonies with a translucent
    centre of the agar's colour have such holes, and the distance transform round a hole has a
    ring of peaks that step 5 counted as several colonies (AGAR plate 14380: 44 -> 30 found, 34
    boxed); the hole of a pen loop is most of it. Measured on the AGAR photographs: F1 0.845 ->
    0.849, median count error 14.0 -> 12.5 %; a share of 0.05 gives the same, 0.25 F1 0.843.
    Strokes are flagged in ``stroke`` (and counted). The concavity (the waist test of step 4) is
    measured only for the contours where ``need_concavity`` is true (``inf`` elsewhere): the
    caller leaves out those that cannot be a DES anyway (centroid outside or D_alpha too large).
    """
    survivors, elongations = [], []
    for k, contour in enumerate(contours):
        reason, elongation = moment_test(contour, params)
        if reason is None:
            survivors.append(k)
            elongations.append(elongation)
        else:
            rejected[reason] = rejected.get(reason, 0) + 1
    index = np.array(survivors, dtype=np.intp)
    kept = [contours[k] for k in survivors]
    if not kept:
        none, empty = np.zeros(0, np.intp), np.zeros(0)
        canvas_none = np.zeros((0, 1), np.uint8)
        return Bodies(
            none, none, none, none, none, none, none, canvas_none,
            canvas_none.astype(np.float32), empty, empty, empty.astype(bool), empty, empty,
        )  # fmt: skip
    boxes = np.array([cv2.boundingRect(c) for c in kept], np.intp).reshape(-1, 4)
    left, top = boxes[:, 0] - PAD, boxes[:, 1] - PAD
    width, height = boxes[:, 2] + 2 * PAD, boxes[:, 3] + 2 * PAD
    slot = (height + _GAP + 1) // 2 * 2  # rows taken on the canvas (even)
    row = np.cumsum(slot) - slot
    n_rows = int(slot.sum())
    row_body = np.repeat(np.arange(len(kept)), slot)
    row_body[np.arange(n_rows) - row[row_body] >= height[row_body]] = -1
    canvas = (n_rows, int(width.max(initial=1)))
    bands = bands_of(row, slot, width, n_rows)  # the steps over all bodies run band by band

    # the contours moved to the canvas, all drawn (filled) at once: one body per canvas row
    lengths = [len(c) for c in kept]
    shift = np.stack((-left, row - top), axis=1).astype(np.int32)
    moved = np.split(
        np.concatenate(kept).reshape(-1, 2) + np.repeat(shift, lengths, axis=0),
        np.cumsum(lengths)[:-1],
    )
    mask = np.zeros(canvas, np.uint8)
    cv2.drawContours(mask, [c.reshape(-1, 1, 2) for c in moved], -1, 1, -1)
    if fg is not None:
        fg_canvas = np.zeros(canvas, np.uint8)
        for r, t, lft, h, w in zip(row, top, left, height, width, strict=True):
            fg_canvas[r : r + h, :w] = fg[t : t + h, lft : lft + w]
        solid = on_bands(_closed, bands, mask, fg_canvas)
        mask = _small_holes_filled(mask, solid, row, row_body, bands)
    dt = on_bands(_distances, bands, mask)
    r_in = np.maximum.reduceat(per_row(_row_max, dt, bands), row).astype(np.float64)
    area = np.add.reduceat(per_row(_row_count, mask, bands), row).astype(np.float64)
    stroke = area > params.max_fill_ratio * math.pi * r_in * r_in
    if stroke.any():
        rejected["stroke"] = rejected.get("stroke", 0) + int(stroke.sum())

    # deepest concavity: largest distance from the hull's outline of a hull pixel not in the
    # body (0 when there is no such pixel)
    concavity = np.full(len(kept), math.inf)
    wanted = need_concavity[index] & ~stroke
    if wanted.any():
        hulls = np.zeros((n_rows, int(width[wanted].max())), np.uint8)  # as wide as these
        for i in np.flatnonzero(wanted):
            cv2.fillConvexPoly(hulls, cv2.convexHull(moved[i]), 1)
        pocket = cv2.compare(hulls, mask[:, : hulls.shape[1]], cv2.CMP_GT)
        hull_dt = cv2.distanceTransform(hulls, cv2.DIST_L2, 3)
        hull_dt[pocket == 0] = 0.0
        depth = np.maximum.reduceat(hull_dt.max(axis=1), row).astype(np.float64)
        concavity[wanted] = depth[wanted] / np.maximum(r_in[wanted], 1.0)
    return Bodies(
        index, top, left, height, width, row, row_body, mask, dt, area, r_in, stroke, concavity,
        np.asarray(elongations, float),
    )  # fmt: skip


def _closed(mask: np.ndarray, fg: np.ndarray) -> np.ndarray:
    """The filled contours restricted to the foreground, closed with a 5x5 disc."""
    return cv2.morphologyEx(cv2.min(mask, fg), cv2.MORPH_CLOSE, _DISC5)


def _distances(mask: np.ndarray) -> np.ndarray:
    """The 3x3 L2 chamfer distance transform."""
    return cv2.distanceTransform(mask, cv2.DIST_L2, 3)


def _row_max(canvas: np.ndarray) -> np.ndarray:
    return canvas.max(axis=1)


def _row_count(canvas: np.ndarray) -> np.ndarray:
    return np.count_nonzero(canvas, axis=1)


def _small_holes_filled(
    filled: np.ndarray, solid: np.ndarray, row: np.ndarray, row_body: np.ndarray, bands: list[Band]
) -> np.ndarray:
    """``solid`` with every hole of a body under ``HOLE_SHARE`` of its filled contour filled."""
    holes = on_bands(lambda f, s: cv2.compare(f, s, cv2.CMP_GT), bands, filled, solid)
    # labels without statistics, each hole's area and body read at its own pixels (quicker
    # than connectedComponentsWithStats over the canvas)
    n, labels = components(holes, bands, connectivity=4)
    if n <= 1:
        return solid
    xs, ys = nonzero(holes, bands)
    hole = labels[ys, xs]
    owner = np.zeros(n, np.intp)
    owner[hole] = row_body[ys]  # any row of a hole: no canvas row holds two bodies
    body_area = np.add.reduceat(per_row(_row_count, filled, bands), row)
    small = np.bincount(hole, minlength=n) < HOLE_SHARE * body_area[owner]
    small[0] = False
    filled_in = small[hole]
    out = solid.copy()
    out[ys[filled_in], xs[filled_in]] = 1
    return out


def holes_filled(mask: np.ndarray, row_body: np.ndarray, bodies: np.ndarray) -> np.ndarray:
    """Canvas ``mask`` (0 / 1; ``row_body``: the body of every row) with every hole of the
    bodies where ``bodies`` is true filled. A hole is background that the background round the
    crops (4-connected) does not reach; it lies in the rows of the body round it."""
    outside = np.zeros((mask.shape[0] + 2, mask.shape[1] + 2), np.uint8)
    cv2.floodFill(mask.copy(), outside, (0, 0), 1, 0, 0, 4 | (1 << 8) | cv2.FLOODFILL_MASK_ONLY)
    holes = cv2.compare(outside[1:-1, 1:-1], 0, cv2.CMP_EQ) & cv2.compare(mask, 0, cv2.CMP_EQ)
    holes[~((row_body >= 0) & bodies[np.maximum(row_body, 0)])] = 0
    return mask | (holes & 1)
