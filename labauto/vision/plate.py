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
   refined along rays where the colour leaves the agar's for about a millimetre (the meniscus or
   the wall, not a thin lid line), with a robust circle fit. It reads 0.2-2.3 px short of the
   drawn agar edge on the synthetic plates. A dish with over a quarter of its rim outside the
   image is refused (``detect_dish=False`` analyses the whole image). The usable area is the
   dish shrunk by ``rim_margin_mm`` (negative grows it), or a configured circle
   (``PlateParams.region``, also shrunk) or polygon (used as is). Bodies touching the usable
   area's border are kept (colonies at the meniscus), unless ``drop_at_border``.
2. **Objects** (paper eq. 1, with no knowledge of the agar's colour). The background is
   estimated from the dish itself (:mod:`labauto.vision.plate_background`): medians over cells
   of ~0.8 mm (a ~25 mm and a ~4 mm window) mark what is not agar, a normalised Gaussian
   convolution of the rest gives the local agar colour, and the outer ``rim_band_mm`` follow
   the dish's radial profile (the meniscus). A pixel is foreground when its summed squared
   deviation from the background over B, G, R (optionally weighted) exceeds ``t``
   (``color_threshold``, or a multiple of the agar's noise); lines thinner than ``open_mm``
   are opened away so colonies touching them come apart, and fragments of thick strokes are
   dropped. Outer contours of all bodies, also those lying in another's hole, are traced in
   the 8-neighbourhood (OpenCV). The gradient at each contour point is a 5x5 Sobel of the
   deviation image: it points into every object, whatever its colour. D_alpha, the centroid and
   the centroid-inside test come from :func:`labauto.vision.shape_angle.shape_angles`,
   vectorised over all contours. ``method="detector"`` uses
   :func:`labauto.vision.detector.detect` instead (slower).
3. **Artefacts** are dropped, in this order: ``area < min_colony_area_px`` (dust) or
   ``> max_colony_area_px``; mean width ``2 * area / perimeter < min_width_px`` (scratches, thin
   pen strokes: a disc of radius r gives r, a strip of width w gives w); elongation
   ``sqrt(l1 / l2)`` of the second moments above ``max_elongation`` (glare streaks, straight
   strokes; the paper's DES limit is about 1:4); area above ``max_fill_ratio`` times the largest
   inscribed disc (curved or closed pen writing); printed or written ink (black or blue, stroke-
   shaped, dot-sized or dotted: :mod:`labauto.vision.plate_ink`). The body's mask is its filled
   contour restricted to the foreground (a loop of ink is not solid) and closed with a 5x5 disc.
4. **Classes.** Authentic: a DES, i.e. centroid inside and D_alpha (median by default) below
   ``des_threshold_deg``, and no waist: the deepest concavity (distance from the convex hull)
   is below ``max_concavity`` times the inscribed radius. D_alpha alone does not separate a
   merged pair of unequal colonies (they read 14-46 degrees, single colonies 2-21), the waist
   does (measured: singles <= 0.12, merged >= 0.22). Real colonies are round, so an authentic
   colony's axis ratio is at most ``max_authentic_elongation`` (1.3), and its distance transform
   has one peak (step 5 counts every body): two colonies that meet in a shallow waist pass the
   DES tests, and picking one would take a mix of two. Merged: every other object. Mixed: a DES
   whose colours do not follow one species' dome. Its pixels at least ``edge_skip_px`` inside
   the boundary are fitted per channel by a quadratic in the normalised distance to the
   boundary (the dome shading of one species); a pixel farther than ``mix_residual`` grey
   levels (Euclidean, BGR) from the fit is an outlier, and the colony is mixed when the fraction
   of outliers (``mix_score``) is at least ``mix_fraction``: a sector or speckles of a second
   species of another colour or brightness. The rule is absolute, not relative to the plate's
   other colonies, so a plate of only mixed colonies is still read right.
5. **Merged count.** Peaks of the merged body's distance transform (one per plateau), kept
   greedily from the highest; a peak is a new colony when the distance transform along the
   straight segment to every peak already kept dips below ``valley_ratio`` times the lower peak
   (a waist). At least 1: a body that is not a DES yet shows a single peak is one colony whose
   shape cannot be read as a DES (small colonies of a few pixels, irregular edges on real
   plates). It stays in the class ``merged`` (never offered for picking) with
   ``estimated_count`` 1; forcing 2 here over-counted small colonies on real plates by up to a
   third. Compact clumps of three whose members overlap deeply are the usual miss (counted 2).

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from labauto.vision.detector import DetectorParams, detect
from labauto.vision.dish import Dish, find_dish
from labauto.vision.image import as_image
from labauto.vision.plate_background import (
    adaptive_threshold,
    deviation,
    hysteresis,
    local_background,
    open_thin_lines,
    with_radial_rim,
)
from labauto.vision.plate_faint import faint_bodies
from labauto.vision.plate_ink import ink_bodies
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

Circle = tuple[float, float, float]
Polygon = tuple[tuple[float, float], ...]

_SQUARES = (np.arange(256, dtype=np.float32) ** 2).reshape(1, 256)
_ONES_3 = np.ones((1, 3), np.float32)  # cv2.transform: sum of the three channels
_SOBEL5_SMOOTH = np.array([1.0, 4.0, 6.0, 4.0, 1.0], np.float32)
_SOBEL5_DERIV = np.array([-1.0, -2.0, 0.0, 2.0, 1.0], np.float32)
_SOBEL5_X = np.outer(_SOBEL5_SMOOTH, _SOBEL5_DERIV).ravel()  # rows: dy, cols: dx
_SOBEL5_Y = np.outer(_SOBEL5_DERIV, _SOBEL5_SMOOTH).ravel()
_DY5, _DX5 = (g.ravel() for g in np.mgrid[-2:3, -2:3])
_MIN_MERGED_COUNT = 1  # a body that is not a DES but shows one peak: one colony, not pickable
_PAD = 3  # margin (px) around a body's mask; bodies this close to the usable border are dropped
_DISC5 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))


@dataclass(frozen=True)
class PlateParams:
    """Tunables of :func:`analyze_plate`; sizes in millimetres, turned into pixels per image.

    Every size is physical. The image's scale (pixels per mm) comes from ``px_per_mm`` when a
    camera calibration gives it, else from the dish found in the image (its diameter is
    ``dish_diameter_mm``). Images finer than ``analysis_px_per_mm`` are analysed on a copy
    resampled to that scale (area averaging), and the results are mapped back to the image's
    pixels, so the same defaults serve a 0.5-Mpixel webcam image and a 16-Mpixel photo. Each
    ``*_px`` field, when set, overrides its millimetre twin (pixels of the image as given).

    Attributes
    ----------
    region : tuple or None
        Usable area, skipping dish detection: a circle ``(cx, cy, r)`` (the rim margin is then
        still taken off) or a polygon ``((x, y), ...)`` of at least 3 vertices (used as is).
    detect_dish : bool
        Find the dish when ``region`` is None; if False the whole image is the usable area.
    dish_radius_range : tuple of float
        Dish radius searched, as fractions of ``min(height, width)``.
    dish_diameter_mm : float
        Diameter of the agar disc that :func:`find_dish` finds (or ``region`` gives), in mm.
    px_per_mm : float or None
        The image's scale from a camera calibration; None: from the dish.
    analysis_px_per_mm : float
        Finest scale analysed; finer images are resampled down to it (0: never resample).
    rim_margin_mm, rim_margin_px : float
        Width of the band inside the dish edge that is ignored (the wall's shadow). Colonies
        that touch the meniscus inside it are still found: only their part on the band is cut.
    method : str
        ``"segmentation"`` (eq. 1 with a local background, default) or ``"detector"`` (the generic
        :func:`labauto.vision.detector.detect` on the dish with ``detector`` params).
    color_threshold : float
        Least ``t`` of eq. 1: summed squared deviation from the background (grey levels squared).
    noise_factor : float
        ``t`` is at least this many times the agar's median deviation (its noise); 0: off.
    low_ratio : float
        Hysteresis: a body's pixels need only ``low_ratio * t`` when it holds one above ``t``.
    open_mm : float
        The foreground is opened with a disc of this diameter: thinner lines (the lid's and the
        wall's edges, scratches, hairs) are removed and colonies touching them come apart;
        0 turns it off.
    channel_weights : tuple of float
        Weights of the B, G, R squared deviations in eq. 1.
    background_cell_mm, background_scale : float, int
        Cell of the background estimate (its detail is ~4 cells); ``background_scale`` in px.
    min_colony_diameter_mm, max_colony_diameter_mm : float
        Objects smaller (dust) or larger than a disc of these diameters are not colonies;
        ``min_colony_area_px`` and ``max_colony_area_px`` override them as areas in pixels.
    min_width_mm, min_width_px : float
        Objects with a mean width ``2 * area / perimeter`` below this are scratches or strokes.
    max_elongation : float
        Objects with a second-moment axis ratio above this are streaks (glare, pen).
    max_fill_ratio : float
        Objects whose area exceeds this many times the area of their largest inscribed disc are
        strokes (pen writing, scratches); merged chains of up to ~4 colonies stay below 5.
    des_threshold_deg : float
        D_alpha threshold of a DES, degrees (25: colonies are at most ~1:1.6 and read <= 21;
        the paper's "typical DES" of ~30 also takes in merged pairs of unequal size).
    statistic : str
        ``"median"`` or ``"mean"`` D_alpha.
    max_concavity : float
        Largest depth of a concavity (distance from the convex hull) relative to the inscribed
        radius for a DES; a waist between two colonies is deeper.
    max_authentic_elongation : float
        Largest second-moment axis ratio of an authentic colony; a longer DES is merged (with
        its count). Measured on the AGAR photographs: single colonies 1.01-1.21 (5th-95th
        percentile, 2.8 % above 1.3), DES bodies that hold two colonies 1.03-1.72 (median 1.38,
        22 of 40 above 1.3).
    edge_skip_mm, edge_skip_px : float
        Pixels this close to a colony's boundary are left out of the mixed-colony test.
    mix_residual : float
        Colour distance (grey levels) from the one-species dome fit that makes a pixel an outlier.
    mix_fraction : float
        Least fraction of outlier pixels that makes a DES a mixed colony.
    valley_ratio : float
        Distance-transform dip between two peaks, relative to the lower peak, that separates two
        colonies of a merged body.
    rim_band_mm : float
        Width of the band inside the agar's edge whose background follows the dish's radial
        profile (the meniscus; see :func:`labauto.vision.plate_background.with_radial_rim`);
        0 turns it off.
    faint_factor : float
        Faint colonies (:mod:`labauto.vision.plate_faint`): a smoothed departure from a coarse
        background this many times the agar's own is foreground; 0 turns the pass off.
    faint_min_diameter_mm, faint_max_diameter_mm : float
        Sizes (as discs) of the faint bodies kept.
    drop_at_border : bool
        Drop bodies within 3 px of the usable area's border (cut by it). False (default): a
        colony at the meniscus is found and counted; picking keeps its own distance from the
        rim (``picking.min_rim_distance_px``).
    reject_ink : bool
        Drop bodies of black or blue ink (labels; see :mod:`labauto.vision.plate_ink`).
        Turn off for plates whose colonies are dark grey or blue.
    detector : DetectorParams
        Parameters passed to the generic detector when ``method == "detector"``.
    """

    region: Circle | Polygon | None = None
    detect_dish: bool = True
    dish_radius_range: tuple[float, float] = (0.30, 0.50)
    dish_diameter_mm: float = 90.0
    px_per_mm: float | None = None
    analysis_px_per_mm: float = 12.0
    rim_margin_mm: float = 0.5
    rim_margin_px: float | None = None
    method: str = "segmentation"
    color_threshold: float = 600.0
    noise_factor: float = 0.0
    low_ratio: float = 1.0
    open_mm: float = 0.75
    channel_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)
    background_cell_mm: float = 0.8
    background_scale: int | None = None
    min_colony_diameter_mm: float = 0.3
    max_colony_diameter_mm: float = 27.0
    min_colony_area_px: float | None = None
    max_colony_area_px: float | None = None
    min_width_mm: float = 0.15
    min_width_px: float | None = None
    max_elongation: float = 3.5
    max_fill_ratio: float = 5.0
    des_threshold_deg: float = 25.0
    statistic: str = "median"
    max_concavity: float = 0.17
    max_authentic_elongation: float = 1.3
    edge_skip_mm: float = 0.25
    edge_skip_px: float | None = None
    mix_residual: float = 24.0
    mix_fraction: float = 0.06
    valley_ratio: float = 0.9
    reject_ink: bool = True
    drop_at_border: bool = False
    faint_factor: float = 4.0
    faint_min_diameter_mm: float = 2.0
    faint_max_diameter_mm: float = 12.0
    rim_band_mm: float = 4.0
    detector: DetectorParams = field(default_factory=lambda: DetectorParams(method="color"))

    def __post_init__(self) -> None:
        non_negative = (
            "color_threshold",
            "noise_factor",
            "open_mm",
            "analysis_px_per_mm",
            "min_colony_diameter_mm",
            "min_colony_area_px",
            "max_colony_area_px",
            "min_width_mm",
            "min_width_px",
            "max_elongation",
            "des_threshold_deg",
            "mix_residual",
            "edge_skip_mm",
            "rim_band_mm",
            "faint_factor",
        )
        for name in non_negative:
            value = getattr(self, name)
            if value is not None and not value >= 0:
                raise ValueError(f"PlateParams.{name} must be >= 0, got {value!r}")
        for name in ("rim_margin_mm", "rim_margin_px"):
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise ValueError(f"PlateParams.{name} must be a finite number, got {value!r}")
        positive = (
            "dish_diameter_mm",
            "px_per_mm",
            "background_cell_mm",
            "max_colony_diameter_mm",
            "faint_min_diameter_mm",
            "faint_max_diameter_mm",
        )
        for name in positive:
            value = getattr(self, name)
            if value is not None and not (value > 0 and math.isfinite(value)):
                raise ValueError(f"PlateParams.{name} must be a number > 0, got {value!r}")
        if self.min_colony_diameter_mm > self.max_colony_diameter_mm:
            raise ValueError(
                "PlateParams.min_colony_diameter_mm must not exceed max_colony_diameter_mm"
            )
        if not self.max_authentic_elongation >= 1:
            raise ValueError(
                "PlateParams.max_authentic_elongation must be >= 1, got "
                f"{self.max_authentic_elongation!r}"
            )
        if self.faint_min_diameter_mm > self.faint_max_diameter_mm:
            raise ValueError(
                "PlateParams.faint_min_diameter_mm must not exceed faint_max_diameter_mm"
            )
        lo_area, hi_area = self.min_colony_area_px, self.max_colony_area_px
        if lo_area is not None and hi_area is not None and lo_area > hi_area:
            raise ValueError("PlateParams.min_colony_area_px must not exceed max_colony_area_px")
        if self.method not in ("segmentation", "detector"):
            raise ValueError(
                f"PlateParams.method must be 'segmentation' or 'detector', got {self.method!r}"
            )
        if self.statistic not in ("median", "mean"):
            raise ValueError(
                f"PlateParams.statistic must be 'median' or 'mean', got {self.statistic!r}"
            )
        scale = self.background_scale
        if scale is not None and (int(scale) != scale or scale < 1):
            raise ValueError(f"PlateParams.background_scale must be an integer >= 1, got {scale!r}")
        lo, hi = self.dish_radius_range
        if not 0 < lo < hi <= 1:
            raise ValueError(
                f"PlateParams.dish_radius_range must satisfy 0 < lo < hi <= 1, got "
                f"{self.dish_radius_range!r}"
            )
        for name in ("mix_fraction", "valley_ratio", "low_ratio"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(
                    f"PlateParams.{name} must be in [0, 1], got {getattr(self, name)!r}"
                )
        if len(self.channel_weights) != 3 or min(self.channel_weights) < 0:
            raise ValueError(
                f"PlateParams.channel_weights must be 3 weights >= 0, got {self.channel_weights!r}"
            )
        if self.region is not None:
            _check_region(self.region)


def _check_region(region: Any) -> None:
    arr = np.asarray(region, dtype=float)
    if arr.shape == (3,):
        if not arr[2] > 0:
            raise ValueError(f"PlateParams.region circle radius must be > 0, got {arr[2]}")
        return
    if arr.ndim == 2 and arr.shape[1] == 2 and arr.shape[0] >= 3:
        return
    raise ValueError(
        f"PlateParams.region must be a circle (cx, cy, r) or a polygon of >= 3 "
        f"(x, y) vertices, got {region!r}"
    )


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
    rim); ``stage_ms`` is the time taken per stage of :func:`analyze_plate` (``dish``: dish and
    usable area; ``objects``: segmentation, contours and D_alpha; ``measures``: artefact tests
    and waists; ``classes``: mixed-colony test, merged counts and the result). Both are
    diagnostic and not part of the JSON.
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


