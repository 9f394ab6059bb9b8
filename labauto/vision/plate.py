"""Plate analysis: from a petri-dish image to colonies worth picking (Teutsch et al., 4.1).

``analyze_plate(image)`` finds the dish, segments every object on the agar without knowing the
agar's colour, drops artefacts, and sorts the rest into authentic colonies (a deformed elliptic
shape, DES), merged colonies (touching colonies, not a DES) and mixed colonies (a DES holding two
species). Pure functions on arrays: no I/O.

Pipeline and the choices it makes where the paper or the brief leave room:

1. **Dish.** Hough circle on a grey image subsampled to ~128 px, refined at full resolution:
   along 180 rays the agar's edge is where the colour first departs from the agar's by more than
   18 grey levels (meniscus or wall), taken at half that first peak's height (sub-pixel), and a
   least-squares circle is fitted to those points, dropping outliers in three rounds (labels,
   pen marks and colonies near the wall). The dish radius reads 0.2-2.3 px short of the drawn
   agar edge on the synthetic plates (the dark meniscus ring starts inside it). The usable area
   is the dish shrunk by ``rim_margin_px``, or a configured circle (``PlateParams.region``, also
   shrunk) or polygon (used as is). Objects within 3 px of the usable area's border are ignored
   (a colony cut by the rim margin cannot be picked).
2. **Objects** (paper eq. 1, with no knowledge of the agar's colour). The background mean is
   estimated from the dish itself, locally: on the dish subsampled by ``background_scale``, a
   5x5 median gives a first estimate, pixels that deviate from it are masked out, and a
   normalised Gaussian convolution of the remaining agar gives the background, resized back
   (so a lighting gradient does not matter). A pixel is foreground when its summed squared
   deviation from the background over B, G, R (optionally weighted) exceeds
   ``color_threshold``; contours are traced in the 8-neighbourhood (OpenCV). The gradient at
   each contour point is a 5x5 Sobel of that deviation image: it points into every object,
   whatever its colour. D_alpha, the centroid and the centroid-inside test come from V1's
   :func:`labauto.vision.shape_angle.shape_angles`, vectorised over all contours.
   ``method="detector"`` uses V1's :func:`labauto.vision.detector.detect` instead (slower).
3. **Artefacts** are dropped, in this order: ``area < min_colony_area_px`` (dust) or
   ``> max_colony_area_px``; mean width ``2 * area / perimeter < min_width_px`` (scratches, thin
   pen strokes: a disc of radius r gives r, a strip of width w gives w); elongation
   ``sqrt(l1 / l2)`` of the second moments above ``max_elongation`` (glare streaks, straight
   strokes; the paper's DES limit is about 1:4); area above ``max_fill_ratio`` times the largest
   inscribed disc (curved or closed pen writing). The body's mask is its filled contour
   restricted to the foreground (a loop of ink is not solid) and closed with a 5x5 disc.
4. **Classes.** Authentic: a DES, i.e. centroid inside and D_alpha (median by default) below
   ``des_threshold_deg``, and no waist: the deepest concavity (distance from the convex hull)
   is below ``max_concavity`` times the inscribed radius. D_alpha alone does not separate a
   merged pair of unequal colonies (they read 14-46 degrees, single colonies 2-21), the waist
   does (measured: singles <= 0.12, merged >= 0.22). Merged: every other object. Mixed: a DES
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
   (a waist). At least 2. Compact clumps of three whose members overlap deeply are the usual
   miss (counted 2).

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from labauto.vision.detector import DetectorParams, detect
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
_SOBEL5_SMOOTH = np.array([1.0, 4.0, 6.0, 4.0, 1.0], np.float32)
_SOBEL5_DERIV = np.array([-1.0, -2.0, 0.0, 2.0, 1.0], np.float32)
_SOBEL5_X = np.outer(_SOBEL5_SMOOTH, _SOBEL5_DERIV).ravel()  # rows: dy, cols: dx
_SOBEL5_Y = np.outer(_SOBEL5_DERIV, _SOBEL5_SMOOTH).ravel()
_DY5, _DX5 = (g.ravel() for g in np.mgrid[-2:3, -2:3])
_PAD = 3  # margin (px) around a body's mask; bodies this close to the usable border are dropped
_DISC5 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
_DISH_EDGE_CONTRAST = 18.0  # colour distance (grey levels) from the agar that marks its edge


@dataclass(frozen=True)
class PlateParams:
    """Tunables of :func:`analyze_plate` (defaults for ~10 px/mm colour images of a 90 mm dish).

    Attributes
    ----------
    region : tuple or None
        Usable area, skipping dish detection: a circle ``(cx, cy, r)`` (the rim margin is then
        still taken off) or a polygon ``((x, y), ...)`` of at least 3 vertices (used as is).
    detect_dish : bool
        Find the dish when ``region`` is None; if False the whole image is the usable area.
    dish_radius_range : tuple of float
        Dish radius searched, as fractions of ``min(height, width)``.
    rim_margin_px : float
        Width of the band inside the dish edge that is ignored (wall, labels, pen marks).
    method : str
        ``"segmentation"`` (eq. 1 with a local background, default) or ``"detector"`` (V1's
        :func:`labauto.vision.detector.detect` on the dish with ``detector`` params).
    color_threshold : float
        ``t`` of eq. 1: summed squared deviation from the background (grey levels squared).
    channel_weights : tuple of float
        Weights of the B, G, R squared deviations in eq. 1.
    background_scale : int
        Subsampling factor of the background estimate (its detail is ~4x this in pixels).
    min_colony_area_px, max_colony_area_px : float
        Objects outside this area range are artefacts (dust) or not colonies.
    min_width_px : float
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
    edge_skip_px : float
        Pixels this close to a colony's boundary are left out of the mixed-colony test.
    mix_residual : float
        Colour distance (grey levels) from the one-species dome fit that makes a pixel an outlier.
    mix_fraction : float
        Least fraction of outlier pixels that makes a DES a mixed colony.
    valley_ratio : float
        Distance-transform dip between two peaks, relative to the lower peak, that separates two
        colonies of a merged body.
    detector : DetectorParams
        Parameters passed to V1's detector when ``method == "detector"``.
    """

    region: Circle | Polygon | None = None
    detect_dish: bool = True
    dish_radius_range: tuple[float, float] = (0.30, 0.50)
    rim_margin_px: float = 25.0
    method: str = "segmentation"
    color_threshold: float = 600.0
    channel_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)
    background_scale: int = 8
    min_colony_area_px: float = 60.0
    max_colony_area_px: float = 60000.0
    min_width_px: float = 5.0
    max_elongation: float = 3.5
    max_fill_ratio: float = 5.0
    des_threshold_deg: float = 25.0
    statistic: str = "median"
    max_concavity: float = 0.17
    edge_skip_px: float = 2.5
    mix_residual: float = 24.0
    mix_fraction: float = 0.06
    valley_ratio: float = 0.9
    detector: DetectorParams = field(default_factory=lambda: DetectorParams(method="color"))

    def __post_init__(self) -> None:
        positive = (
            "rim_margin_px",
            "color_threshold",
            "min_colony_area_px",
            "max_colony_area_px",
            "min_width_px",
            "max_elongation",
            "des_threshold_deg",
            "mix_residual",
        )
        for name in positive:
            if not getattr(self, name) >= 0:
                raise ValueError(f"PlateParams.{name} must be >= 0, got {getattr(self, name)!r}")
        if self.min_colony_area_px > self.max_colony_area_px:
            raise ValueError("PlateParams.min_colony_area_px must not exceed max_colony_area_px")
        if self.method not in ("segmentation", "detector"):
            raise ValueError(
                f"PlateParams.method must be 'segmentation' or 'detector', got {self.method!r}"
            )
        if self.statistic not in ("median", "mean"):
            raise ValueError(
                f"PlateParams.statistic must be 'median' or 'mean', got {self.statistic!r}"
            )
        if int(self.background_scale) != self.background_scale or self.background_scale < 1:
            raise ValueError(
                f"PlateParams.background_scale must be an integer >= 1, got "
                f"{self.background_scale!r}"
            )
        lo, hi = self.dish_radius_range
        if not 0 < lo < hi <= 1:
            raise ValueError(
                f"PlateParams.dish_radius_range must satisfy 0 < lo < hi <= 1, got "
                f"{self.dish_radius_range!r}"
            )
        for name in ("mix_fraction", "valley_ratio"):
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
        Colonies in the body (1 for authentic and mixed).
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

    ``rejected`` counts the objects dropped per reason (dust, large, thin, elongated, rim); it is
    diagnostic and not part of the JSON.
    """

    width: int
    height: int
    timing_ms: float
    dish: Dish
    colonies: list[Colony]
    rejected: dict[str, int] = field(default_factory=dict)

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


