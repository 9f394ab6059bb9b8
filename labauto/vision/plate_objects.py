"""The objects on the agar: eq. 1's segmentation, contours and D_alpha (plate analysis, step 2).

:func:`objects_by_segmentation` finds the foreground (eq. 1 on the agar's local background, the
faint and the ring colonies, thin lines opened away), traces the outer contours and takes
D_alpha, the centroid and the centroid-inside test of every one; :func:`objects_by_detector`
takes them from the generic detector instead. :func:`start_beside` starts, in a thread of its
own, what needs only the image (:mod:`labauto.vision.plate` gives the rules).
"""

from __future__ import annotations

import math
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.vision.detector import detect
from labauto.vision.plate_background import (
    adaptive_threshold,
    deviation,
    hysteresis,
    local_background,
    rim_profile,
    with_radial_rim,
)
from labauto.vision.plate_bodies import PAD
from labauto.vision.plate_faint import faint_bodies
from labauto.vision.plate_opening import open_thin_lines, with_erased_colonies
from labauto.vision.plate_params import Circle, PlateParams
from labauto.vision.plate_rings import ring_bodies, ring_circles
from labauto.vision.shape_angle import shape_angles

_SOBEL5_SMOOTH = np.array([1.0, 4.0, 6.0, 4.0, 1.0], np.float32)
_SOBEL5_DERIV = np.array([-1.0, -2.0, 0.0, 2.0, 1.0], np.float32)
_SOBEL5_X = np.outer(_SOBEL5_SMOOTH, _SOBEL5_DERIV).ravel()  # rows: dy, cols: dx
_SOBEL5_Y = np.outer(_SOBEL5_DERIV, _SOBEL5_SMOOTH).ravel()
_DY5, _DX5 = (g.ravel() for g in np.mgrid[-2:3, -2:3])


def start_beside(
    roi: np.ndarray, usable: np.ndarray, rim: Circle | None, params: PlateParams
) -> tuple[Future | None, Future | None]:
    """The rim's radial profile and the ring colonies' circle search, started in a thread.

    Both need only the image, and OpenCV lets go of the GIL: they run while eq. 1's
    background, threshold and faint pass take the calling thread, the profile first, then the
    circle search (``cv2.HoughCircles``, ~5 ms per 1.3-Mpixel plate). A pool per call is safe
    after a fork; the results are the same as in sequence. Either future is None when the
    parameters leave its step out.
    """
    side = ThreadPoolExecutor(max_workers=1, thread_name_prefix="labauto-plate")
    profile = circles = None
    if rim is not None and params.rim_band_mm > 0:
        ppm = float(params.px_per_mm or 0.0)
        profile = side.submit(rim_profile, roi, rim, rim_band_px(params), ppm)
    if params.method != "detector" and params.find_rings:
        circles = side.submit(ring_circles, roi, usable, float(params.px_per_mm or 1.0))
    side.shutdown(wait=False)  # the thread ends with its tasks
    return profile, circles


def rim_band_px(params: PlateParams) -> float:
    """Width of the outer band that follows the dish's radial profile (working pixels)."""
    return params.rim_band_mm * float(params.px_per_mm or 1.0)


def agar_background(
    roi: np.ndarray,
    usable: np.ndarray,
    params: PlateParams,
    rim: Circle | None = None,
    profile: Future | None = None,
) -> np.ndarray:
    """The agar's local colour (:func:`labauto.vision.plate_background.local_background`).

    ``profile`` is the rim's radial profile (:func:`rim_profile`) started beside, if it was.
    """
    cell = int(params.background_scale or 1)
    bg = local_background(roi, usable, cell, params.color_threshold)
    if rim is None or params.rim_band_mm <= 0:
        return bg
    if profile is None:
        found = rim_profile(roi, rim, rim_band_px(params), float(params.px_per_mm or 0.0))
    else:
        found = profile.result()
    return with_radial_rim(bg, found)