def _background(
    roi: np.ndarray, usable: np.ndarray, params: PlateParams, rim: Circle | None = None
) -> np.ndarray:
    """The agar's local colour (:func:`labauto.vision.plate_background.local_background`)."""
    cell = int(params.background_scale or 1)
    bg = local_background(roi, usable, cell, params.color_threshold)
    if rim is not None and params.rim_band_mm > 0:
        band = params.rim_band_mm * float(params.px_per_mm or 1.0)
        bg = with_radial_rim(roi, bg, rim, band)
    return bg


def _gradients(dev: np.ndarray, points: np.ndarray) -> np.ndarray:
    """5x5 Sobel gradient of ``dev`` at integer ``points`` (x, y), vectorised."""
    h, w = dev.shape
    xs = np.clip(points[:, 0], 2, w - 3)
    ys = np.clip(points[:, 1], 2, h - 3)
    flat = (ys * w + xs)[:, None] + (_DY5 * w + _DX5)[None, :]
    patch = dev.ravel().take(flat)
    return np.column_stack((patch @ _SOBEL5_X, patch @ _SOBEL5_Y))


# --------------------------------------------------------------------------------------------
# Per-object measures


_GAP = 2  # empty canvas rows between two bodies' crops (the 5x5 filters reach 2 px)


