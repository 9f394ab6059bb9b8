"""Coded circular markers found by the DES detector (the paper's section 4.2).

Pipeline, as in the paper ("before we apply any ellipse fitting procedures to all possible
objects, we first segment obviously elliptical shapes from artifacts using our DES approach"):

1. **Contours** of the grey image by our Canny detector (:func:`labauto.vision.detector.
   extract_contours`, sub-pixel edges).
2. **DES prefilter**: the shape angle D_alpha (eq. 3) with the centroid-inside test
   (:func:`labauto.vision.shape_angle.shape_angles`); only DES go on, so rectangles, lines,
   ring sectors and other artefacts are never fitted.
3. **Ellipse fit for the read**: the direct algebraic fit (Halir-Flusser,
   :func:`labauto.vision.ellipse_fit.fit_ellipses_algebraic_batch`) of every DES of a
   plausible size whose code ring lies inside the image. On a marker's centre circle it is
   within 0.03 px of the geometric fit (centre and axes; 0.002 px on average, noisy renders),
   far less than the read needs (a sector is over 4 px wide on a 10 px marker), at a sixth of
   the cost; the geometric fit waits for the markers (step 5).
4. **Code read** in the ellipse's rectified frame: the affine map taking the unit circle onto the
   fitted ellipse takes the marker's plane, to first order, onto the image (up to an unknown
   rotation, which the rotation-invariant code does not care about). The image is sampled
   (bilinear) on circles of radii 2.35 and 2.65 (the code ring, 2-3 centre radii) at 8 samples
   per sector, on the centre circle (ink level) and on the paper gap and quiet zone (paper
   level). Samples are normalised to 0 (ink) .. 1 (paper), so dark-on-light and light-on-dark
   markers read alike and uneven light only matters through the local levels. The sector
   phase is the one of the 8 that gives the most decisive bits (the ends of each sector are
   left out); a bit is ink when its mean is below 0.5. The word must be a code of
   :mod:`labauto.vision.marker_codes` (even weight, so one wrong bit never gives another id),
   the ink-paper contrast at least ``min_contrast`` and every bit at least ``min_margin`` from
   the threshold (in units of half the contrast): rectangles, plain dots and artefacts get no
   id. The best read of each id is kept.
5. **Sub-pixel circles and perspective-bias correction**
   (:mod:`labauto.vision.marker_edges`): the centre circle and the code ring's outer edge are
   measured again along rays laid out in the read's frame (the moment of each edge profile),
   each fitted with the geometric ellipse fit (orthogonal distances, Ahn's method), and the
   image of their common centre (the best-conditioned pair; the ring's inner edge is measured
   to stand in only where the outer one fails) is the eigenvector construction of
   :mod:`labauto.vision.concentric`, exact under any homography. With no usable ring fit, or a
   correction larger than any perspective makes (``MAX_BIAS_SHARE`` of the semi-minor axis
   plus ``MAX_BIAS_PX``), the centre is the centre circle's ellipse centre and
   ``bias_corrected`` is False. ``ellipse`` is the re-measured centre circle; where there is
   none (``correct_bias=False``, or a failed re-measure) it is the geometric fit of the DES
   contour (:func:`labauto.vision.ellipse_fit.fit_selected_ellipses`).

Markers must be seen from their printed side: a mirrored marker (seen through a transparent
sheet, or drawn by a map that flips orientation) reads its ring backwards, which is in general
the word of another valid code, so it gets a wrong id.

``score`` is the smallest bit margin (0..1) times the contrast share (contrast / 255, capped at
1 after doubling): 1 is a perfect read.

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down. Works on any
sub-image (a tracker's window): positions are in that array's pixels.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, fields, replace

import cv2
import numpy as np

from labauto.vision.contours import Contours
from labauto.vision.detector import DetectorParams, extract_contours, validate_params
from labauto.vision.ellipse import Ellipse
from labauto.vision.ellipse_fit import fit_ellipses_algebraic_batch, fit_selected_ellipses
from labauto.vision.image import as_grey
from labauto.vision.marker_codes import N_BITS, RING_OUTER, decode_words
from labauto.vision.marker_codes import warm as warm_codes
from labauto.vision.marker_edges import affine_frames, refine_circles, ring_rows
from labauto.vision.shape_angle import shape_angles

#: Samples per sector along the ring, and the ring radii sampled (centre radii).
SAMPLES_PER_BIT = 8
READ_RADII = (2.35, 2.65)
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
        The fit of the code ring's edge that ``center`` came from: the outer edge, or the inner
        one where it stood in for a failed outer one (empty when not ``bias_corrected``).
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
        HxW grey or HxWx3 BGR (HxWx4 BGRA) image, read by the rules of
        :func:`labauto.vision.image.as_image` (uint8, or float on a 0-1 or 0-255 scale); any
        sub-image works.
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
    grey = as_grey(image)
    contours = extract_contours(grey, params.detector_params())
    markers = _markers(grey, contours, params) if len(contours) else []
    elapsed = (time.perf_counter() - start) * 1e3
    return MarkerResult(grey.shape[1], grey.shape[0], elapsed, markers)


# ------------------------------------------------------------------------------ the steps


def _sample(
    grey: np.ndarray, centres: np.ndarray, maps: np.ndarray, unit: np.ndarray
) -> np.ndarray:
    """Bilinear grey values at ``centre + map @ unit`` for every frame: (K, M), float32."""
    m = maps.astype(np.float32)
    u, v = unit[:, 0].astype(np.float32), unit[:, 1].astype(np.float32)
    c = centres.astype(np.float32)
    mx = c[:, :1] + m[:, 0, :1] * u + m[:, 0, 1:] * v
    my = c[:, 1:] + m[:, 1, :1] * u + m[:, 1, 1:] * v
    out = cv2.remap(grey, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.astype(np.float32)


@functools.cache
def _read_points() -> tuple[np.ndarray, tuple[int, int]]:
    """Unit-circle frame points sampled by the code read: 8 per ink radius, 24 per paper radius
    and ``N_BITS * SAMPLES_PER_BIT`` per ring radius, in that order, and where the paper and
    the ring points start."""

    def circle(radii: tuple[float, ...], n: int) -> np.ndarray:
        t = 2.0 * np.pi * (np.arange(n) + 0.5) / n
        return np.concatenate([np.column_stack((r * np.cos(t), r * np.sin(t))) for r in radii])

    parts = (
        circle(INK_RADII, 8),
        circle(PAPER_RADII, 24),
        circle(READ_RADII, N_BITS * SAMPLES_PER_BIT),
    )
    return np.concatenate(parts), (len(parts[0]), len(parts[0]) + len(parts[1]))


def _medians(values: np.ndarray) -> np.ndarray:
    """Row medians (a sort of short rows: quicker than ``np.median`` here)."""
    ordered = np.sort(values, axis=1)
    n = ordered.shape[1]
    return (ordered[:, (n - 1) // 2].astype(np.float64) + ordered[:, n // 2]) / 2.0


def _sector_means(level: np.ndarray) -> np.ndarray:
    """(K, S, N_BITS) mean level of every sector for every phase p of S: sector k of phase p
    is ring samples ``k*S + p + 1 .. k*S + p + S - 2`` (the sector without one sample at each
    end), cyclically."""
    s = SAMPLES_PER_BIT
    k, n = level.shape
    width = s - 2
    # moving sums over ``width`` samples starting at each sample (cyclic), by cumulative sums
    cum = np.zeros((k, n + width))
    np.cumsum(np.concatenate((level, level[:, : width - 1]), axis=1), axis=1, out=cum[:, 1:])
    sums = cum[:, width:] - cum[:, :n]  # sums[:, j] = level[:, j .. j + width - 1]
    # the window of phase p, sector k starts at k*S + p + 1
    return np.roll(sums, -1, axis=1).reshape(k, N_BITS, s).transpose(0, 2, 1) / width


def _read_codes(
    grey: np.ndarray, rows: np.ndarray, params: MarkerParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Ids (-1: no code), scores, code bit-0 directions (rad), bits as read and where read bit 0
    starts (rad), all in the rectified frames of the ellipse rows ``(cx, cy, a, b, angle)``."""
    k = len(rows)
    centres, maps = affine_frames(rows)
    n_ring = N_BITS * SAMPLES_PER_BIT
    points, (paper_at, ring_at) = _read_points()
    samples = _sample(grey, centres, maps, points)  # one remap for all
    ink = _medians(samples[:, :paper_at])
    paper = _medians(samples[:, paper_at:ring_at])
    contrast = paper - ink
    lit = np.flatnonzero(np.abs(contrast) >= params.min_contrast)
    ids = np.full(k, -1)
    score = np.zeros(k)
    bit0 = np.zeros(k)
    bits = np.zeros((k, N_BITS), bool)
    start = np.zeros(k)
    if lit.size == 0:
        return ids, score, bit0, bits, start
    ring = samples[lit, ring_at:].reshape(len(lit), len(READ_RADII), n_ring).mean(axis=1)
    level = (ring - ink[lit, None]) / contrast[lit, None]  # 0 ink .. 1 paper
    # every phase p at once: (lit, phase, sector) means; the phase with the most decisive
    # weakest bit wins (the first such phase on a tie)
    means = _sector_means(level)
    margins = np.min(np.abs(means - 0.5), axis=2) * 2.0
    phase = np.argmax(margins, axis=1)
    margin = margins[np.arange(len(lit)), phase]
    read = means[np.arange(len(lit)), phase] < 0.5
    words = (read.astype(np.int64) << np.arange(N_BITS)).sum(axis=1)
    found, turns = decode_words(words)
    ok = margin >= params.min_margin
    s = SAMPLES_PER_BIT
    ids[lit] = np.where(ok, found, -1)
    score[lit] = margin * np.minimum(np.abs(contrast[lit]) * 2.0 / 255.0, 1.0)
    # read bit i starts at angle (i*S + p) * 2 pi / n_ring; the code's bit 0 is read bit -turns
    bit0[lit] = ((-turns) % N_BITS * s + phase) * 2.0 * np.pi / n_ring
    bits[lit] = read
    start[lit] = phase * 2.0 * np.pi / n_ring  # where read bit 0 starts
    return ids, score, bit0, bits, start


