"""The dish and the usable area of a plate (plate analysis, step 1).

The dish is found (:func:`labauto.vision.dish.find_dish`) or configured (``PlateParams.region``:
a circle or a polygon), the image's scale read from it, the working copy made
(:mod:`labauto.vision.plate_scale`), and the usable area drawn: the dish shrunk by the rim
margin, or the configured polygon as it is (:mod:`labauto.vision.plate` gives the rules).
"""

from __future__ import annotations

import cv2
import numpy as np

from labauto.vision.dish import Dish, find_dish
from labauto.vision.plate_params import Circle, PlateParams
from labauto.vision.plate_scale import WorkingCopy, image_scale, pixel_params, working_copy

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