@dataclass
class _Bodies:
    """The objects that passed the moment tests, with their masks on one shared canvas.

    Every body's crop (its bounding box grown by ``_PAD`` on every side) is copied to the
    canvas at column 0 and an even row, below the previous one with ``_GAP`` empty rows
    between them. No canvas row holds two bodies, so one OpenCV call (closing, distance
    transform, dilation, connected components) treats all bodies at once and gives, inside
    every crop, exactly what it gives on the crop alone (the crop's rim of ``_PAD`` px and the
    gap rows are background), and a per-body reduction is a reduction over a range of rows.

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


def _moment_test(contour: np.ndarray, params: PlateParams) -> tuple[str | None, float]:
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


def _measure_bodies(
    contours: list[np.ndarray],
    fg: np.ndarray | None,
    need_concavity: np.ndarray,
    params: PlateParams,
    rejected: dict[str, int],
) -> _Bodies:
    """Artefact tests (module docstring, step 3) and waists of all contours.

    Contours failing a moment test are counted in ``rejected``; the others become bodies.
    A body's mask is its filled contour, restricted to the foreground ``fg`` (so a closed loop
    of pen ink is not taken for a solid body) and closed with a 5x5 disc (so a crack of a pixel
    or two where two species' colours meet at the edge does not read as a waist). Strokes are
    flagged in ``stroke`` (and counted). The concavity (the waist test of step 4) is measured
    only for the contours where ``need_concavity`` is true (``inf`` elsewhere): the caller
    leaves out those that cannot be a DES anyway (centroid outside or D_alpha too large).
    """
    survivors, elongations = [], []
    for k, contour in enumerate(contours):
        reason, elongation = _moment_test(contour, params)
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
        return _Bodies(
            none, none, none, none, none, none, none, canvas_none,
            canvas_none.astype(np.float32), empty, empty, empty.astype(bool), empty, empty,
        )  # fmt: skip
    boxes = np.array([cv2.boundingRect(c) for c in kept], np.intp).reshape(-1, 4)
    left, top = boxes[:, 0] - _PAD, boxes[:, 1] - _PAD
    width, height = boxes[:, 2] + 2 * _PAD, boxes[:, 3] + 2 * _PAD
    slot = (height + _GAP + 1) // 2 * 2  # rows taken on the canvas (even)
    row = np.cumsum(slot) - slot
    n_rows = int(slot.sum())
    row_body = np.repeat(np.arange(len(kept)), slot)
    row_body[np.arange(n_rows) - row[row_body] >= height[row_body]] = -1
    canvas = (n_rows, int(width.max(initial=1)))

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
        mask = cv2.morphologyEx(cv2.min(mask, fg_canvas), cv2.MORPH_CLOSE, _DISC5)
    dt = cv2.distanceTransform(mask, cv2.DIST_L2, 3)
    r_in = np.maximum.reduceat(dt.max(axis=1), row).astype(np.float64)
    area = np.add.reduceat(np.count_nonzero(mask, axis=1), row).astype(np.float64)
    stroke = area > params.max_fill_ratio * math.pi * r_in * r_in
    if stroke.any():
        rejected["stroke"] = rejected.get("stroke", 0) + int(stroke.sum())

    # deepest concavity: largest distance from the hull's outline of a hull pixel not in the
    # body (0 when there is no such pixel)
    concavity = np.full(len(kept), math.inf)
    wanted = need_concavity[index] & ~stroke
    if wanted.any():
        hulls = np.zeros(canvas, np.uint8)
        for i in np.flatnonzero(wanted):
            cv2.fillConvexPoly(hulls, cv2.convexHull(moved[i]), 1)
        pocket = cv2.compare(hulls, mask, cv2.CMP_GT)
        hull_dt = cv2.distanceTransform(hulls, cv2.DIST_L2, 3)
        hull_dt[pocket == 0] = 0.0
        depth = np.maximum.reduceat(hull_dt.max(axis=1), row).astype(np.float64)
        concavity[wanted] = depth[wanted] / np.maximum(r_in[wanted], 1.0)
    return _Bodies(
        index, top, left, height, width, row, row_body, mask, dt, area, r_in, stroke, concavity,
        np.asarray(elongations, float),
    )  # fmt: skip


def _mix_scores(
    roi: np.ndarray, bodies: _Bodies, which: np.ndarray, params: PlateParams
) -> np.ndarray:
    """Mixed-colony score of the bodies where ``which`` is true, all at once (step 4; 0 elsewhere).

    Per body, the inner pixels' B, G, R are fitted by ``c0 + c1 s + c2 s^2`` with ``s`` the
    distance to the boundary over its maximum (least squares, solved for all bodies together);
    the score is the fraction of inner pixels farther than ``mix_residual`` from the fit. Every
    second row and column of the body's crop is used (a speckle of 2 px radius still gives
    samples).
    """
    k = len(bodies.index)
    score = np.zeros(k)
    # inner samples: every second row and column of the crops (crops start at even rows)
    dt = bodies.dt[::2, ::2]
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
        return score
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
    return score


def _merged_counts(bodies: _Bodies, which: np.ndarray, valley_ratio: float) -> np.ndarray:
    """Colonies in each merged body (where ``which`` is true; 1 elsewhere), all at once.

    Step 5: one peak per plateau of the distance transform's local maxima (5x5), above
    ``max(2, 0.3 r_in)``, at its highest pixel (the first in raster order on a tie); peaks are
    taken greedily from the highest (plateaus of equal height in the order OpenCV labels a
    crop: by their first 2x2 block in raster order), and a peak is kept when the straight
    segment to every peak kept before it dips below ``valley_ratio`` times the lower of the
    two. At least ``_MIN_MERGED_COUNT`` (1). The segments between all pairs of peaks of a body
    are sampled at once.
    """
    counts = np.ones(len(bodies.index), np.intp)
    if not which.any():
        return counts
    counts[which] = _MIN_MERGED_COUNT
    # a smaller canvas of only these bodies' slots (the layout's rules still hold)
    slot = np.diff(np.append(bodies.row, len(bodies.row_body)))
    rows = which[np.repeat(np.arange(len(slot)), slot)]
    dt, row_body = bodies.dt[rows], bodies.row_body[rows]
    first_row = np.zeros(len(slot), np.intp)
    first_row[which] = np.cumsum(slot[which]) - slot[which]
    floor = np.maximum(2.0, 0.3 * bodies.r_in)
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
        counts[body[lo]] = max(_MIN_MERGED_COUNT, len(kept))
    return counts


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
        # a margin of _PAD px all round, so that bodies touching the usable area's border
        # (colonies at the meniscus) still have whole crops
        roi = cv2.copyMakeBorder(roi, _PAD, _PAD, _PAD, _PAD, cv2.BORDER_REPLICATE)
        usable = cv2.copyMakeBorder(usable, _PAD, _PAD, _PAD, _PAD, cv2.BORDER_CONSTANT, value=0)
        x0, y0 = x0 - _PAD, y0 - _PAD
        if rim is not None:
            rim = (rim[0] + _PAD, rim[1] + _PAD, rim[2])
    stage_done("dish")

    background = _background(roi, usable, params, rim)
    if params.method == "detector":
        objects = _objects_by_detector(roi, usable, params)
    else:
        objects = _objects_by_segmentation(roi, usable, params, background)
    contours, d_alpha, inside, centroids, rejected, fg = objects
    stage_done("objects")

    # a DES needs its centroid inside and a small D_alpha; only then does the waist matter
    des_shape = np.asarray(inside, bool) & (np.asarray(d_alpha) < params.des_threshold_deg)
    bodies = _measure_bodies(contours, fg, des_shape, params, rejected)
    if params.reject_ink:
        ink = ink_bodies(roi, background, bodies, ~bodies.stroke, float(params.px_per_mm or 0.0))
        if ink.any():
            rejected["ink"] = int(ink.sum())
            bodies.stroke |= ink
    des = des_shape[bodies.index] & (bodies.concavity < params.max_concavity) & ~bodies.stroke
    des &= bodies.elongation <= params.max_authentic_elongation
    stage_done("measures")
    # every body is counted: a DES holding two peaks apart (two colonies that meet in a shallow
    # waist) is merged, never offered for picking
    counts = _merged_counts(bodies, ~bodies.stroke, params.valley_ratio)
    des &= counts == 1
    mix = _mix_scores(roi, bodies, des, params)

    colonies: list[Colony] = []
    for b, k in enumerate(bodies.index.tolist()):
        if bodies.stroke[b]:
            continue
        klass = "merged"
        if des[b]:
            klass = "mixed" if mix[b] >= params.mix_fraction else "authentic"
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
    """True for every contour with a point within ``_PAD`` px of the usable area's outline.

    The usable mask is eroded by a square of ``2 * _PAD + 1`` (one full-size pass) and read
    only at the contours' points, all at once.
    """
    if not contours:
        return np.zeros(0, bool)
    kernel = np.ones((2 * _PAD + 1, 2 * _PAD + 1), np.uint8)
    inner = cv2.erode(usable, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    points = np.concatenate(contours).reshape(-1, 2)
    starts = np.cumsum([0] + [len(c) for c in contours[:-1]])
    return np.logical_or.reduceat(inner[points[:, 1], points[:, 0]] == 0, starts)


def _objects_by_segmentation(
    roi: np.ndarray, usable: np.ndarray, params: PlateParams, background: np.ndarray
) -> _Objects:
    """Contours of eq. 1's objects with D_alpha, centroid-inside and centroid (ROI pixels)."""
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
        )
        fg = cv2.bitwise_or(fg, faint)
    if params.open_mm > 0:
        # lines thinner than open_mm (the lid's and the wall's edges, scratches, hairs) go, so
        # colonies touching them come apart from them
        k = 2 * math.floor(params.open_mm * float(params.px_per_mm or 0.0) / 2) + 1  # odd
        if k >= 3:
            fg = open_thin_lines(fg, k)
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