def _plausible(rows: np.ndarray, shape: tuple[int, ...], params: MarkerParams) -> np.ndarray:
    """(K,) bool: ellipse rows ``(cx, cy, a, b, angle)`` of a centre circle's size (and not
    flatter than 1:4) whose code ring lies inside the image (False for NaN rows)."""
    cx, cy, a, b = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
    h, w = shape[:2]
    reach = RING_OUTER * a + 1
    return (
        (a >= params.min_radius_px)
        & (a <= params.max_radius_px)
        & (b >= 0.25 * a)
        & (cx - reach >= 0)
        & (cy - reach >= 0)
        & (cx + reach <= w - 1)
        & (cy + reach <= h - 1)
    )


def _candidates(
    grey: np.ndarray, contours: Contours, params: MarkerParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """DES centroids of all contours, and the indices and algebraic ellipse rows of the DES of
    a plausible size whose code ring lies inside the image."""
    angles = shape_angles(contours.points, contours.gradients, contours.offsets, contours.closed)
    des = angles.is_des(params.des_threshold_deg)
    # cheap size test before fitting: the DES's extent from its area
    radius = np.sqrt(np.maximum(angles.area, 0.0) / np.pi)
    des &= (radius >= params.min_radius_px * 0.5) & (radius <= params.max_radius_px * 1.2)
    index = np.flatnonzero(des)
    # the algebraic fit of every contour (cheaper than gathering the DES), good to a small
    # fraction of a sector for the code read; the geometric fit waits for the markers
    rows = fit_ellipses_algebraic_batch(contours.points, contours.offsets)[index]
    keep = _plausible(rows, grey.shape, params)
    return np.asarray(angles.centroid), index[keep], rows[keep]


def _best_reads(ids: np.ndarray, score: np.ndarray) -> list[tuple[int, int]]:
    """``(id, candidate)`` of the best read of every id found, by id."""
    best: dict[int, int] = {}
    for j, marker_id in enumerate(ids.tolist()):
        if marker_id >= 0 and (marker_id not in best or score[j] > score[best[marker_id]]):
            best[marker_id] = j
    return sorted(best.items())


def _markers(grey: np.ndarray, contours: Contours, params: MarkerParams) -> list[Marker]:
    centroids, index, rows = _candidates(grey, contours, params)
    if not len(index):
        return []
    ids, score, bit0, bits, start = _read_codes(grey, rows, params)
    chosen = _best_reads(ids, score)
    if not chosen:
        return []
    picked = np.array([j for _, j in chosen], np.int64)
    k = len(picked)
    circles, centres = np.full((k, 3, 5), np.nan), np.full((k, 2), np.nan)
    if params.correct_bias:
        pixels = grey.astype(np.float32)  # sampled at sub-pixel positions from here on
        circles, centres = refine_circles(
            pixels, rows[picked], bits[picked], start[picked], params.min_contrast
        )
    # the geometric fit of the centre circle's contour where the re-measure gave none
    ellipses = circles[:, 0].copy()
    need = np.flatnonzero(~np.isfinite(ellipses[:, 0]))
    if need.size:
        mask = np.zeros(len(contours), bool)
        mask[index[picked[need]]] = True
        first = fit_selected_ellipses(
            contours.points, contours.offsets, mask, max_iter=10, tol=1e-7
        )
        for j in need.tolist():
            e = first[index[picked[j]]]
            if e is not None:
                ellipses[j] = (*e.center, *e.axes, e.angle)
    # the size and the ring's room were judged on the fit the code was read in (a second
    # test here would drop a marker read at the border, or at the least radius, for a few
    # hundredths of a pixel between the fits); only a marker with no fit at all is dropped
    keep = np.flatnonzero(np.isfinite(ellipses[:, 0]))
    # a bias larger than any perspective makes is a failed ring fit
    bias = np.hypot(*(centres - ellipses[:, :2]).T)
    corrected = np.isfinite(bias) & (bias <= MAX_BIAS_SHARE * ellipses[:, 3] + MAX_BIAS_PX)
    centres = np.where(corrected[:, None], centres, ellipses[:, :2])
    # the ring fit the centre came from (finite wherever the centre was corrected)
    rings = ring_rows(circles)
    # plain Python values from here on (numpy scalars are slow one at a time)
    columns = zip(
        [chosen[j][0] for j in keep.tolist()],
        centres[keep].tolist(),
        centroids[index[picked[keep]]].tolist(),
        ellipses[keep].tolist(),
        score[picked[keep]].tolist(),
        np.degrees(bit0[picked[keep]]).tolist(),
        corrected[keep].tolist(),
        rings[keep].tolist(),
        strict=True,
    )
    return [
        Marker(
            id=marker_id,
            center=(x, y),
            centroid=(cx, cy),
            ellipse=Ellipse.normalised(*e),
            score=read_score,
            rotation_deg=rotation,
            bias_corrected=ok,
            ring_ellipses=(Ellipse.normalised(*ring),) if ok else (),
        )
        for marker_id, (x, y), (cx, cy), e, read_score, rotation, ok, ring in columns
    ]
