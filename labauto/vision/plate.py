"""Plate analysis: from a petri-dish image to colonies worth picking (Teutsch et al., 4.1).

``analyze_plate(image)`` finds the dish, segments every object on the agar without knowing the
agar's colour, drops artefacts, and sorts the rest into authentic colonies (a deformed elliptic
shape, DES), merged colonies (touching colonies, not a DES) and mixed colonies (a DES holding two
species). Pure functions on arrays: no I/O.

Pipeline and the choices it makes where the paper leaves room:

0. **Scale.** Every size is in millimetres (``PlateParams``) and is turned into pixels from the
   dish found (its diameter is ``dish_diameter_mm``) or a calibrated ``px_per_mm``; images finer
   than ``analysis_px_per_mm`` are analysed on a resampled copy and the results mapped back
   (:mod:`labauto.vision.plate_scale`). Below, "px" means pixels of that working copy.
1. **Dish.** :func:`labauto.vision.dish.find_dish`: a Hough circle on a subsampled grey image,
   refined along rays where the colour leaves the agar's for about a millimetre and does not come
   back (the meniscus or the wall, not a line of the lid with agar beyond it), with a robust
   circle fit. It reads 0.2-2.3 px short of the
   drawn agar edge on the synthetic plates. A dish with over a quarter of its rim outside the
   image is refused (``detect_dish=False`` analyses the whole image). The usable area is the
   dish shrunk by ``rim_margin_mm`` (negative grows it), or a configured circle
   (``PlateParams.region``, also shrunk) or polygon (used as is). Bodies touching the usable
   area's border are kept (colonies at the meniscus), unless ``drop_at_border``.
2. **Objects** (paper eq. 1, with no knowledge of the agar's colour). The background is
   estimated from the dish itself (:mod:`labauto.vision.plate_background`): medians over cells
   of ~0.8 mm (a ~25 mm and a ~4 mm window) mark what is not agar, a normalised Gaussian
   convolution of the rest gives the local agar colour, and the outer ``rim_band_mm`` follow the
   dish's radial profile (the meniscus). A pixel is foreground when its summed squared deviation
   from the background over B, G, R (optionally weighted) exceeds ``t`` (``color_threshold``, or
   a multiple of the agar's noise). Faint colonies (a smoothed departure from a coarse
   background, :mod:`labauto.vision.plate_faint`) and ring colonies (a round edge with little
   body inside, by the circular Hough transform, :mod:`labauto.vision.plate_rings`) are added to
   that foreground. Lines thinner than ``open_mm`` are opened away so colonies touching them
   come apart, and fragments of thick strokes are dropped. Outer contours of all bodies, also
   those lying in another's hole, are traced in the 8-neighbourhood (OpenCV). The gradient at
   each contour point is a 5x5 Sobel of the deviation image: it points into every object,
   whatever its colour. D_alpha, the centroid and the centroid-inside test come from
   :func:`labauto.vision.shape_angle.shape_angles`, vectorised over all contours.
   ``method="detector"`` uses :func:`labauto.vision.detector.detect` instead (slower).
3. **Artefacts** are dropped, in this order: ``area < min_colony_area_px`` (dust) or
   ``> max_colony_area_px``; mean width ``2 * area / perimeter < min_width_px`` (scratches, thin
   pen strokes: a disc of radius r gives r, a strip of width w gives w); elongation
   ``sqrt(l1 / l2)`` of the second moments above ``max_elongation`` (glare streaks, straight
   strokes; the paper's DES limit is about 1:4); area above ``max_fill_ratio`` times the largest
   inscribed disc (curved or closed pen writing), unless it is as wide as the plate's colonies
   (``chain_ratio``: a chain of colonies along a streak, counted as a merged body); printed or
   written ink (black or blue, stroke-shaped, dot-sized or dotted:
   :mod:`labauto.vision.plate_ink`). The body's mask is its filled
   contour restricted to the foreground (a loop of ink is not solid) and closed with a 5x5 disc;
   holes under a tenth of it are filled (translucent centres, ``plate_bodies.HOLE_SHARE``).
4. **Classes.** Authentic: a DES, i.e. centroid inside and D_alpha (median by default) below
   ``des_threshold_deg``, and no waist: the deepest concavity (distance from the convex hull) is
   below ``max_concavity`` times the inscribed radius. D_alpha alone does not separate a merged
   pair of unequal colonies (they read 14-46 degrees, single colonies 2-21), the waist does
   (generator: singles <= 0.12, merged >= 0.22; ``max_concavity`` 0.2). Real colonies are round, so
   an authentic colony's axis ratio is at most ``max_authentic_elongation`` (1.2), and its distance
   transform has one peak (step 5 counts every body): two colonies that meet in a shallow waist
   pass the DES tests, and picking one would take a mix of two. Merged: every other object. Mixed:
   a DES whose colours do not follow one species' dome. Its pixels at least ``edge_skip_px`` inside
   the boundary are fitted per channel by a quadratic in the normalised distance to the boundary
   (the dome shading of one species); a pixel farther than ``mix_residual`` grey levels (Euclidean,
   BGR) from the fit is an outlier, and the colony is mixed when the fraction of outliers
   (``mix_score``) is at least ``mix_fraction``: a sector or speckles of a second species of
   another colour or brightness. A DES whose outliers hold one round spot of 0.4 mm or more
   (a small colony sitting on a large one, too small a share for the fraction) is mixed too
   (:func:`labauto.vision.plate_bodies.mix_scores`). The rule is absolute, not relative to the
   plate's other colonies, so a plate of only mixed colonies is still read right.
5. **Merged count.** Peaks of the merged body's distance transform (one per plateau), kept
   greedily from the highest; a peak is a new colony when the distance transform along the
   straight segment to every peak already kept dips below ``valley_ratio`` times the lower peak
   (a waist). At least 1: a body that is not a DES yet shows a single peak is one colony whose
   shape cannot be read as a DES (small colonies of a few pixels, irregular edges on real
   plates). It stays in the class ``merged`` (never offered for picking) with
   ``estimated_count`` 1; forcing 2 here over-counted small colonies on real plates by up to a
   third. A peak lower than ``peak_floor_ratio`` (0.3) times the median inscribed radius of
   the plate's DES bodies is no colony's centre (thin crescents of a large colony); a body with
   no point that deep that is also long (axis ratio ``sliver_elongation``, 1.5) is a sliver and
   is not reported (crescents of a large colony's pale rim, pieces of the wall). A body whose
   outline is a DES is counted with its holes filled (a translucent part or a reflection
   across one colony is no waist). A one-peak
   body longer than ``pair_elongation`` (1.3) and at least as large as the plate's median
   authentic colony counts two (two colonies overlapping too deeply for a waist): on the AGAR
   photographs F1 0.817 -> 0.827 and median count error 20.0 -> 17.9 %, on the phone photos
   (not used to choose it) 5.5 -> 3.1 %. Compact clumps of three whose members overlap deeply
   are the usual miss (counted 2).

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from labauto.vision.detector import detect
from labauto.vision.dish import Dish, find_dish
from labauto.vision.image import as_image
from labauto.vision.plate_background import (
    adaptive_threshold,
    deviation,
    hysteresis,
    local_background,
    open_thin_lines,
    rim_profile,
    with_hued_bodies,
    with_radial_rim,
)
from labauto.vision.plate_bodies import (
    MIN_SINGLES,
    PAD,
    measure_bodies,
    merged_counts,
    mix_scores,
    pair_counts,
)
from labauto.vision.plate_faint import faint_bodies
from labauto.vision.plate_ink import ink_bodies, without_ink
from labauto.vision.plate_params import Circle, PlateParams
from labauto.vision.plate_rings import ring_bodies, ring_circles
from labauto.vision.plate_scale import WorkingCopy, image_scale, pixel_params, working_copy
from labauto.vision.shape_angle import shape_angles

__all__ = [
    "Colony",
    "Dish",
    "PlateParams",
    "PlateResult",
    "analyze_plate",
    "find_dish",
]

KLASSES = ("authentic", "merged", "mixed")

_SOBEL5_SMOOTH = np.array([1.0, 4.0, 6.0, 4.0, 1.0], np.float32)
_SOBEL5_DERIV = np.array([-1.0, -2.0, 0.0, 2.0, 1.0], np.float32)
_SOBEL5_X = np.outer(_SOBEL5_SMOOTH, _SOBEL5_DERIV).ravel()  # rows: dy, cols: dx
_SOBEL5_Y = np.outer(_SOBEL5_DERIV, _SOBEL5_SMOOTH).ravel()
_DY5, _DX5 = (g.ravel() for g in np.mgrid[-2:3, -2:3])


@dataclass
class Colony:
    """One colony (or merged body) on the plate.

    Attributes
    ----------
    id : int
        Index in :attr:`PlateResult.colonies`.
    centroid : tuple of float
        Centre of gravity ``(x, y)`` of the contour's polygon.
    klass : str
        ``"authentic"``, ``"merged"`` or ``"mixed"``.
    area_px : float
        Pixels inside the contour.
    d_alpha_median : float
        Median shape angle D_alpha in degrees.
    estimated_count : int
        Colonies in the body (1 for authentic and mixed; for merged, the peaks of its distance
        transform: 1 when it is one colony whose shape is not a DES).
    contour : ndarray, shape (n, 2)
        Outline ``(x, y)`` in image pixels.
    mix_score : float
        Fraction of the colony's inner pixels that do not follow one species' colour.
    """

    id: int
    centroid: tuple[float, float]
    klass: str
    area_px: float
    d_alpha_median: float
    estimated_count: int
    contour: np.ndarray = field(repr=False)
    mix_score: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (contour as a list of ``[x, y]``)."""
        return {
            "id": self.id,
            "centroid": [round(float(self.centroid[0]), 3), round(float(self.centroid[1]), 3)],
            "class": self.klass,
            "area_px": float(self.area_px),
            "d_alpha_median": round(float(self.d_alpha_median), 3),
            "estimated_count": int(self.estimated_count),
            "mix_score": round(float(self.mix_score), 4),
            "contour": np.asarray(self.contour, dtype=float).round(2).tolist(),
        }


