"""Mixed colonies: the share of a colony's inner pixels that do not follow one species' colour,
and round spots of a second colony on a large one (plate analysis, steps 4 and 5).

:mod:`labauto.vision.plate` gives the rule and its measured figures.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from labauto.vision.plate_bodies import Bodies
from labauto.vision.plate_params import PlateParams

SPOT_MM = 0.4  # a second colony on a colony: a round spot of outliers at least this wide ...
SPOT_ROUNDNESS = 0.7  # ... both ways, filling this share of the ellipse in its bounding box
LARGE_BODY_RATIO = 1.5  # a body this many times as wide as the plate's single colonies is large


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
