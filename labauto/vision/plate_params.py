"""Parameters of plate analysis (:func:`labauto.vision.plate.analyze_plate`), validated.

Every size is in millimetres and turned into pixels from the dish (or a configured scale) by
:func:`labauto.vision.plate_scale.pixel_params`; a ``*_px`` field, when set, overrides its
millimetre twin. The pipeline the parameters steer is described in :mod:`labauto.vision.plate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labauto.vision.detector import DetectorParams

Circle = tuple[float, float, float]
Polygon = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class PlateParams:
    """Tunables of :func:`labauto.vision.plate.analyze_plate`; sizes in mm, in pixels per image.

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
    min_analysis_px_per_mm : float
        Images coarser than this are resampled up to ``analysis_px_per_mm``
        (:mod:`labauto.vision.plate_scale`); 0 never upsamples.
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
    chain_ratio : float
        A stroke-shaped body (``max_fill_ratio``) whose inscribed radius is at least this
        fraction of the plate's median single colony's (the DES bodies, of 3 or more) is as
        wide as the plate's colonies: a chain of them along a streak, not a pen line. Unless it
        is ink (:mod:`labauto.vision.plate_ink`) it is kept as a merged body and counted by its
        peaks; 0 turns it off. A pen line is 0.5-1 mm wide, thinner than the colonies of most
        plates. Measured on the AGAR photographs: 0.6 keeps a chain of 11 boxed colonies on
        plate 525 (61 -> 72 matched; F1 0.853 -> 0.857, median count error 11.4 -> 10.5 %),
        0.8 the same, 0.4 also keeps 6 bodies holding none (F1 0.856); phone-counts unchanged;
        at 7 px/mm F1 0.815 -> 0.818.
    des_threshold_deg : float
        D_alpha threshold of a DES, degrees (25: colonies are at most ~1:1.6 and read <= 21;
        the paper's "typical DES" of ~30 also takes in merged pairs of unequal size).
    statistic : str
        ``"median"`` or ``"mean"`` D_alpha.
    max_concavity : float
        Largest depth of a concavity (distance from the convex hull) relative to the inscribed
        radius for a DES; a waist between two colonies is deeper. Generator: singles <= 0.12,
        merged >= 0.22. AGAR photographs, DES bodies within ``max_authentic_elongation``:
        those holding one boxed colony 0.033-0.184 (5th-95th percentile; ragged outlines),
        those holding two median 0.16. 0.2 (was 0.17) offers 879 colonies for picking instead
        of 807, with the same 7 holding two boxed colonies (0.22: 7 as well; 0.3: 11).
    max_authentic_elongation : float
        Largest second-moment axis ratio of an authentic colony; a longer DES is merged (with
        its count), never offered for picking. Measured on the AGAR photographs, of the bodies
        that passed every other authentic test: those holding one boxed colony 1.006-1.168
        (5th-95th percentile), those holding two 1.05-1.28 (median 1.21). 1.2 takes 11 of
        those 18 pairs out of the picking list and 26 of 821 single colonies with them (3 %);
        1.3 let all 18 pairs through (``benchmarks/bench_real_plates.py``, picking line).
        Counts do not change (the class does not set them).
    edge_skip_mm, edge_skip_px : float
        Pixels this close to a colony's boundary are left out of the mixed-colony test.
    mix_residual : float
        Colour distance (grey levels) from the one-species dome fit that makes a pixel an outlier.
    mix_fraction : float
        Least fraction of outlier pixels that makes a DES a mixed colony.
    valley_ratio : float
        Distance-transform dip between two peaks, relative to the lower peak, that separates two
        colonies of a merged body.
    peak_floor_ratio : float
        A distance-transform peak of a merged body is a colony's centre only when it is at
        least this fraction of the plate's median single colony's inscribed radius (the DES
        bodies, of 3 or more); 0 turns it off. Thin pieces of a large colony (crescents that
        the rim's background cut from it) otherwise counted two or three each. Measured on
        the AGAR photographs: 0.3 drops 28 reported colonies and 1 matched one (F1 0.846 ->
        0.852; plate 4904 48 -> 36 of 22), 0.2 drops 17 (F1 0.849), 0.5 drops 61 and 7
        matched (F1 0.857, but median count error 11.8 -> 13.3 %); phone-counts unchanged.
    pair_elongation : float
        A merged body of one peak whose axis ratio is at least this and whose area is at least
        the plate's median single colony's (authentic or mixed, of 3 or more) counts as two
        (:func:`labauto.vision.plate_counts.pair_counts`); 0 turns it off.
    sliver_elongation : float
        A body no point of which lies as deep inside it as the peak floor (``peak_floor_ratio``
        of the plate's median single colony's inscribed radius) and whose axis ratio is at
        least this is a sliver, not a colony, and is not reported (``rejected["sliver"]``); 0
        turns it off. A small round colony is as thin but not long, and stays. On the AGAR
        photographs the slivers are crescents of large colonies' pale rims and pieces of the
        wall: 1.5 drops 29 reported colonies and 8 matched ones (F1 0.851 -> 0.853, median
        count error 11.8 -> 11.4 %, plate 4904 37 -> 20 of 22; 1.3: F1 0.854, 2.0: 0.853);
        phone-counts unchanged; at a webcam's 7 px/mm F1 0.814 -> 0.815, at 4.5 px/mm 0.749 ->
        0.748.
    rim_band_mm : float
        Width of the band inside the agar's edge whose background follows the dish's radial
        profile (the meniscus; see :func:`labauto.vision.plate_background.rim_profile`);
        0 turns it off.
    faint_factor : float
        Faint colonies (:mod:`labauto.vision.plate_faint`): a smoothed departure from a coarse
        background this many times the agar's own is foreground; 0 turns the pass off.
    faint_min_diameter_mm, faint_max_diameter_mm : float
        Sizes (as discs) of the faint bodies kept.
    faint_min_hue_diameter_mm : float
        Least size of a faint body departing in hue (the search across the grey axis, where
        the agar's texture is weaker): smaller yellowish colonies are found there.
    find_rings : bool
        Ring colonies (:mod:`labauto.vision.plate_rings`): round edges with little body inside,
        found by the circular Hough transform; False turns the pass off.
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
    min_analysis_px_per_mm: float = 8.0
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
    max_concavity: float = 0.2
    max_authentic_elongation: float = 1.2
    edge_skip_mm: float = 0.25
    edge_skip_px: float | None = None
    mix_residual: float = 24.0
    mix_fraction: float = 0.06
    valley_ratio: float = 0.9
    peak_floor_ratio: float = 0.3
    pair_elongation: float = 1.3
    sliver_elongation: float = 1.5
    chain_ratio: float = 0.6
    reject_ink: bool = True
    drop_at_border: bool = False
    faint_factor: float = 4.0
    faint_min_diameter_mm: float = 2.0
    faint_max_diameter_mm: float = 12.0
    faint_min_hue_diameter_mm: float = 1.0
    find_rings: bool = True
    rim_band_mm: float = 4.0
    detector: DetectorParams = field(default_factory=lambda: DetectorParams(method="color"))

    def __post_init__(self) -> None:
        non_negative = (
            "color_threshold",
            "noise_factor",
            "open_mm",
            "analysis_px_per_mm",
            "min_analysis_px_per_mm",
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
            "pair_elongation",
            "peak_floor_ratio",
            "sliver_elongation",
            "chain_ratio",
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
            "faint_min_hue_diameter_mm",
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
        if 0 < self.analysis_px_per_mm < self.min_analysis_px_per_mm:
            raise ValueError(
                "PlateParams.min_analysis_px_per_mm must not exceed analysis_px_per_mm"
            )
        for name in ("faint_min_diameter_mm", "faint_min_hue_diameter_mm"):
            if getattr(self, name) > self.faint_max_diameter_mm:
                raise ValueError(f"PlateParams.{name} must not exceed faint_max_diameter_mm")
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