@dataclass
class PlateResult:
    """Everything :func:`analyze_plate` found on one plate.

    ``rejected`` counts the objects dropped per reason (dust, large, thin, elongated, stroke,
    ink, sliver, rim); ``stage_ms`` is the time taken per stage of :func:`analyze_plate`
    (``dish``: dish and usable area; ``objects``: segmentation, contours and D_alpha;
    ``measures``: artefact tests and waists; ``classes``: mixed-colony test, merged counts and
    the result). Both are diagnostic and not part of the JSON.
    """

    width: int
    height: int
    timing_ms: float
    dish: Dish
    colonies: list[Colony]
    rejected: dict[str, int] = field(default_factory=dict)
    stage_ms: dict[str, float] = field(default_factory=dict)

    @property
    def counts(self) -> dict[str, int]:
        """Colonies per class and ``colonies_estimate`` (merged bodies by their count)."""
        out = {k: sum(c.klass == k for c in self.colonies) for k in KLASSES}
        out["colonies_estimate"] = sum(c.estimated_count for c in self.colonies)
        return out

    def to_dict(self) -> dict[str, Any]:
        """Return the public JSON form (``labauto plate IMAGE --json``)."""
        return {
            "width": self.width,
            "height": self.height,
            "timing_ms": round(float(self.timing_ms), 3),
            "dish": self.dish.to_dict(),
            "colonies": [c.to_dict() for c in self.colonies],
            "counts": self.counts,
        }


