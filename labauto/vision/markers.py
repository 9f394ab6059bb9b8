"""Coded circular markers found by the DES detector (the paper's section 4.2).

Pipeline, as in the paper ("before we apply any ellipse fitting procedures to all possible
objects, we first segment obviously elliptical shapes from artifacts using our DES approach"):

1. **Contours** of the grey image by our Canny detector (:func:`labauto.vision.detector.
   extract_contours`, sub-pixel edges).
2. **DES prefilter**: the shape angle D_alpha (eq. 3) with the centroid-inside test
   (:func:`labauto.vision.shape_angle.shape_angles`); only DES go on, so rectangles, lines,
   ring sectors and other artefacts are never fitted.
3. **Geometric ellipse fit** of every DES of a plausible size (orthogonal distances, Ahn's
   method, :func:`labauto.vision.ellipse_fit.fit_selected_ellipses`).
4. **Code read** in the ellipse's rectified frame: the affine map taking the unit circle onto the
   fitted ellipse takes the marker's plane, to first order, onto the image (up to an unknown
   rotation, which the rotation-invariant code does not care about). The image is sampled
   (bilinear) on circles of radii 2.3, 2.5, 2.7 (the code ring, 2-3 centre radii) at 8 samples
   per sector, on the centre circle (ink level) and on the paper gap and quiet zone (paper
   level). Samples are normalised to 0 (ink) .. 1 (paper), so dark-on-light and light-on-dark
   markers read alike and uneven light only matters through the local levels. The sector
   phase is the one of the 8 that gives the most decisive bits (the ends of each sector are
   left out); a bit is ink when its mean is below 0.5. The word must be a code of
   :mod:`labauto.vision.marker_codes` (even weight, so one wrong bit never gives another id),
   the ink-paper contrast at least ``min_contrast`` and every bit at least ``min_margin`` from
   the threshold (in units of half the contrast): rectangles, plain dots and artefacts get no
   id.
5. **Sub-pixel circles and perspective-bias correction**
   (:mod:`labauto.vision.marker_edges`): the centre circle and the code ring's inner and outer
   edges are measured again along rays (the moment of each edge profile), each fitted with the
   geometric ellipse fit, and the image of the common centre of the centre circle and the
   ring's outer edge (the best-conditioned pair; the inner edge stands in when the outer one
   failed) is the eigenvector construction of :mod:`labauto.vision.concentric`, exact under
   any homography. With no usable ring fit, or a correction larger than any perspective makes
   (``MAX_BIAS_SHARE`` of the semi-minor axis plus ``MAX_BIAS_PX``), the centre is the centre
   circle's ellipse centre and ``bias_corrected`` is False. ``ellipse`` is the re-measured
   centre circle.

Markers must be seen from their printed side: a mirrored marker (seen through a transparent
sheet, or drawn by a map that flips orientation) reads its ring backwards, which is in general
the word of another valid code, so it gets a wrong id.

``score`` is the smallest bit margin (0..1) times the contrast share (contrast / 255, capped at
1 after doubling): 1 is a perfect read.

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down. Works on any
sub-image (a tracker's window): positions are in that array's pixels.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace

import cv2
import numpy as np

from labauto.vision.contours import Contours
from labauto.vision.detector import DetectorParams, extract_contours, validate_params
from labauto.vision.ellipse import Ellipse
from labauto.vision.ellipse_fit import fit_selected_ellipses
from labauto.vision.gradient import as_uint8_image
from labauto.vision.marker_codes import N_BITS, RING_OUTER, decode_words
from labauto.vision.marker_codes import warm as warm_codes
from labauto.vision.marker_edges import affine_frames, marker_centers, refine_circles
from labauto.vision.shape_angle import shape_angles

#: Samples per sector along the ring, and the ring radii sampled (centre radii).
SAMPLES_PER_BIT = 8
READ_RADII = (2.3, 2.5, 2.7)
#: Largest believable perspective bias: a corrected centre farther than this from the centre
#: circle's ellipse centre (share of its semi-minor axis, plus px) is dropped (the bias of a
#: 20 px marker at 60 degrees seen with strong perspective is 0.05 semi-minor axes).
MAX_BIAS_SHARE = 0.2
MAX_BIAS_PX = 0.3
#: Radii (centre radii) sampled for the ink level and the paper level.
INK_RADII = (0.0, 0.35, 0.6)
PAPER_RADII = (1.5, 3.35)


@dataclass(frozen=True)
class MarkerParams:
    """Tunables of :func:`detect_markers`.

    Attributes
    ----------
    blur_sigma, canny_low, canny_high : float
        Of the contour detector (:class:`labauto.vision.detector.DetectorParams`).
    des_threshold_deg : float
        D_alpha threshold of the DES prefilter (60: ellipses down to 1:4, a 75 degree tilt).
    min_radius_px, max_radius_px : float
        Range of the centre circle's semi-major axis.
    min_contrast : float
        Least ink-paper difference (grey levels) of a marker.
    min_margin : float
        Least distance of every bit from the threshold, in half-contrasts (0..1).
    correct_bias : bool
        Fit the code ring's edges and correct the centre for perspective.
    """

    blur_sigma: float = 0.7
    canny_low: float = 30.0
    canny_high: float = 80.0
    des_threshold_deg: float = 60.0
    min_radius_px: float = 3.0
    max_radius_px: float = 400.0
    min_contrast: float = 25.0
    min_margin: float = 0.3
    correct_bias: bool = True

    def detector_params(self) -> DetectorParams:
        """The contour detector's parameters."""
        return DetectorParams(
            blur_sigma=self.blur_sigma,
            canny_low=self.canny_low,
            canny_high=self.canny_high,
            des_threshold_deg=self.des_threshold_deg,
            classify=False,
        )