def _gradients(dev: np.ndarray, points: np.ndarray) -> np.ndarray:
    """5x5 Sobel gradient of ``dev`` at integer ``points`` (x, y), vectorised."""
    h, w = dev.shape
    xs = np.clip(points[:, 0], 2, w - 3)
    ys = np.clip(points[:, 1], 2, h - 3)
    flat = (ys * w + xs)[:, None] + (_DY5 * w + _DX5)[None, :]
    patch = dev.ravel().take(flat)
    return np.column_stack((patch @ _SOBEL5_X, patch @ _SOBEL5_Y))


@dataclass
class Objects:
    """The objects found on the agar (ROI pixels), one entry per contour.

    ``doubtful`` marks the objects that are counted but never offered for picking: lone dots
    the opening erased and that came back without a hue of their own
    (:func:`labauto.vision.plate_opening.with_erased_colonies`). ``foreground`` is eq. 1's
    final mask, ``unopened`` the same before thin lines were opened away, ``departure`` eq. 1's
    deviation from the agar's background (all three None for the generic detector).
    """

    contours: list[np.ndarray]
    d_alpha: np.ndarray
    inside: np.ndarray  # centroid-inside test
    centroids: np.ndarray
    rejected: dict[str, int]
    foreground: np.ndarray | None
    doubtful: np.ndarray
    unopened: np.ndarray | None = None
    departure: np.ndarray | None = None

    @classmethod
    def none(
        cls,
        rejected: dict[str, int],
        foreground: np.ndarray | None,
        unopened: np.ndarray | None = None,
    ) -> Objects:
        """No object (all rejected, or none found)."""
        empty = np.zeros(0, bool)
        return cls([], np.zeros(0), empty, np.zeros((0, 2)), rejected, foreground, empty, unopened)