_MAX_RIM_OUTSIDE = 0.25  # share of the dish's rim that may lie outside the image


def _rim_outside(dish: Dish, width: int, height: int) -> float:
    """The share of the dish's rim (circle) that lies outside the image, from 360 samples."""
    theta = np.linspace(0.0, 2 * np.pi, 360, endpoint=False)
    x = dish.center[0] + dish.radius * np.cos(theta)
    y = dish.center[1] + dish.radius * np.sin(theta)
    inside = (x >= -0.5) & (x <= width - 0.5) & (y >= -0.5) & (y <= height - 0.5)
    return float(1.0 - inside.mean())


def _dish_of(img: np.ndarray, params: PlateParams) -> tuple[Dish, np.ndarray | None]:
    """The dish (found or configured, original pixels) and the configured polygon, if any."""
    h, w = img.shape[:2]
    region = params.region
    if region is not None and np.asarray(region, dtype=float).shape != (3,):
        poly = np.asarray(region, dtype=np.float64)
        (ccx, ccy), cr = cv2.minEnclosingCircle(poly.astype(np.float32))
        return Dish((float(ccx), float(ccy)), float(cr)), poly
    if region is not None:
        return Dish((float(region[0]), float(region[1])), float(region[2])), None
    if params.detect_dish:
        dish = find_dish(img, params.dish_radius_range)
        outside = _rim_outside(dish, w, h)
        if outside > _MAX_RIM_OUTSIDE:
            (cx, cy), r = dish.center, dish.radius
            raise ValueError(
                f"the dish found at ({cx:.0f}, {cy:.0f}) px, radius {r:.0f} px, is cut by the "
                f"image border ({100 * outside:.0f} % of its rim lies outside the frame): frame "
                f"the whole dish, or set plate.detect_dish to false to analyse the whole image"
            )
        return dish, None
    whole = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64)
    return Dish(((w - 1) / 2, (h - 1) / 2), min(h, w) / 2), whole