@dataclass(frozen=True)
class Marker:
    """One coded marker found in an image.

    Attributes
    ----------
    id : int
        The marker's id (index in :func:`labauto.vision.marker_codes.code_book`).
    center : (x, y)
        Image of the marker's centre: bias-corrected when ``bias_corrected``, else the centre
        of ``ellipse``.
    centroid : (x, y)
        Centre of gravity of the centre circle's contour (the DES centroid).
    ellipse : Ellipse
        Geometric fit of the centre circle's edge.
    score : float
        Read quality in (0, 1].
    rotation_deg : float
        Direction of the code's bit 0 in the rectified frame (degrees from +x toward +y).
    bias_corrected : bool
        ``center`` comes from the concentric ring fits.
    ring_ellipses : tuple of Ellipse
        Fits of the code ring's inner and outer edges that were used (may be empty).
    """

    id: int
    center: tuple[float, float]
    centroid: tuple[float, float]
    ellipse: Ellipse
    score: float
    rotation_deg: float = 0.0
    bias_corrected: bool = False
    ring_ellipses: tuple[Ellipse, ...] = ()

    def to_dict(self) -> dict:
        """JSON form: ``{"id", "center", "centroid", "ellipse", "score", "bias_corrected"}``."""
        return {
            "id": int(self.id),
            "center": [float(self.center[0]), float(self.center[1])],
            "centroid": [float(self.centroid[0]), float(self.centroid[1])],
            "ellipse": self.ellipse.to_dict(),
            "score": float(self.score),
            "bias_corrected": bool(self.bias_corrected),
        }

    def shifted(self, dx: float, dy: float) -> Marker:
        """The same marker with every position moved by ``(dx, dy)`` (window to full image)."""

        def move(e: Ellipse) -> Ellipse:
            return Ellipse((e.center[0] + dx, e.center[1] + dy), e.axes, e.angle)

        return replace(
            self,
            center=(self.center[0] + dx, self.center[1] + dy),
            centroid=(self.centroid[0] + dx, self.centroid[1] + dy),
            ellipse=move(self.ellipse),
            ring_ellipses=tuple(move(e) for e in self.ring_ellipses),
        )


@dataclass(frozen=True)
class MarkerResult:
    """The markers of one image and the time the detection took."""

    width: int
    height: int
    timing_ms: float
    markers: list[Marker]

    def to_dict(self) -> dict:
        """``{"width", "height", "timing_ms", "markers": [...]}``."""
        return {
            "width": int(self.width),
            "height": int(self.height),
            "timing_ms": float(self.timing_ms),
            "markers": [m.to_dict() for m in self.markers],
        }


