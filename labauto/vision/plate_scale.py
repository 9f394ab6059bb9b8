"""The physical scale of a plate image, and the resampled copy plate analysis works on.

Plate analysis sizes everything in millimetres (``PlateParams``). This module turns them into
pixels of one image:

* **Scale.** ``px_per_mm`` when a camera calibration gives it; otherwise the dish found in the
  image (or the configured region's circle) is ``dish_diameter_mm`` across. With
  ``detect_dish=False`` and no region, the image's shorter side is taken for the dish.
* **Working copy.** An image finer than ``analysis_px_per_mm`` is analysed on a copy of the dish's
  bounding box resampled to that scale by area averaging (``cv2.INTER_AREA``): a 16-Mpixel photo
  and a 1.3-Mpixel camera frame of the same plate then see the same pixels per colony, the same
  noise after averaging, and take about the same time. An image coarser than
  ``min_analysis_px_per_mm`` (a webcam frame) is resampled up to ``analysis_px_per_mm`` (bilinear):
  it brings no detail, but the analysis's small fixed kernels (5x5 Sobel and closing, the distance
  transform's peaks) then span the lengths they were chosen for. Measured on the AGAR photographs
  resampled so that the dish is at 7 and 4.5 px/mm (``benchmarks/bench_real_plates.py
  --camera-scale``): F1 0.804 -> 0.814 and 0.684 -> 0.749 (native: 0.851), colonies offered for
  picking at 7 px/mm 429 -> 844 (native 879), at 4.5 px/mm those holding no boxed colony 58 -> 15;
  phone-counts' median count error 8.0 -> 6.1 % at 7 px/mm, 5.7 -> 6.2 % at 4.5 px/mm. Upsampling
  only to 10 px/mm was worse (F1 0.793, 0.725). Images between the two scales are used as they are.
  A coarser ``analysis_px_per_mm`` would buy time (a 1.3-Mpixel plate's pixels fall with its
  square) but costs colonies: 10 and 8 px/mm (``min_analysis_px_per_mm`` 6.7 and 5.3) gave AGAR
  F1 0.905 and 0.880 (0.910 at 12), median count error 8.3 and 9.6 % (5.7 %), phone-counts 3.0
  and 5.5 % (1.9 %) (2026-12-07, ninth session).
  A coarse frame's dust is a blur of a pixel or two that the resampling widens past the
  opening: 24 generated plates (seeds 1000-1023, six agars) resampled to 7 and 4.5 px/mm show
  20 and 28 false colonies, all dust specks (1 at their own scale). A least colony of 2-3 pixels
  of the original frame, besides ``min_colony_diameter_mm``, was tried and not kept: with 2.5 px
  17 and 7 false there, but on the AGAR photographs at 7 and 4.5 px/mm matched 1616 -> 1612 and
  1591 -> 1581 for reported 1716 -> 1711 and 1712 -> 1696: real specks that small are colonies
  about as often as not (2026-12-07, eighth session).
  Positions map back by the pixel-centre rule ``u = (u' + 0.5) / f - 0.5`` (origin at the centre of
  the top-left pixel), areas by ``1 / f**2``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import cv2
import numpy as np

if TYPE_CHECKING:
    from labauto.vision.plate_params import PlateParams


@dataclass(frozen=True)
class WorkingCopy:
    """A plate image resampled for analysis.

    Attributes
    ----------
    image : ndarray
        The crop ``[y0:y1, x0:x1]`` of the original image, resized by ``factor``.
    origin : tuple of int
        ``(x0, y0)`` of the crop in the original image.
    factor : float
        Working pixels per original pixel (> 1 for an upsampled webcam frame).
    px_per_mm : float
        Working pixels per millimetre.
    """

    image: np.ndarray
    origin: tuple[int, int]
    factor: float
    px_per_mm: float

    def to_original(self, points: np.ndarray) -> np.ndarray:
        """Map working ``(x, y)`` points (any shape ending in 2) to original image pixels."""
        pts = np.asarray(points, dtype=np.float64)
        return (pts + 0.5) / self.factor - 0.5 + np.asarray(self.origin, np.float64)

    def to_working(self, points: np.ndarray) -> np.ndarray:
        """Map original ``(x, y)`` points to working pixels."""
        pts = np.asarray(points, dtype=np.float64) - np.asarray(self.origin, np.float64)
        return (pts + 0.5) * self.factor - 0.5


def image_scale(radius_px: float, params: PlateParams) -> float:
    """Pixels per millimetre of the original image (module docstring)."""
    if params.px_per_mm is not None:
        return float(params.px_per_mm)
    return 2.0 * float(radius_px) / params.dish_diameter_mm


def working_copy(
    image: np.ndarray, bounds: tuple[float, float, float, float], px_per_mm: float,
    params: PlateParams,
) -> WorkingCopy:  # fmt: skip
    """Crop ``bounds`` (x0, y0, x1, y1, original pixels) and resample to the analysis scale."""
    h, w = image.shape[:2]
    factor = 1.0
    target = params.analysis_px_per_mm
    if target > 0 and (px_per_mm > target or px_per_mm < params.min_analysis_px_per_mm):
        factor = target / px_per_mm
    x0, y0 = max(math.floor(bounds[0]) - 2, 0), max(math.floor(bounds[1]) - 2, 0)
    x1, y1 = min(math.ceil(bounds[2]) + 3, w), min(math.ceil(bounds[3]) + 3, h)
    if factor == 1.0:
        return WorkingCopy(image, (0, 0), 1.0, px_per_mm)
    crop = image[y0:y1, x0:x1]
    size = (max(round((x1 - x0) * factor), 1), max(round((y1 - y0) * factor), 1))
    interpolation = cv2.INTER_AREA if factor < 1 else cv2.INTER_LINEAR
    small = cv2.resize(crop, size, interpolation=interpolation)
    # the factor actually applied (sizes are rounded to whole pixels)
    factor = size[0] / (x1 - x0)
    return WorkingCopy(small, (x0, y0), factor, px_per_mm * factor)


def pixel_params(params: PlateParams, copy: WorkingCopy) -> PlateParams:
    """``params`` with every ``*_px`` size resolved for the working copy.

    A ``*_px`` override is in pixels of the original image and is scaled by the copy's factor;
    otherwise the millimetre value is turned into working pixels. ``px_per_mm`` becomes the
    working copy's scale: every size of the returned params is in working pixels.
    """
    f, mm = copy.factor, copy.px_per_mm

    def length(px: float | None, millimetres: float) -> float:
        return float(px) * f if px is not None else millimetres * mm

    def area(px: float | None, diameter_mm: float) -> float:
        return float(px) * f * f if px is not None else math.pi * (diameter_mm * mm / 2) ** 2

    cell = params.background_scale
    cell_px = round(cell * f) if cell is not None else round(params.background_cell_mm * mm)
    return replace(
        params,
        px_per_mm=mm,
        rim_margin_px=length(params.rim_margin_px, params.rim_margin_mm),
        min_colony_area_px=area(params.min_colony_area_px, params.min_colony_diameter_mm),
        max_colony_area_px=area(params.max_colony_area_px, params.max_colony_diameter_mm),
        min_width_px=length(params.min_width_px, params.min_width_mm),
        edge_skip_px=length(params.edge_skip_px, params.edge_skip_mm),
        background_scale=max(cell_px, 1),
    )