def prepare_plate(
    img: np.ndarray, params: PlateParams
) -> tuple[Dish, WorkingCopy, PlateParams, tuple[int, int], np.ndarray, Circle | None]:
    """Dish, working copy, pixel-resolved params, ROI origin, usable mask and rim of a plate.

    The dish is in the original image's pixels; the ROI origin ``(x0, y0)``, the usable mask
    and the rim (the usable circle ``(cx, cy, r)`` in ROI pixels; None for a polygon) are in
    the working copy's (see :mod:`labauto.vision.plate_scale`).
    """
    dish, polygon = _dish_of(img, params)
    px_per_mm = image_scale(dish.radius, params)
    if polygon is not None:
        bounds = (*polygon.min(axis=0), *polygon.max(axis=0))
    else:
        (cx, cy), r = dish.center, dish.radius
        margin = params.rim_margin_px
        r -= min(margin if margin is not None else params.rim_margin_mm * px_per_mm, 0.0)
        bounds = (cx - r, cy - r, cx + r, cy + r)
    copy = working_copy(img, bounds, px_per_mm, params)
    params = pixel_params(params, copy)
    (wcx, wcy), wr = copy.to_working(dish.center), dish.radius * copy.factor
    work_poly = None if polygon is None else copy.to_working(polygon)
    (x0, y0, _, _), usable = _usable_area(copy.image, Dish((wcx, wcy), wr), work_poly, params)
    rim = None
    if polygon is None:
        rim = (wcx - x0, wcy - y0, wr - float(params.rim_margin_px or 0.0))
    return dish, copy, params, (x0, y0), usable, rim