def marker_params(**options: object) -> MarkerParams:
    """Build :class:`MarkerParams` from keyword options, naming an unknown one."""
    known = {f.name for f in fields(MarkerParams)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"unknown marker option(s) {unknown}; known: {sorted(known)}")
    params = MarkerParams(**options)  # type: ignore[arg-type]
    if not 0 < params.min_radius_px <= params.max_radius_px:
        raise ValueError(
            f"need 0 < min_radius_px <= max_radius_px, got {params.min_radius_px}, "
            f"{params.max_radius_px}"
        )
    if not 0 <= params.min_margin < 1:
        raise ValueError(f"min_margin must be in [0, 1), got {params.min_margin}")
    validate_params(params.detector_params())
    return params


def detect_markers(image: np.ndarray, **options: object) -> list[Marker]:
    """Find the coded markers in an image.

    Parameters
    ----------
    image : np.ndarray
        HxW grey or HxWx3 BGR image (uint8, or float on a 0-255 scale); any sub-image works.
    **options
        Fields of :class:`MarkerParams`.

    Returns
    -------
    list of Marker
        Sorted by id; at most one marker per id (the best read when an id is seen twice).
    """
    return find_markers(image, marker_params(**options)).markers


def find_markers(image: np.ndarray, params: MarkerParams = MarkerParams()) -> MarkerResult:
    """:func:`detect_markers` with its parameters as one value, and the timing."""
    warm_codes()  # the one-off code table is not part of an image's time
    start = time.perf_counter()
    img = as_uint8_image(image)
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if img.ndim == 3 else img
    contours = extract_contours(grey, params.detector_params())
    markers = _markers(grey, contours, params) if len(contours) else []
    elapsed = (time.perf_counter() - start) * 1e3
    return MarkerResult(grey.shape[1], grey.shape[0], elapsed, markers)


# ------------------------------------------------------------------------------ the steps


