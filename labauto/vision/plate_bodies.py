"""The bodies of a plate: artefact tests, waists, mixed-colony scores and merged counts.

Steps 3-5 of :mod:`labauto.vision.plate` (its docstring gives the rules): every object that
passes the contour's moment tests becomes a body whose mask lies on one shared canvas
(:class:`Bodies`), so each measure is one OpenCV or numpy call over all bodies.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.vision.plate_canvas import Band, bands_of, components, nonzero, on_bands, per_row
from labauto.vision.plate_params import PlateParams

MIN_MERGED_COUNT = 1  # a body that is not a DES but shows one peak: one colony, not pickable
PAD = 3  # margin (px) around a body's mask; bodies this close to the usable border are dropped
HOLE_SHARE = 0.1  # a hole under this share of its body's filled contour is part of the body
MIN_SINGLES = 3  # single colonies a plate needs before their median area is a yardstick
_DISC5 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
SPOT_MM = 0.4  # a second colony on a colony: a round spot of outliers at least this wide ...
SPOT_ROUNDNESS = 0.7  # ... both ways, filling this share of the ellipse in its bounding box
LARGE_BODY_RATIO = 1.5  # a body this many times as wide as the plate's single colonies is large
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

    def slots_of(self, which: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """A smaller canvas of only the bodies where ``which`` is true (the layout's rules
        still hold): which canvas rows it keeps, each body's first row on it (0 for the
        others), and its width, the widest of those bodies' crops (a stroke left out no
        longer widens it)."""
        slot = np.diff(np.append(self.row, len(self.row_body)))
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


def mix_scores(
    roi: np.ndarray, bodies: Bodies, which: np.ndarray, params: PlateParams
) -> tuple[np.ndarray, np.ndarray]:
    """Mixed-colony score of the bodies where ``which`` is true, all at once (step 4; 0 elsewhere).

    Per body, the inner pixels' B, G, R are fitted by ``c0 + c1 s + c2 s^2`` with ``s`` the
    distance to the boundary over its maximum (least squares, solved for all bodies together);
    the score is the fraction of inner pixels farther than ``mix_residual`` from the fit. Every
    second row and column of the body's crop is used (a speckle of 2 px radius still gives
    samples).

    Also returned: how many round spots a body's outliers hold (connected pieces at least
    ``SPOT_MM`` across both ways, filling ``SPOT_ROUNDNESS`` of the ellipse inscribed in their
    bounding box): small colonies sitting on a large one, too small a share of it for the
    score. Measured on the colonies offered for picking on the AGAR photographs (their
    outliers at the photo's own resolution): the three that held a small boxed colony on a
    large one had spots 0.61-0.84 mm across filling 0.92-0.96 of their enclosing circle; the
    single colonies' largest outlier pieces, a textured centre or the arcs of concentric
    rings, filled at most 0.69. In the analysis (every second pixel at 12 px/mm), the spot
    rule takes 3 of the 7 offered colonies holding two boxed ones out of the picking list,
    and 12 single colonies with them (1.4 % of 886); 0.5 mm takes the same, roundness 0.8
    only 2 and 7 singles.
    """
    k = len(bodies.index)
    score = np.zeros(k)
    if not which.any():
        return score, np.zeros(k, np.intp)
    # inner samples: every second row and column of the crops (crops start at even rows), on
    # the canvas as wide as these bodies
    dt = bodies.dt[::2, : int(bodies.width[which].max()) : 2]
    body_of_row = bodies.row_body[::2]
    row_wanted = (body_of_row >= 0) & which[np.maximum(body_of_row, 0)]
    inner = (dt >= params.edge_skip_px) & row_wanted[:, None]
    sub_y, sub_x = np.nonzero(inner)  # body after body, each in raster order
    label = body_of_row[sub_y]
    crop_y, crop_x = 2 * sub_y - bodies.row[label], 2 * sub_x
    in_crop = crop_x < bodies.width[label]
    if not in_crop.all():  # edge_skip_px <= 0 takes in the background beside the crop
        sub_y, sub_x, label = sub_y[in_crop], sub_x[in_crop], label[in_crop]
        crop_y, crop_x = crop_y[in_crop], crop_x[in_crop]
    sizes = np.bincount(label, minlength=k)
    if sizes.sum() == 0:
        return score, np.zeros(k, np.intp)
    starts = np.cumsum(sizes) - sizes
    c = roi[bodies.top[label] + crop_y, bodies.left[label] + crop_x].astype(np.float32)
    depth_scale = (1.0 / np.maximum(bodies.r_in, 1e-6)).astype(np.float32)
    s = dt[sub_y, sub_x] * depth_scale[label]  # normalised depth, 0 at the boundary
    s2 = s * s
    # per-body sums of every product the normal equations need, in one pass (one row per
    # pixel; summed row after row, i.e. in pixel order, per body)
    products = np.empty((len(s), 14))
    products[:, 0] = 1.0
    products[:, 1] = s
    products[:, 2] = s2
    products[:, 3] = s2 * s
    products[:, 4] = s2 * s2
    products[:, 5:8] = c  # times s ** 0
    products[:, 8:11] = s[:, None] * c
    products[:, 11:14] = s2[:, None] * c
    nonempty = sizes > 0
    sums = np.zeros((k, 14))
    sums[nonempty] = np.add.reduceat(products, starts[nonempty], axis=0)
    gram = np.stack([sums[:, i : i + 3] for i in range(3)], axis=1) + np.eye(3) * 1e-6
    rhs = sums[:, 5:14].reshape(k, 3, 3)  # [body, power of s, channel]
    coef = np.linalg.solve(gram, rhs).astype(np.float32)[label]
    resid = c - (coef[:, 0] + s[:, None] * coef[:, 1] + s2[:, None] * coef[:, 2])
    off = np.einsum("ij,ij->i", resid, resid) > params.mix_residual**2
    score = np.bincount(label, off, minlength=k) / np.maximum(sizes, 1)
    score[sizes < 8] = 0.0  # too few inner samples to judge
    spots = np.zeros(k, np.intp)
    spot_px = SPOT_MM * float(params.px_per_mm or 0.0) / 2  # on the grid of every second pixel
    if spot_px > 0 and off.any():
        spots = _round_spots(off, sub_y, sub_x, dt.shape, body_of_row, spot_px, k)
    return score, spots


def _round_spots(
    off: np.ndarray,
    sub_y: np.ndarray,
    sub_x: np.ndarray,
    shape: tuple[int, ...],
    body_of_row: np.ndarray,
    spot_px: float,
    k: int,
) -> np.ndarray:
    """How many round spots at least ``spot_px`` across each body's outlier samples (``off``
    at ``sub_y, sub_x`` on the half-resolution canvas of ``shape``) hold."""
    canvas = np.zeros(shape, np.uint8)
    canvas[sub_y[off], sub_x[off]] = 1
    _, _, stats, _ = cv2.connectedComponentsWithStats(canvas, connectivity=8)
    area = stats[1:, cv2.CC_STAT_AREA].astype(np.float64)
    width, height = stats[1:, cv2.CC_STAT_WIDTH], stats[1:, cv2.CC_STAT_HEIGHT]
    ellipse = math.pi / 4 * width * height  # the ellipse inscribed in the spot's box
    spot = (np.minimum(width, height) >= spot_px) & (area >= SPOT_ROUNDNESS * ellipse)
    # no canvas row holds two bodies: a spot's top row names its body
    return np.bincount(body_of_row[stats[1:, cv2.CC_STAT_TOP][spot]], minlength=k)


def merged_counts(
    bodies: Bodies,
    which: np.ndarray,
    valley_ratio: float,
    least_peak: float = 0.0,
    round_outline: np.ndarray | None = None,
    count_mask: np.ndarray | None = None,
) -> np.ndarray:
    """Colonies in each merged body (where ``which`` is true; 1 elsewhere), all at once.

    Step 5: one peak per plateau of the distance transform's local maxima (5x5), above
    ``max(2, least_peak, 0.3 r_in)``, at its highest pixel (the first in raster order on a
    tie); peaks are taken greedily from the highest (plateaus of equal height in the order
    OpenCV labels a crop: by their first 2x2 block in raster order), and a peak is kept when
    the straight segment to every peak kept before it dips below ``valley_ratio`` times the
    lower of the two. At least ``MIN_MERGED_COUNT`` (1). The segments between all pairs of
    peaks of a body are sampled at once. ``least_peak`` (px) is the plate's yardstick for a
    colony's centre (:attr:`PlateParams.peak_floor_ratio`); 0 leaves it out.

    The bodies where ``round_outline`` is true (their outline is a DES: centroid inside, small
    D_alpha) are counted with all their holes filled: round a hole the distance transform has
    a ring of peaks, and a round outline with a hole is one colony with a translucent part or a
    reflection across it (AGAR plates 14130 and 14627 had such colonies counted 4-6). A chain of
    colonies closed round a patch of agar has no round outline, and keeps its hole. Measured on
    the AGAR photographs: reported 1575 -> 1565, matched 1485 either way (F1 0.858 -> 0.861);
    filling the holes of every body also took 5 matched colonies of such chains. An open ring
    (a C: phone photo IMG_2525's ring about 1.7 mm across counted 3) is no DES either.
    Counting 1 every body of two or more that surrounds its centroid (the centroid outside
    it, its outline in 18 or 22 of 24 directions from it) cost 9 or 2 matched AGAR colonies
    (median count error 5.7 -> 7.3 %): such chains curl round agar as well. Not kept.

    ``count_mask`` (a canvas as ``bodies.mask``) replaces the bodies' masks for counting: the
    masks without the printed ink across them (:func:`labauto.vision.plate_ink.without_ink`).
    """
    counts = np.ones(len(bodies.index), np.intp)
    if not which.any():
        return counts
    counts[which] = MIN_MERGED_COUNT
    rows, first_row, width = bodies.slots_of(which)
    dt, row_body = bodies.dt[rows, :width], bodies.row_body[rows]
    r_in = bodies.r_in
    if count_mask is not None or (round_outline is not None and (round_outline & which).any()):
        solid = (bodies.mask if count_mask is None else count_mask)[rows, :width]
        if round_outline is not None:
            solid = holes_filled(solid, row_body, round_outline)
        dt = cv2.distanceTransform(solid, cv2.DIST_L2, 3)
        r_in = np.zeros(len(which))
        r_in[which] = np.maximum.reduceat(dt.max(axis=1), first_row[which])
    floor = np.maximum(max(2.0, least_peak), 0.3 * r_in)
    floor_of_row = np.where(row_body >= 0, floor[np.maximum(row_body, 0)], np.inf)
    cand = (dt >= cv2.dilate(dt, _DISC5)) & (dt >= floor_of_row[:, None])
    n, labels = cv2.connectedComponents(cand.view(np.uint8), connectivity=8)
    if n <= 1:
        return counts
    ys, xs = np.nonzero(cand)  # raster order
    plateau, value = labels[ys, xs], dt[ys, xs]
    order = np.lexsort((-value, plateau))  # by plateau, highest first, raster order on ties
    first = order[np.searchsorted(plateau[order], np.arange(1, n))]
    first_block = np.full(n, np.iinfo(np.intp).max)
    np.minimum.at(first_block, plateau, (ys // 2) * dt.shape[1] + xs // 2)
    peaks = first[np.argsort(first_block[1:], kind="stable")]  # body after body (rows)
    body = row_body[ys[peaks]]
    pv = value[peaks].astype(np.float64)
    peaks = peaks[np.lexsort((-pv, body))]  # per body, highest first (stable on ties)
    body, pv = row_body[ys[peaks]], value[peaks].astype(np.float64)
    px, py = xs[peaks], ys[peaks] - first_row[body]  # crop coordinates
    # every pair (j, i) of peaks of one body with i before j
    bounds = np.flatnonzero(np.diff(body, prepend=-1, append=-1))
    pairs = [
        (j, i)
        for lo, hi in itertools.pairwise(bounds.tolist())
        for j in range(lo + 1, hi)
        for i in range(lo, j)
    ]
    if not pairs:
        return counts
    jj, ii = np.array(pairs, np.intp).T
    # the segment from peak j to peak i, sampled as np.linspace(p_j, p_i, m) in crop pixels
    dx, dy = px[ii] - px[jj], py[ii] - py[jj]
    m = np.sqrt((dx * dx + dy * dy).astype(np.float64)).astype(np.intp) + 2
    seg_start = np.cumsum(m) - m
    pair = np.repeat(np.arange(len(m)), m)
    t = (np.arange(pair.size) - seg_start[pair]).astype(np.float64)
    lx = t * (dx / (m - 1))[pair] + px[jj][pair]
    ly = t * (dy / (m - 1))[pair] + py[jj][pair]
    last = seg_start + m - 1
    lx[last], ly[last] = px[ii], py[ii]
    samples = dt[ly.round().astype(np.intp) + first_row[body[jj]][pair], lx.round().astype(np.intp)]
    valley = np.minimum.reduceat(samples, seg_start)  # lowest point of every segment
    joined = valley >= valley_ratio * np.minimum(pv[jj], pv[ii])  # no waist between j and i
    joined_to: dict[int, set[int]] = {}
    for j, i in zip(jj[joined].tolist(), ii[joined].tolist(), strict=True):
        joined_to.setdefault(j, set()).add(i)
    for lo, hi in itertools.pairwise(bounds.tolist()):
        kept: list[int] = []
        for j in range(lo, hi):
            if not joined_to.get(j, set()).intersection(kept):
                kept.append(j)
        counts[body[lo]] = max(MIN_MERGED_COUNT, len(kept))
    return counts


def holes_filled(mask: np.ndarray, row_body: np.ndarray, bodies: np.ndarray) -> np.ndarray:
    """Canvas ``mask`` (0 / 1; ``row_body``: the body of every row) with every hole of the
    bodies where ``bodies`` is true filled. A hole is background that the background round the
    crops (4-connected) does not reach; it lies in the rows of the body round it."""
    outside = np.zeros((mask.shape[0] + 2, mask.shape[1] + 2), np.uint8)
    cv2.floodFill(mask.copy(), outside, (0, 0), 1, 0, 0, 4 | (1 << 8) | cv2.FLOODFILL_MASK_ONLY)
    holes = cv2.compare(outside[1:-1, 1:-1], 0, cv2.CMP_EQ) & cv2.compare(mask, 0, cv2.CMP_EQ)
    holes[~((row_body >= 0) & bodies[np.maximum(row_body, 0)])] = 0
    return mask | (holes & 1)


def pair_counts(
    bodies: Bodies, counts: np.ndarray, authentic: np.ndarray, pair_elongation: float
) -> np.ndarray:
    """``counts`` with the merged bodies of one peak that are two colonies counted 2 (step 5).

    Two colonies that overlap by more than about half their diameter leave no waist for the
    distance transform, so :func:`merged_counts` finds one peak. Such a body is longer than a
    single colony (axis ratio at least ``pair_elongation``; single colonies on the AGAR
    photographs: 1.01-1.21, 5th-95th percentile) and at least as large as the plate's median
    single colony (``authentic``: the authentic and mixed DES, ``MIN_SINGLES`` or more); a
    small or round irregular colony is neither.
    Measured on the AGAR photographs: of the one-peak merged bodies, 36 of the 52 that hold two
    or more boxed colonies and 13 of the 255 that hold one or none pass both.
    Tried and not kept: the axis ratio of the body opened by a disc of 0.5, 0.8 or 1.0 times
    its inscribed radius, so that pieces of the wall's lines stuck to a colony at the rim do
    not make it long (phone photo IMG_2528: one colony counted 2, 14 for 12): AGAR F1 0.911,
    0.909, 0.906 (0.910 without), median count error 5.7 -> 8.6 % at all three.
    """
    if pair_elongation <= 0 or authentic.sum() < MIN_SINGLES:
        return counts
    single = float(np.median(bodies.area[authentic]))
    pair = ~authentic & ~bodies.stroke & (counts == 1)
    pair &= (bodies.elongation >= pair_elongation) & (bodies.area >= single)
    return np.where(pair, 2, counts)