# --------------------------------------------------------------------------------------------
# Input


def _as_bgr(image: Any) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise ValueError(f"image must be a numpy array, got {type(image).__name__}")
    if image.size == 0:
        raise ValueError(f"image is empty (shape {image.shape})")
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3 or image.shape[2] not in (1, 3, 4):
        raise ValueError(f"image must be HxW, HxWx3 (BGR) or HxWx4, got shape {image.shape}")
    if min(image.shape[:2]) < 64:
        raise ValueError(f"image must be at least 64x64 pixels, got shape {image.shape}")
    if image.dtype != np.uint8:
        if image.dtype.kind not in "uif" or image.dtype == np.bool_:
            raise ValueError(f"image dtype must be uint8 or a real number type, got {image.dtype}")
        if image.dtype.kind == "f" and not np.all(np.isfinite(image)):
            raise ValueError("image holds NaN or infinite values")
        image = np.clip(image, 0, 255).astype(np.uint8)
    if image.shape[2] == 1:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    elif image.shape[2] == 4:
        image = np.ascontiguousarray(image[..., :3])
    return np.ascontiguousarray(image)


# --------------------------------------------------------------------------------------------
# Dish


def find_dish(image: np.ndarray, radius_range: tuple[float, float] = (0.30, 0.50)) -> Dish:
    """Find the petri dish: the agar disc inside the wall.

    A Hough circle on a grey image subsampled to ~128 px gives a first guess. Along rays at full
    resolution the agar's edge is the first place, going outward, where the colour departs from
    the agar's by more than 18 grey levels (the meniscus or the wall); it is located at half the
    height of that first peak, with sub-pixel interpolation. A least-squares circle is fitted to
    the edge points of all rays (+-40 px around the first guess), dropping outliers (labels, pen
    marks, colonies near the wall) in three rounds.

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
    img = _as_bgr(image)
    h, w = img.shape[:2]
    step = max(1, min(h, w) // 128)
    small = cv2.resize(img, (w // step, h // step), interpolation=cv2.INTER_NEAREST)
    small = cv2.GaussianBlur(cv2.cvtColor(small, cv2.COLOR_BGR2GRAY), (5, 5), 1.0)
    r_min = radius_range[0] * min(h, w) / step
    r_max = radius_range[1] * min(h, w) / step
    circles = cv2.HoughCircles(
        small,
        cv2.HOUGH_GRADIENT,
        dp=1,
        minDist=max(small.shape),
        param1=60,
        param2=15,
        minRadius=int(r_min),
        maxRadius=math.ceil(r_max),
    )
    if circles is None:
        raise ValueError("no petri dish found in the image; set PlateParams.region to the dish")
    cx, cy, r = (float(v) * step for v in circles[0, 0])
    cx, cy, r = _refine_dish(img, cx, cy, r, n_rays=180, reach=40.0, step=1.0)
    return Dish((cx, cy), r)


def _refine_dish(
    img: np.ndarray, cx: float, cy: float, r: float, n_rays: int, reach: float, step: float
) -> tuple[float, float, float]:
    """Refine a dish circle on the agar's edge along rays (see :func:`find_dish`)."""
    theta = np.linspace(0.0, 2 * np.pi, n_rays, endpoint=False, dtype=np.float32)
    radii = np.arange(r - reach, r + reach + step / 2, step, dtype=np.float32)
    map_x = (cx + np.cos(theta)[:, None] * radii[None, :]).astype(np.float32)
    map_y = (cy + np.sin(theta)[:, None] * radii[None, :]).astype(np.float32)
    prof = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    prof = prof.astype(np.float32)
    n_ref = max(round(4.0 / step), 2)
    ref = prof[:, :n_ref].mean(axis=1)  # agar colour at the inner end of every ray
    diff = prof - ref[:, None, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    rows = np.arange(n_rays)
    first = np.argmax(dist >= _DISH_EDGE_CONTRAST, axis=1)
    ok = (dist[rows, first] >= _DISH_EDGE_CONTRAST) & (first > 0)
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


def _fit_circle(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Algebraic (Kasa) least-squares circle through points."""
    a = np.column_stack((x, y, np.ones_like(x)))
    b = x * x + y * y
    (p, q, s), *_ = np.linalg.lstsq(a, b, rcond=None)
    cx, cy = p / 2, q / 2
    return float(cx), float(cy), float(math.sqrt(max(s + cx * cx + cy * cy, 0.0)))


def _usable_area(
    img: np.ndarray, params: PlateParams
) -> tuple[Dish, tuple[int, int, int, int], np.ndarray]:
    """Return the dish, the ROI ``(x0, y0, x1, y1)`` and the usable mask (uint8 0/255) in it."""
    h, w = img.shape[:2]
    region = params.region
    if region is not None and np.asarray(region, dtype=float).shape != (3,):
        poly = np.asarray(region, dtype=np.float64)
        (ccx, ccy), cr = cv2.minEnclosingCircle(poly.astype(np.float32))
        dish = Dish((float(ccx), float(ccy)), float(cr))
        x0, y0 = max(int(np.floor(poly[:, 0].min())), 0), max(int(np.floor(poly[:, 1].min())), 0)
        x1 = min(int(np.ceil(poly[:, 0].max())) + 1, w)
        y1 = min(int(np.ceil(poly[:, 1].max())) + 1, h)
        mask = np.zeros((max(y1 - y0, 0), max(x1 - x0, 0)), np.uint8)
        cv2.fillPoly(mask, [np.round(poly - [x0, y0]).astype(np.int32)], 255)
    else:
        if region is not None:
            dish = Dish((float(region[0]), float(region[1])), float(region[2]))
        elif params.detect_dish:
            dish = find_dish(img, params.dish_radius_range)
        else:
            dish = Dish(((w - 1) / 2, (h - 1) / 2), min(h, w) / 2)
        cx, cy = dish.center
        ru = dish.radius - (params.rim_margin_px if params.detect_dish or region else 0.0)
        if ru <= 2:
            raise ValueError(
                f"usable dish radius {ru:.1f} px is too small (dish radius "
                f"{dish.radius:.1f}, rim_margin_px {params.rim_margin_px})"
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
        if not params.detect_dish and region is None:
            mask[:] = 255
    if mask.size == 0 or not mask.any():
        raise ValueError("the usable area of the plate lies outside the image")
    return dish, (x0, y0, x1, y1), mask


# --------------------------------------------------------------------------------------------
# Segmentation (eq. 1 with a local background)


def _deviation(roi: np.ndarray, usable: np.ndarray, params: PlateParams) -> np.ndarray:
    """Summed squared colour deviation from the local background (float32, ROI-sized)."""
    h, w = usable.shape
    s = int(params.background_scale)
    small = np.ascontiguousarray(roi[::s, ::s])
    valid = usable[::s, ::s] == 255
    med = cv2.medianBlur(small, 5)
    diff = small.astype(np.float32) - med
    outlier = (diff * diff).sum(axis=2) > params.color_threshold * 0.5
    outlier = cv2.dilate(outlier.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    weight = (valid & ~outlier).astype(np.float32)
    if weight.sum() < 4:
        weight = valid.astype(np.float32)
    if weight.sum() < 1:
        weight = np.ones_like(weight)
    num = cv2.GaussianBlur(small.astype(np.float32) * weight[..., None], (0, 0), 2.0)
    den = cv2.GaussianBlur(weight, (0, 0), 2.0)
    far = den <= 0.05  # no agar nearby: use the dish's mean agar colour
    bg_small = num / np.maximum(den, 0.05)[..., None]
    if far.any():
        bg_small[far] = small[weight > 0].mean(axis=0)
    bg_small = cv2.convertScaleAbs(bg_small)
    # back to full size (a shift of (s - 1) / 2 px of this smooth field does not matter)
    sh, sw = bg_small.shape[:2]
    bg = cv2.resize(bg_small, (sw * s, sh * s), interpolation=cv2.INTER_LINEAR)[:h, :w]
    sq = cv2.LUT(cv2.absdiff(roi, bg), _SQUARES)
    weights = np.asarray(params.channel_weights, np.float32).reshape(1, 3)
    return cv2.transform(sq, weights)


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


@dataclass
class _Body:
    """An object that passed the artefact tests, with what classification needs."""

    index: int
    bbox: tuple[int, int, int, int]
    mask: np.ndarray
    dt: np.ndarray
    area: float
    concavity: float


def _measure(
    contour: np.ndarray, index: int, fg: np.ndarray | None, params: PlateParams
) -> _Body | str:
    """Artefact tests of one contour (module docstring, step 3): a body or a reject reason.

    The body's mask is the filled contour, restricted to the foreground ``fg`` (so a closed
    loop of pen ink is not taken for a solid body) and closed with a 5x5 disc (so a crack of a
    pixel or two where two species' colours meet at the edge does not read as a waist).
    """
    m = cv2.moments(contour)
    area = m["m00"] + len(contour) / 2.0 + 1.0  # polygon through pixel centres + half-pixel rim
    if area < params.min_colony_area_px:
        return "dust"
    if area > params.max_colony_area_px:
        return "large"
    if 2.0 * area / max(cv2.arcLength(contour, True), 1.0) < params.min_width_px:
        return "thin"
    mu20, mu02, mu11 = m["mu20"], m["mu02"], m["mu11"]
    half_trace = (mu20 + mu02) / 2.0
    spread = math.sqrt(((mu20 - mu02) / 2.0) ** 2 + mu11 * mu11)
    if half_trace + spread > params.max_elongation**2 * max(half_trace - spread, 1e-9):
        return "elongated"
    x, y, bw, bh = bbox = cv2.boundingRect(contour)
    shift = np.array([x - _PAD, y - _PAD], np.int32)
    mask = np.zeros((bh + 2 * _PAD, bw + 2 * _PAD), np.uint8)
    cv2.drawContours(mask, [contour - shift], -1, 1, -1)
    if fg is not None:
        mask &= fg[y - _PAD : y + bh + _PAD, x - _PAD : x + bw + _PAD] > 0
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _DISC5)
    dt = cv2.distanceTransform(mask, cv2.DIST_L2, 3)
    r_in = float(dt.max())
    pixel_area = float(np.count_nonzero(mask))
    if pixel_area > params.max_fill_ratio * math.pi * r_in * r_in:
        return "stroke"
    # deepest concavity: largest distance from the hull's outline of a hull pixel not in the body
    hull_mask = np.zeros_like(mask)
    cv2.fillConvexPoly(hull_mask, cv2.convexHull(contour) - shift, 1)
    pocket = hull_mask > mask
    depth = 0.0
    if pocket.any():
        depth = float(cv2.distanceTransform(hull_mask, cv2.DIST_L2, 3)[pocket].max())
    return _Body(index, bbox, mask, dt, pixel_area, depth / max(r_in, 1.0))


def _mix_scores(roi: np.ndarray, bodies: list[_Body], params: PlateParams) -> np.ndarray:
    """Mixed-colony score of every body at once (module docstring, step 4).

    Per body, the inner pixels' B, G, R are fitted by ``c0 + c1 s + c2 s^2`` with ``s`` the
    distance to the boundary over its maximum (least squares, solved for all bodies together);
    the score is the fraction of inner pixels farther than ``mix_residual`` from the fit. Every
    second row and column is used (a speckle of 2 px radius still gives samples).
    """
    colours, depths = [], []
    for body in bodies:
        x, y, bw, bh = body.bbox
        dt = body.dt[::2, ::2]
        inner = dt >= params.edge_skip_px
        colours.append(roi[y - _PAD : y + bh + _PAD : 2, x - _PAD : x + bw + _PAD : 2][inner])
        depths.append(dt[inner] * np.float32(1.0 / max(float(body.dt.max()), 1e-6)))
    sizes = np.array([len(d) for d in depths])
    k = len(bodies)
    if sizes.sum() == 0:
        return np.zeros(k)
    label = np.repeat(np.arange(k), sizes)
    c = np.concatenate(colours).astype(np.float32)
    s = np.concatenate(depths)
    s2 = s * s
    feats = (np.ones_like(s), s, s2, s2 * s, s2 * s2)
    sums = np.stack([np.bincount(label, f, minlength=k) for f in feats], axis=1)  # (k, 5)
    gram = np.stack([sums[:, i : i + 3] for i in range(3)], axis=1) + np.eye(3) * 1e-6
    rhs = np.empty((k, 3, 3))
    for i in range(3):
        for ch in range(3):
            rhs[:, i, ch] = np.bincount(label, feats[i] * c[:, ch], minlength=k)
    coef = np.repeat(np.linalg.solve(gram, rhs).astype(np.float32), sizes, axis=0)
    resid = c - (coef[:, 0] + s[:, None] * coef[:, 1] + s2[:, None] * coef[:, 2])
    off = np.einsum("ij,ij->i", resid, resid) > params.mix_residual**2
    score = np.bincount(label, off, minlength=k) / np.maximum(sizes, 1)
    score[sizes < 8] = 0.0  # too few inner samples to judge
    return score


def _merged_count(dt: np.ndarray, valley_ratio: float) -> int:
    """Colonies in a merged body from the peaks of its distance transform (at least 2)."""
    peak_max = float(dt.max())
    dil = cv2.dilate(dt, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    cand = ((dt >= dil) & (dt >= max(2.0, 0.3 * peak_max))).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(cand, connectivity=8)
    peaks = []
    for i in range(1, n):  # one peak per plateau, at its highest pixel
        x, y, bw, bh = stats[i, :4]
        sub = np.where(labels[y : y + bh, x : x + bw] == i, dt[y : y + bh, x : x + bw], -1.0)
        j = int(np.argmax(sub))
        peaks.append((x + j % bw, y + j // bw, float(sub.flat[j])))
    peaks.sort(key=lambda p: -p[2])
    kept: list[tuple[int, int, float]] = []
    for px, py, pv in peaks:
        separate = True
        for qx, qy, qv in kept:
            m = int(math.hypot(px - qx, py - qy)) + 2
            lx = np.linspace(px, qx, m).round().astype(np.intp)
            ly = np.linspace(py, qy, m).round().astype(np.intp)
            if dt[ly, lx].min() >= valley_ratio * min(pv, qv):
                separate = False
                break
        if separate:
            kept.append((px, py, pv))
    return max(2, len(kept))


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
    img = _as_bgr(image)
    h, w = img.shape[:2]
    dish, (x0, y0, _, _), usable = _usable_area(img, params)
    roi = img[y0 : y0 + usable.shape[0], x0 : x0 + usable.shape[1]]

    if params.method == "detector":
        objects = _objects_by_detector(roi, usable, params)
    else:
        objects = _objects_by_segmentation(roi, usable, params)
    contours, d_alpha, inside, centroids, rejected, fg = objects

    bodies: list[_Body] = []
    for k, contour in enumerate(contours):
        body = _measure(contour, k, fg, params)
        if isinstance(body, str):
            rejected[body] = rejected.get(body, 0) + 1
        else:
            bodies.append(body)
    des = [
        bool(inside[b.index])
        and d_alpha[b.index] < params.des_threshold_deg
        and b.concavity < params.max_concavity
        for b in bodies
    ]
    mix = np.zeros(len(bodies))
    des_idx = [i for i, d in enumerate(des) if d]
    if des_idx:
        mix[des_idx] = _mix_scores(roi, [bodies[i] for i in des_idx], params)

    colonies: list[Colony] = []
    for body, is_des, score in zip(bodies, des, mix, strict=True):
        if is_des:
            klass = "mixed" if score >= params.mix_fraction else "authentic"
            count = 1
        else:
            klass, count = "merged", _merged_count(body.dt, params.valley_ratio)
        k = body.index
        colonies.append(
            Colony(
                id=len(colonies),
                centroid=(float(centroids[k][0] + x0), float(centroids[k][1] + y0)),
                klass=klass,
                area_px=body.area,
                d_alpha_median=float(d_alpha[k]),
                estimated_count=count,
                contour=contours[k].reshape(-1, 2).astype(float) + np.array([x0, y0]),
                mix_score=float(score),
            )
        )
    timing = (time.perf_counter() - t0) * 1000.0
    return PlateResult(
        width=w, height=h, timing_ms=timing, dish=dish, colonies=colonies, rejected=rejected
    )


# contours, D_alpha, centroid inside, centroids (ROI pixels), reject counts, foreground or None
_Objects = tuple[
    list[np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, int], np.ndarray | None
]


def _border(usable: np.ndarray, width: int) -> np.ndarray:
    """True on pixels within ``width`` px of the usable area's outline (or outside it)."""
    kernel = np.ones((2 * width + 1, 2 * width + 1), np.uint8)
    return cv2.erode(usable, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) == 0


def _objects_by_segmentation(roi: np.ndarray, usable: np.ndarray, params: PlateParams) -> _Objects:
    """Contours of eq. 1's objects with D_alpha, centroid-inside and centroid (ROI pixels)."""
    dev = _deviation(roi, usable, params)
    fg = cv2.bitwise_and(cv2.compare(dev, params.color_threshold, cv2.CMP_GT), usable)
    found, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    border = _border(usable, _PAD)
    rejected = {"dust": 0, "rim": 0}
    min_points = max(4, int(2.0 * math.sqrt(params.min_colony_area_px)))
    kept = []
    for c in found:
        if len(c) < min_points:
            rejected["dust"] += 1
        elif border[c[:, 0, 1], c[:, 0, 0]].any():
            rejected["rim"] += 1
        else:
            kept.append(c)
    if not kept:
        return [], np.zeros(0), np.zeros(0, bool), np.zeros((0, 2)), rejected, fg
    offsets = np.concatenate(([0], np.cumsum([len(c) for c in kept])))
    points = np.concatenate(kept).reshape(-1, 2)
    grads = _gradients(dev, points)
    sa = shape_angles(
        points.astype(np.float64), grads.astype(np.float64), offsets, np.ones(len(kept), bool)
    )
    return kept, sa.statistic(params.statistic), sa.centroid_inside, sa.centroid, rejected, fg


def _objects_by_detector(roi: np.ndarray, usable: np.ndarray, params: PlateParams) -> _Objects:
    """Objects of V1's detector on the dish, the area outside the usable one painted agar."""
    agar = np.median(roi[usable > 0], axis=0).astype(np.uint8)
    painted = roi.copy()
    painted[usable == 0] = agar
    result = detect(painted, params.detector)
    border = _border(usable, _PAD)
    h, w = usable.shape
    contours, d_alpha, inside, centroids = [], [], [], []
    rejected = {"open": 0, "rim": 0}
    for obj in result.objects:
        if not obj.closed:
            rejected["open"] += 1
            continue
        pts = np.round(np.asarray(obj.points, dtype=float)).astype(np.int32)
        pts[:, 0] = np.clip(pts[:, 0], 0, w - 1)
        pts[:, 1] = np.clip(pts[:, 1], 0, h - 1)
        if border[pts[:, 1], pts[:, 0]].any():
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
