"""The DES detector of Teutsch et al.: contours, shape angle, shape label and ellipse fit.

Pipeline (sections 3.1-3.2 of the paper):

1. contours, either from the colour Canny detector (``method="canny"``: eq. 2 colour gradient,
   hysteresis, ordered edge linking, sub-pixel refinement) or from the adaptive colour
   segmentation (``method="color"``: eq. 1, boundary tracing in the 8-neighbourhood);
2. the shape angle D_alpha (eq. 3) of every contour, its centroid and the centroid-inside test;
3. a DES is a contour whose centroid is inside and whose D_alpha is below a threshold;
4. a shape label for every object (harmonic analysis) and a geometric ellipse fit for every DES,
   each one call for all contours of the image (``classify_shapes``, ``fit_selected_ellipses``).

Every step's inner loop is a compiled kernel (:mod:`labauto.vision.kernels`) working on all
contours of the image at once; the Python modules hold the definitions and the input checks.

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from labauto.vision.contours import Contours, canny_contours, color_contours
from labauto.vision.ellipse import Ellipse
from labauto.vision.ellipse_fit import fit_selected_ellipses
from labauto.vision.harmonics import classify_shapes
from labauto.vision.image import as_image
from labauto.vision.shape_angle import (
    DEFAULT_DES_THRESHOLD_DEG,
    DEFAULT_MAX_GAP_FRACTION,
    shape_angles,
)

#: Shape label given when classification is disabled or impossible.
UNKNOWN_SHAPE = "unknown"

#: Levenberg-Marquardt cap of the geometric ellipse fit of every DES. From the algebraic seed
#: an elliptic contour reaches its optimum within 1e-5 px in 2-3 Gauss-Newton steps (on the
#: benchmark scenes the fitted ellipses equal fully converged fits to 2e-6 px); a DES that is
#: no ellipse (a square, a bean) creeps on for dozens of iterations toward an ever longer
#: ellipse, which the cap stops (its rms stays pixels large either way).
FIT_MAX_ITER = 5
#: Relative tolerance of that fit: a step below ``FIT_TOL * a`` px ends it (1e-4 px at a = 10).
FIT_TOL = 1e-5


@dataclass(frozen=True)
class DetectorParams:
    """Every tunable of the detector, with defaults for 8-bit images of colonies or markers.

    Attributes
    ----------
    method : str
        ``"canny"`` (colour Canny, default) or ``"color"`` (adaptive colour segmentation).
    blur_sigma : float
        Gaussian blur (pixels) before the gradient; 0 disables it.
    canny_low, canny_high : float
        Hysteresis thresholds on the L2 colour-gradient magnitude of a 3x3 Sobel (a step of
        contrast C grey levels gives a magnitude of about 4 C before blurring).
    color_threshold : float
        ``t`` of eq. 1: a pixel is foreground when its (weighted) summed squared deviation from
        the background mean exceeds ``t`` (grey levels squared).
    channel_weights : tuple of float or None
        Per-channel weights of eq. 1 (B, G, R order, as the image); None means all 1.
    min_contour_length, max_contour_length : int
        Contours with fewer or more points are rejected (paper: "too short" / "very long").
    des_threshold_deg : float
        D_alpha threshold (degrees) under which a contour with its centroid inside is a DES
        (60: ellipses down to 1:4, see :mod:`labauto.vision.shape_angle`).
    max_gap_fraction : float
        Largest missing share of the outline of a DES (chord / (length + chord)).
    statistic : str
        ``"median"`` (default, the paper's robust choice) or ``"mean"``.
    fit_ellipses : bool
        Fit an ellipse (geometric, orthogonal distances) to every DES.
    subpixel : bool
        Refine Canny edge points to sub-pixel precision.
    classify : bool
        Give every object a shape label (harmonic analysis); ``"unknown"`` when disabled.
    """

    method: str = "canny"
    blur_sigma: float = 0.7
    canny_low: float = 40.0
    canny_high: float = 100.0
    color_threshold: float = 900.0
    channel_weights: tuple[float, float, float] | None = None
    min_contour_length: int = 20
    max_contour_length: int = 10000
    des_threshold_deg: float = DEFAULT_DES_THRESHOLD_DEG
    max_gap_fraction: float = DEFAULT_MAX_GAP_FRACTION
    statistic: str = "median"
    fit_ellipses: bool = True
    subpixel: bool = True
    classify: bool = True


@dataclass
class DetectedObject:
    """One contour found in the image.

    ``points`` is the (n, 2) float array of contour points ``(x, y)``; it is not part of the
    JSON form.
    """

    id: int
    centroid: tuple[float, float]
    n_points: int
    closed: bool
    d_alpha_median: float
    d_alpha_mean: float
    centroid_inside: bool
    is_des: bool
    shape: str
    ellipse: Ellipse | None
    points: np.ndarray = field(repr=False)
    area_px: float = 0.0
    descriptors: dict | None = None

    def to_dict(self) -> dict:
        """Return the JSON form (no points)."""
        return {
            "id": int(self.id),
            "centroid": [float(self.centroid[0]), float(self.centroid[1])],
            "n_points": int(self.n_points),
            "closed": bool(self.closed),
            "d_alpha_median": float(self.d_alpha_median),
            "d_alpha_mean": float(self.d_alpha_mean),
            "centroid_inside": bool(self.centroid_inside),
            "is_des": bool(self.is_des),
            "shape": self.shape,
            "ellipse": None if self.ellipse is None else self.ellipse.to_dict(),
        }


@dataclass
class DetectionResult:
    """All objects of one image and the time the detection took."""

    width: int
    height: int
    method: str
    timing_ms: float
    objects: list[DetectedObject]

    def to_dict(self) -> dict:
        """Return ``{"width", "height", "method", "timing_ms", "objects": [...]}``."""
        return {
            "width": int(self.width),
            "height": int(self.height),
            "method": self.method,
            "timing_ms": float(self.timing_ms),
            "objects": [obj.to_dict() for obj in self.objects],
        }

    @property
    def des(self) -> list[DetectedObject]:
        """The objects that are DES."""
        return [obj for obj in self.objects if obj.is_des]


def detect(image: np.ndarray, params: DetectorParams = DetectorParams()) -> DetectionResult:
    """Find contours in ``image`` and tell deformed elliptic shapes (DES) from the rest.

    Parameters
    ----------
    image : np.ndarray
        HxW grey or HxWx3 colour (BGR, as ``cv2.imread`` gives) image, uint8 or float
        (float images are taken on a 0-255 scale).
    params : DetectorParams
        Tunables.

    Returns
    -------
    DetectionResult

    Raises
    ------
    ValueError
        If the image is empty, has the wrong number of dimensions or channels, or an unsupported
        dtype, or a parameter is out of range.
    """
    start = time.perf_counter()
    validate_params(params)
    img = as_image(image)
    contours = extract_contours(img, params)
    objects = _objects(contours, params)
    elapsed_ms = (time.perf_counter() - start) * 1e3
    h, w = img.shape[:2]
    return DetectionResult(w, h, params.method, elapsed_ms, objects)


def validate_params(params: DetectorParams) -> None:
    """Raise ValueError naming the first out-of-range field of ``params``."""
    if not isinstance(params, DetectorParams):
        raise ValueError(f"params must be a DetectorParams, got {type(params).__name__}")
    if params.method not in ("canny", "color"):
        raise ValueError(f"method must be 'canny' or 'color', got {params.method!r}")
    if params.statistic not in ("median", "mean"):
        raise ValueError(f"statistic must be 'median' or 'mean', got {params.statistic!r}")
    if params.blur_sigma < 0:
        raise ValueError(f"blur_sigma must be >= 0, got {params.blur_sigma}")
    if not 0 <= params.canny_low <= params.canny_high:
        raise ValueError(
            f"need 0 <= canny_low <= canny_high, got {params.canny_low}, {params.canny_high}"
        )
    if params.color_threshold < 0:
        raise ValueError(f"color_threshold must be >= 0, got {params.color_threshold}")
    if params.channel_weights is not None and (
        len(params.channel_weights) != 3 or min(params.channel_weights) < 0
    ):
        raise ValueError(f"channel_weights must be 3 values >= 0, got {params.channel_weights}")
    if not 3 <= params.min_contour_length <= params.max_contour_length:
        raise ValueError(
            "need 3 <= min_contour_length <= max_contour_length, got "
            f"{params.min_contour_length}, {params.max_contour_length}"
        )
    if not 0 <= params.max_gap_fraction <= 1:
        raise ValueError(f"max_gap_fraction must be in [0, 1], got {params.max_gap_fraction}")
    if not 0 < params.des_threshold_deg <= 90:
        raise ValueError(f"des_threshold_deg must be in (0, 90], got {params.des_threshold_deg}")


def extract_contours(image: np.ndarray, params: DetectorParams = DetectorParams()) -> Contours:
    """Contours of a validated uint8 image by ``params.method`` (step 1 of :func:`detect`)."""
    if params.method == "canny":
        return canny_contours(
            image,
            blur_sigma=params.blur_sigma,
            low=params.canny_low,
            high=params.canny_high,
            min_length=params.min_contour_length,
            max_length=params.max_contour_length,
            subpixel=params.subpixel,
        )
    weights = params.channel_weights
    if weights is not None and image.ndim == 2:
        weights = (float(np.mean(weights)),)  # one channel: the weight only scales t
    return color_contours(
        image,
        threshold=params.color_threshold,
        channel_weights=weights,
        min_length=params.min_contour_length,
        max_length=params.max_contour_length,
    )


def _labels(
    contours: Contours,
    d_alpha: np.ndarray,
    inside: np.ndarray,
    centroids: np.ndarray,
    params: DetectorParams,
) -> list[str]:
    """Shape label of every contour (step 4), all contours at once (:func:`classify_shapes`)."""
    if not params.classify:
        return [UNKNOWN_SHAPE] * len(contours)
    labels = classify_shapes(
        contours.points,
        contours.offsets,
        d_alpha=d_alpha,
        centroid_inside=inside,
        des_threshold_deg=params.des_threshold_deg,
        centroids=centroids,
    )
    return [UNKNOWN_SHAPE if label is None else label for label in labels]


def _fits(contours: Contours, des: np.ndarray, params: DetectorParams) -> list[Ellipse | None]:
    """Geometric ellipse of every DES (step 4), all DES in one batched fit; None elsewhere."""
    if not params.fit_ellipses or not des.any():
        return [None] * len(contours)
    return fit_selected_ellipses(
        contours.points, contours.offsets, des, max_iter=FIT_MAX_ITER, tol=FIT_TOL
    )


def _objects(contours: Contours, params: DetectorParams) -> list[DetectedObject]:
    if len(contours) == 0:
        return []
    angles = shape_angles(contours.points, contours.gradients, contours.offsets, contours.closed)
    des = angles.is_des(params.des_threshold_deg, params.statistic, params.max_gap_fraction)
    d_alpha = angles.statistic(params.statistic)
    shapes = _labels(contours, d_alpha, angles.centroid_inside, angles.centroid, params)
    ellipses = _fits(contours, des, params)
    offsets = contours.offsets.tolist()
    centroids = angles.centroid.tolist()
    medians, means = angles.d_alpha_median.tolist(), angles.d_alpha_mean.tolist()
    inside, closed, areas = (
        angles.centroid_inside.tolist(),
        contours.closed.tolist(),
        angles.area.tolist(),
    )
    is_des = des.tolist()
    points = contours.points
    return [
        DetectedObject(
            id=k,
            centroid=(centroids[k][0], centroids[k][1]),
            n_points=offsets[k + 1] - offsets[k],
            closed=closed[k],
            d_alpha_median=medians[k],
            d_alpha_mean=means[k],
            centroid_inside=inside[k],
            is_des=is_des[k],
            shape=shapes[k],
            ellipse=ellipses[k],
            points=points[offsets[k] : offsets[k + 1]],
            area_px=areas[k],
        )
        for k in range(len(contours))
    ]