def _usable_area(
    img: np.ndarray, dish: Dish, polygon: np.ndarray | None, params: PlateParams
) -> tuple[tuple[int, int, int, int], np.ndarray]:
    """The ROI ``(x0, y0, x1, y1)`` and the usable mask (uint8 0/255) in it.

    ``dish`` and ``polygon`` are in ``img``'s pixels; a circle is shrunk by ``rim_margin_px``,
    a polygon is used as it is.
    """
    h, w = img.shape[:2]
    if polygon is not None:
        poly = polygon
        x0, y0 = max(int(np.floor(poly[:, 0].min())), 0), max(int(np.floor(poly[:, 1].min())), 0)
        x1 = min(int(np.ceil(poly[:, 0].max())) + 1, w)
        y1 = min(int(np.ceil(poly[:, 1].max())) + 1, h)
        mask = np.zeros((max(y1 - y0, 0), max(x1 - x0, 0)), np.uint8)
        cv2.fillPoly(mask, [np.round(poly - [x0, y0]).astype(np.int32)], 255)
    else:
        cx, cy = dish.center
        ru = dish.radius - float(params.rim_margin_px or 0.0)
        if ru <= 2:
            raise ValueError(
                f"usable dish radius {ru:.1f} px is too small (dish radius "
                f"{dish.radius:.1f}, rim margin {params.rim_margin_px:.1f} px)"
            )
        x0, y0 = max(int(cx - ru) - 1, 0), max(int(cy - ru) - 1, 0)
        x1, y1 = min(int(cx + ru) + 2, w), min(int(cy + ru) + 2, h)
        mask = np.zeros((max(y1 - y0, 0), max(x1 - x0, 0)), np.uint8)
        shift = 4
        cv2.circle(
            mask,
            (round((cx - x0) * 16), round((cy - y0) * 16)),
            round(ru * 16),
            255,
            -1,
            cv2.LINE_8,
            shift,
        )
    if mask.size == 0 or not mask.any():
        raise ValueError("the usable area of the plate lies outside the image")
    return (x0, y0, x1, y1), mask


# --------------------------------------------------------------------------------------------
# Segmentation (eq. 1 with a local background)


def _rim_band_px(params: PlateParams) -> float:
    """Width of the outer band that follows the dish's radial profile (working pixels)."""
    return params.rim_band_mm * float(params.px_per_mm or 1.0)