def _sample(
    grey: np.ndarray, centres: np.ndarray, maps: np.ndarray, unit: np.ndarray
) -> np.ndarray:
    """Bilinear grey values at ``centre + map @ unit`` for every frame: (K, M)."""
    m = maps.astype(np.float32)
    u, v = unit[:, 0].astype(np.float32), unit[:, 1].astype(np.float32)
    c = centres.astype(np.float32)
    mx = c[:, :1] + m[:, 0, :1] * u + m[:, 0, 1:] * v
    my = c[:, 1:] + m[:, 1, :1] * u + m[:, 1, 1:] * v
    out = cv2.remap(grey, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.astype(np.float64)


def _circle(radii: tuple[float, ...], n: int) -> np.ndarray:
    t = 2.0 * np.pi * (np.arange(n) + 0.5) / n
    return np.concatenate([np.column_stack((r * np.cos(t), r * np.sin(t))) for r in radii])


def _read_codes(
    grey: np.ndarray, ellipses: list[Ellipse], params: MarkerParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ids (-1: no code), scores, code bit-0 directions (rad), bits as read and where read bit 0
    starts (rad), all in the rectified frames of the ellipses."""
    k = len(ellipses)
    centres, maps = affine_frames(ellipses)
    n_ring = N_BITS * SAMPLES_PER_BIT
    # the levels first: only a candidate with marker contrast has its ring sampled
    ink = np.median(_sample(grey, centres, maps, _circle(INK_RADII, 8)), axis=1)
    paper = np.median(_sample(grey, centres, maps, _circle(PAPER_RADII, 24)), axis=1)
    contrast = paper - ink
    lit = np.flatnonzero(np.abs(contrast) >= params.min_contrast)
    ring = _sample(grey, centres[lit], maps[lit], _circle(READ_RADII, n_ring))
    ring = ring.reshape(len(lit), len(READ_RADII), n_ring).mean(axis=1)
    level = np.full((k, n_ring), 0.5)  # candidates without contrast read as undecided
    level[lit] = (ring - ink[lit, None]) / contrast[lit, None]  # 0 ink .. 1 paper
    # per phase p: sector k covers samples k*S + p .. k*S + p + S - 1; drop one at each end
    s = SAMPLES_PER_BIT
    best_margin = np.full(k, -np.inf)
    best_bits = np.zeros((k, N_BITS), bool)
    best_phase = np.zeros(k, np.int64)
    for p in range(s):
        rolled = np.roll(level, -p, axis=1).reshape(k, N_BITS, s)[:, :, 1:-1]
        means = rolled.mean(axis=2)
        margin = np.min(np.abs(means - 0.5), axis=1) * 2.0
        better = margin > best_margin
        best_margin = np.where(better, margin, best_margin)
        best_bits[better] = means[better] < 0.5
        best_phase[better] = p
    words = (best_bits.astype(np.int64) << np.arange(N_BITS)).sum(axis=1)
    ids, turns = decode_words(words)
    ok = (np.abs(contrast) >= params.min_contrast) & (best_margin >= params.min_margin)
    ids = np.where(ok, ids, -1)
    score = best_margin * np.minimum(np.abs(contrast) * 2.0 / 255.0, 1.0)
    # read bit i starts at angle (i*S + p) * 2 pi / n_ring; the code's bit 0 is read bit -turns
    bit0 = ((-turns) % N_BITS * s + best_phase) * 2.0 * np.pi / n_ring
    start = best_phase * 2.0 * np.pi / n_ring  # where read bit 0 starts
    return ids, score, bit0, best_bits, start


def _candidates(grey: np.ndarray, contours: Contours, params: MarkerParams):
    angles = shape_angles(contours.points, contours.gradients, contours.offsets, contours.closed)
    des = angles.is_des(params.des_threshold_deg)
    # cheap size test before fitting: the DES's extent from its area
    radius = np.sqrt(np.maximum(angles.area, 0.0) / np.pi)
    des &= (radius >= params.min_radius_px * 0.5) & (radius <= params.max_radius_px * 1.2)
    fits = fit_selected_ellipses(contours.points, contours.offsets, des, max_iter=10, tol=1e-7)
    h, w = grey.shape
    keep = []
    for k, e in enumerate(fits):
        if e is None:
            continue
        a, b = e.axes
        if not params.min_radius_px <= a <= params.max_radius_px or b < 0.25 * a:
            continue
        reach = RING_OUTER * a + 1
        cx, cy = e.center
        if cx - reach < 0 or cy - reach < 0 or cx + reach > w - 1 or cy + reach > h - 1:
            continue  # the code ring leaves the image
        keep.append(k)
    return angles, fits, keep


def _markers(grey: np.ndarray, contours: Contours, params: MarkerParams) -> list[Marker]:
    angles, fits, keep = _candidates(grey, contours, params)
    if not keep:
        return []
    ellipses = [fits[k] for k in keep]
    pixels = grey.astype(np.float32)  # sampled at sub-pixel positions from here on
    ids, score, bit0, bits, start = _read_codes(pixels, ellipses, params)
    best: dict[int, int] = {}
    for j, marker_id in enumerate(ids.tolist()):
        if marker_id >= 0 and (marker_id not in best or score[j] > score[best[marker_id]]):
            best[marker_id] = j
    chosen = sorted(best.items())
    picked = [j for _, j in chosen]
    circles = (
        refine_circles(
            pixels,
            [ellipses[j] for j in picked],
            [bits[j] for j in picked],
            [float(start[j]) for j in picked],
            params.min_contrast,
        )
        if params.correct_bias
        else [(None, None, None)] * len(picked)
    )
    out = []
    centres = marker_centers(circles)
    for (marker_id, j), (centre_fit, inner, outer), xy in zip(
        chosen, circles, centres, strict=True
    ):
        e = centre_fit if centre_fit is not None else ellipses[j]
        centre = (float(xy[0]), float(xy[1])) if np.isfinite(xy).all() else None
        if (
            centre is not None
            and np.hypot(centre[0] - e.center[0], centre[1] - e.center[1])
            > MAX_BIAS_SHARE * e.axes[1] + MAX_BIAS_PX
        ):
            centre = None  # a bias that large is a failed ring fit, not perspective
        ring = tuple(r for r in (inner, outer) if r is not None)
        cx, cy = angles.centroid[keep[j]]
        out.append(
            Marker(
                id=marker_id,
                center=centre if centre is not None else e.center,
                centroid=(float(cx), float(cy)),
                ellipse=e,
                score=float(score[j]),
                rotation_deg=float(np.degrees(bit0[j])),
                bias_corrected=centre is not None,
                ring_ellipses=ring if centre is not None else (),
            )
        )
    return out