def _at_rim(usable: np.ndarray, contours: list[np.ndarray]) -> np.ndarray:
    """True for every contour with a point within ``PAD`` px of the usable area's outline.

    The usable mask is eroded by a square of ``2 * PAD + 1`` (one full-size pass) and read
    only at the contours' points, all at once.
    """
    if not contours:
        return np.zeros(0, bool)
    kernel = np.ones((2 * PAD + 1, 2 * PAD + 1), np.uint8)
    inner = cv2.erode(usable, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    points = np.concatenate(contours).reshape(-1, 2)
    starts = np.cumsum([0] + [len(c) for c in contours[:-1]])
    return np.logical_or.reduceat(inner[points[:, 1], points[:, 0]] == 0, starts)


def objects_by_segmentation(
    roi: np.ndarray,
    usable: np.ndarray,
    params: PlateParams,
    background: np.ndarray,
    circles: Future | None = None,
) -> Objects:
    """Contours of eq. 1's objects with D_alpha, centroid-inside and centroid (ROI pixels).

    ``circles`` is the ring colonies' circle search (:func:`ring_circles`), started beside.
    """
    dev = deviation(roi, background, params.channel_weights)
    t = adaptive_threshold(dev, usable, params.color_threshold, params.noise_factor)
    fg = hysteresis(dev, usable, t, params.low_ratio * t)
    if params.faint_factor > 0:
        faint = faint_bodies(
            roi,
            usable,
            fg,
            float(params.px_per_mm or 1.0),
            factor=params.faint_factor,
            min_diameter_mm=params.faint_min_diameter_mm,
            min_hue_diameter_mm=params.faint_min_hue_diameter_mm,
            max_diameter_mm=params.faint_max_diameter_mm,
            margin_mm=params.rim_band_mm,
            agar_colour=background,
        )
        fg = cv2.bitwise_or(fg, faint)
    if params.find_rings:
        ppm = float(params.px_per_mm or 1.0)
        found = ring_circles(roi, usable, ppm) if circles is None else circles.result()
        fg = ring_bodies(usable, fg, found, ppm)
    dots = None  # lone dots put back after the opening: doubtful colonies
    unopened = fg  # the ring lines the opening takes away tell their pieces (step 3)
    if params.open_mm > 0:
        # lines thinner than open_mm (the lid's and the wall's edges, scratches, hairs) go, so
        # colonies touching them come apart from them
        k = 2 * math.floor(params.open_mm * float(params.px_per_mm or 0.0) / 2) + 1  # odd
        if k >= 3:
            fg, dots = with_erased_colonies(
                fg, open_thin_lines(fg, k, roi, background), roi, background, k
            )
    # outer boundaries of every body, also of bodies lying in another's hole (a colony inside
    # the meniscus ring): RETR_CCOMP puts all outer boundaries at the top level
    traced, hierarchy = cv2.findContours(fg, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    found = [c for c, h in zip(traced, hierarchy[0] if traced else [], strict=True) if h[3] < 0]
    min_points = max(4, int(2.0 * math.sqrt(params.min_colony_area_px)))
    candidates = [c for c in found if len(c) >= min_points]
    rejected = {"dust": len(found) - len(candidates), "rim": 0}
    if not candidates:
        return Objects.none(rejected, fg, unopened)
    at_rim = np.zeros(len(candidates), bool)
    if params.drop_at_border:
        at_rim = _at_rim(usable, candidates)
    kept = [c for c, rim in zip(candidates, at_rim.tolist(), strict=True) if not rim]
    rejected["rim"] = len(candidates) - len(kept)
    if not kept:
        return Objects.none(rejected, fg, unopened)
    offsets = np.cumsum([0] + [len(c) for c in kept])
    points = np.concatenate(kept).reshape(-1, 2)
    grads = _gradients(dev, points)
    sa = shape_angles(
        points.astype(np.float64), grads.astype(np.float64), offsets, np.ones(len(kept), bool)
    )
    doubtful = np.zeros(len(kept), bool)
    if dots is not None:  # a dot touches nothing else: its contour lies on it
        first = np.array([c[0, 0] for c in kept])
        doubtful = dots[first[:, 1], first[:, 0]] > 0
    statistic = sa.statistic(params.statistic)
    return Objects(
        kept, statistic, sa.centroid_inside, sa.centroid, rejected, fg, doubtful, unopened, dev
    )


def objects_by_detector(roi: np.ndarray, usable: np.ndarray, params: PlateParams) -> Objects:
    """Objects of the generic detector on the dish, the area outside the usable one painted agar."""
    agar = np.median(roi[usable > 0], axis=0).astype(np.uint8)
    painted = roi.copy()
    painted[usable == 0] = agar
    result = detect(painted, params.detector)
    h, w = usable.shape
    contours, d_alpha, inside, centroids = [], [], [], []
    rejected = {"open": 0, "rim": 0}
    closed, closed_points = [], []
    for obj in result.objects:
        if not obj.closed:
            rejected["open"] += 1
            continue
        pts = np.round(np.asarray(obj.points, dtype=float)).astype(np.int32)
        pts[:, 0] = np.clip(pts[:, 0], 0, w - 1)
        pts[:, 1] = np.clip(pts[:, 1], 0, h - 1)
        closed.append(obj)
        closed_points.append(pts)
    for obj, pts, rim in zip(closed, closed_points, _at_rim(usable, closed_points), strict=True):
        if rim:
            rejected["rim"] += 1
            continue
        contours.append(pts.reshape(-1, 1, 2))
        d_alpha.append(obj.d_alpha_median if params.statistic == "median" else obj.d_alpha_mean)
        inside.append(obj.centroid_inside)
        centroids.append(obj.centroid)
    return Objects(
        contours,
        np.asarray(d_alpha, float),
        np.asarray(inside, bool),
        np.asarray(centroids, float).reshape(-1, 2),
        rejected,
        None,
        np.zeros(len(contours), bool),
    )