def _background(
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
        return with_radial_rim(roi, bg, rim, _rim_band_px(params))
    found = profile.result()
    return bg if found is None else with_radial_rim(roi, bg, rim, _rim_band_px(params), found)


def _gradients(dev: np.ndarray, points: np.ndarray) -> np.ndarray:
    """5x5 Sobel gradient of ``dev`` at integer ``points`` (x, y), vectorised."""
    h, w = dev.shape
    xs = np.clip(points[:, 0], 2, w - 3)
    ys = np.clip(points[:, 1], 2, h - 3)
    flat = (ys * w + xs)[:, None] + (_DY5 * w + _DX5)[None, :]
    patch = dev.ravel().take(flat)
    return np.column_stack((patch @ _SOBEL5_X, patch @ _SOBEL5_Y))


# --------------------------------------------------------------------------------------------
# The analysis


def analyze_plate(image: np.ndarray, params: PlateParams | None = None) -> PlateResult:
    """Find and classify the colonies on a petri-dish image.

    Parameters
    ----------
    image : ndarray
        HxWx3 BGR image (as ``cv2.imread`` gives), uint8 or a real type on a 0-255 scale; HxW
        grey and HxWx4 (alpha dropped) are accepted.
    params : PlateParams, optional
        Tunables; ``PlateParams()`` by default.

    Returns
    -------
    PlateResult
        The dish, the colonies (authentic, merged, mixed; artefacts dropped), counts and the time
        taken.

    Raises
    ------
    ValueError
        If the image is empty, has a wrong shape or type, or no dish is found.
    """
    t0 = time.perf_counter()
    params = PlateParams() if params is None else params
    img = as_image(image, color=True, min_side=64)
    h, w = img.shape[:2]
    stage_ms: dict[str, float] = {}
    t_stage = t0

    def stage_done(name: str) -> None:
        nonlocal t_stage
        now = time.perf_counter()
        stage_ms[name] = (now - t_stage) * 1000.0
        t_stage = now

    dish, copy, params, (x0, y0), usable, rim = prepare_plate(img, params)
    roi = copy.image[y0 : y0 + usable.shape[0], x0 : x0 + usable.shape[1]]
    if not params.drop_at_border:
        # a margin of PAD px all round, so that bodies touching the usable area's border
        # (colonies at the meniscus) still have whole crops
        roi = cv2.copyMakeBorder(roi, PAD, PAD, PAD, PAD, cv2.BORDER_REPLICATE)
        usable = cv2.copyMakeBorder(usable, PAD, PAD, PAD, PAD, cv2.BORDER_CONSTANT, value=0)
        x0, y0 = x0 - PAD, y0 - PAD
        if rim is not None:
            rim = (rim[0] + PAD, rim[1] + PAD, rim[2])
    stage_done("dish")

    # what needs only the image runs in a thread beside eq. 1's background, threshold and faint
    # pass (OpenCV lets go of the GIL; a pool per call is safe after a fork): the rim's radial
    # profile, then the ring colonies' circle search (cv2.HoughCircles, ~5 ms per 1.3-Mpixel
    # plate). The results are the same as in sequence.
    side = ThreadPoolExecutor(max_workers=1, thread_name_prefix="labauto-plate")
    profile = circles = None
    if rim is not None and params.rim_band_mm > 0:
        profile = side.submit(rim_profile, roi, rim, _rim_band_px(params))
    if params.method != "detector" and params.find_rings:
        circles = side.submit(ring_circles, roi, usable, float(params.px_per_mm or 1.0))
    side.shutdown(wait=False)  # the thread ends with its tasks
    background = _background(roi, usable, params, rim, profile)
    if params.method == "detector":
        objects = _objects_by_detector(roi, usable, params)
    else:
        objects = _objects_by_segmentation(roi, usable, params, background, circles)
    contours, d_alpha, inside, centroids, rejected, fg = objects
    stage_done("objects")

    # a DES needs its centroid inside and a small D_alpha; only then does the waist matter
    des_shape = np.asarray(inside, bool) & (np.asarray(d_alpha) < params.des_threshold_deg)
    bodies = measure_bodies(contours, fg, des_shape, params, rejected)
    stroke_shaped = bodies.stroke.copy()
    ppm = float(params.px_per_mm or 0.0)
    # a single colony's shape: a DES outline, no waist, round
    single = des_shape[bodies.index] & (bodies.concavity < params.max_concavity)
    single &= bodies.elongation <= params.max_authentic_elongation
    if params.reject_ink:
        coarse = copy.factor > 1.0  # a resampled webcam frame: print's dots have merged
        ink = ink_bodies(roi, background, bodies, ~bodies.stroke, ppm, single if coarse else None)
        if ink.any():
            rejected["ink"] = int(ink.sum())
            bodies.stroke |= ink
    des = single & ~bodies.stroke
    # the plate's yardstick: the inscribed radius of its single colonies
    single_r_in = float(np.median(bodies.r_in[des])) if des.sum() >= MIN_SINGLES else 0.0
    if params.chain_ratio > 0 and single_r_in > 0:  # as wide as a colony: a chain of them
        chain = stroke_shaped & (bodies.r_in >= params.chain_ratio * single_r_in)
        if params.reject_ink and chain.any():
            chain &= ~ink_bodies(roi, background, bodies, chain, ppm)
        if chain.any():
            rejected["stroke"] -= int(chain.sum())
            bodies.stroke &= ~chain
    stage_done("measures")
    # every body is counted: a DES holding two peaks apart (two colonies that meet in a shallow
    # waist) is merged, never offered for picking
    least_peak = params.peak_floor_ratio * single_r_in  # thinner: no colony's centre
    if params.sliver_elongation > 0 and least_peak > 0:  # no centre anywhere, and long
        sliver = ~bodies.stroke & (bodies.r_in < least_peak)
        sliver &= bodies.elongation >= params.sliver_elongation
        if sliver.any():
            rejected["sliver"] = int(sliver.sum())
            bodies.stroke |= sliver
            des &= ~sliver
    # printed characters touching a colony are not counted as colonies
    count_mask, inked = None, np.zeros(len(des), bool)
    if params.reject_ink:
        found = without_ink(roi, background, bodies, ~bodies.stroke & ~des)
        if found is not None:
            count_mask, inked = found
    counts = merged_counts(
        bodies, ~bodies.stroke, params.valley_ratio, least_peak, des_shape[bodies.index], count_mask
    )
    des &= counts == 1
    counts = np.where(inked, counts, pair_counts(bodies, counts, des, params.pair_elongation))
    mix, spotted = mix_scores(roi, bodies, des, params)

    colonies: list[Colony] = []
    for b, k in enumerate(bodies.index.tolist()):
        if bodies.stroke[b]:
            continue
        klass = "merged"
        if des[b]:
            klass = "mixed" if mix[b] >= params.mix_fraction or spotted[b] else "authentic"
        centroid = copy.to_original(np.add(centroids[k], (x0, y0)))
        colonies.append(
            Colony(
                id=len(colonies),
                centroid=(float(centroid[0]), float(centroid[1])),
                klass=klass,
                area_px=float(bodies.area[b]) / copy.factor**2,
                d_alpha_median=float(d_alpha[k]),
                estimated_count=int(counts[b]),
                contour=copy.to_original(np.add(contours[k].reshape(-1, 2), (x0, y0))),
                mix_score=float(mix[b]),
            )
        )
    stage_done("classes")
    timing = (time.perf_counter() - t0) * 1000.0
    return PlateResult(
        width=w,
        height=h,
        timing_ms=timing,
        dish=dish,
        colonies=colonies,
        rejected=rejected,
        stage_ms=stage_ms,
    )


# contours, D_alpha, centroid inside, centroids (ROI pixels), reject counts, foreground or None
_Objects = tuple[
    list[np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, int], np.ndarray | None
]


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


def _objects_by_segmentation(
    roi: np.ndarray,
    usable: np.ndarray,
    params: PlateParams,
    background: np.ndarray,
    circles: Future | None = None,
) -> _Objects:
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
            max_diameter_mm=params.faint_max_diameter_mm,
            margin_mm=params.rim_band_mm,
            agar_colour=background,
        )
        fg = cv2.bitwise_or(fg, faint)
    if params.find_rings:
        found = None if circles is None else circles.result()
        fg = ring_bodies(roi, usable, fg, float(params.px_per_mm or 1.0), circles=found)
    if params.open_mm > 0:
        # lines thinner than open_mm (the lid's and the wall's edges, scratches, hairs) go, so
        # colonies touching them come apart from them
        k = 2 * math.floor(params.open_mm * float(params.px_per_mm or 0.0) / 2) + 1  # odd
        if k >= 3:
            fg = with_hued_bodies(fg, open_thin_lines(fg, k), roi, background)
    # outer boundaries of every body, also of bodies lying in another's hole (a colony inside
    # the meniscus ring): RETR_CCOMP puts all outer boundaries at the top level
    traced, hierarchy = cv2.findContours(fg, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    found = [c for c, h in zip(traced, hierarchy[0] if traced else [], strict=True) if h[3] < 0]
    min_points = max(4, int(2.0 * math.sqrt(params.min_colony_area_px)))
    candidates = [c for c in found if len(c) >= min_points]
    rejected = {"dust": len(found) - len(candidates), "rim": 0}
    if not candidates:
        return [], np.zeros(0), np.zeros(0, bool), np.zeros((0, 2)), rejected, fg
    at_rim = np.zeros(len(candidates), bool)
    if params.drop_at_border:
        at_rim = _at_rim(usable, candidates)
    kept = [c for c, rim in zip(candidates, at_rim.tolist(), strict=True) if not rim]
    rejected["rim"] = len(candidates) - len(kept)
    if not kept:
        return [], np.zeros(0), np.zeros(0, bool), np.zeros((0, 2)), rejected, fg
    offsets = np.cumsum([0] + [len(c) for c in kept])
    points = np.concatenate(kept).reshape(-1, 2)
    grads = _gradients(dev, points)
    sa = shape_angles(
        points.astype(np.float64), grads.astype(np.float64), offsets, np.ones(len(kept), bool)
    )
    return kept, sa.statistic(params.statistic), sa.centroid_inside, sa.centroid, rejected, fg


def _objects_by_detector(roi: np.ndarray, usable: np.ndarray, params: PlateParams) -> _Objects:
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
    return (
        contours,
        np.asarray(d_alpha, float),
        np.asarray(inside, bool),
        np.asarray(centroids, float).reshape(-1, 2),
        rejected,
        None,
    )
