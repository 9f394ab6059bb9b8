"""Image sequences of a moving rigid marker set with exact truth (tracking tests, benchmarks).

A board of coded markers (rows x cols at ``pitch_mm``, ids from ``first_id``) moves in front
of a pinhole camera with OpenCV's distortion model: it swings sideways and up and down (far
enough, with ``amplitude_mm``, to leave the view and come back), turns and tilts (perspective),
and comes closer and goes away. Each frame is drawn with the exact-coverage marker renderer of
:mod:`labauto.synthetic.markers` through the camera (``camera_map``), then optionally:

* **motion blur** (``motion_blur``): a line kernel along the board's mean image motion during
  the exposure (``exposure`` of the frame interval; the mean displacement of the marker
  centres between its start and end), symmetric about the frame's instant, so the truth stays
  the centres at that instant (exact for a translation, an approximation for turns);
* **light changes**: a gain that drifts over time and across the image;
* **an occluder**: a grey bar crossing the view;
* **noise**: Gaussian, ``noise_sigma`` grey levels.

The truth of a frame is the true image centre of every marker, and which are *visible*: the
whole marker (code ring included, with a 2 px margin) inside the image and clear of the
occluder. The pose of the board (``rvec``, ``tvec``, board to camera, mm) is given too.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.synthetic.grey_look import GreyLook
from labauto.synthetic.markers import PlaneToImage, camera_map, draw_marker
from labauto.vision.marker_codes import QUIET_RADIUS, RING_OUTER

__all__ = ["SequenceFrame", "SequenceSpec", "board_points", "mean_motion", "render_sequence"]


@dataclass(frozen=True)
class SequenceSpec:
    """What to render (see the module docstring)."""

    rows: int = 5
    cols: int = 7
    pitch_mm: float = 45.0
    radius_mm: float = 5.0
    first_id: int = 0
    width: int = 1280
    height: int = 1024
    focal_px: float = 1400.0
    dist_coeffs: tuple[float, ...] = (-0.05, 0.01, 0.0, 0.0, 0.0)
    distance_mm: float = 700.0
    amplitude_mm: tuple[float, float] = (120.0, 60.0)
    tilt_deg: float = 30.0
    period_frames: float = 120.0
    motion_blur: bool = False
    exposure: float = 0.5
    noise_sigma: float = 2.0
    light: bool = True
    occluder: bool = False
    paper: float = 215.0
    ink: float = 25.0

    @property
    def camera_matrix(self) -> np.ndarray:
        """The camera's intrinsics."""
        f = self.focal_px
        return np.array([[f, 0, self.width / 2 - 0.5], [0, f, self.height / 2 - 0.5], [0, 0, 1.0]])

    @property
    def look(self) -> GreyLook:
        """Paper, ink and noise of the frames (motion blur is the sequence's own)."""
        return GreyLook(self.paper, self.ink, noise_sigma=self.noise_sigma)


@dataclass(frozen=True)
class SequenceFrame:
    """One rendered frame and its truth."""

    index: int
    image: np.ndarray
    centers: dict[int, tuple[float, float]]
    visible: frozenset[int]
    rvec: np.ndarray
    tvec: np.ndarray


def board_points(spec: SequenceSpec) -> dict[int, tuple[float, float, float]]:
    """``{id: (x, y, 0)}`` of the board's markers in mm, centred on the board's middle."""
    out = {}
    for r in range(spec.rows):
        for c in range(spec.cols):
            x = (c - (spec.cols - 1) / 2) * spec.pitch_mm
            y = (r - (spec.rows - 1) / 2) * spec.pitch_mm
            out[spec.first_id + r * spec.cols + c] = (x, y, 0.0)
    return out


def board_pose(spec: SequenceSpec, t: float) -> tuple[np.ndarray, np.ndarray]:
    """The board's pose at (fractional) frame ``t``: Rodrigues vector and translation (mm)."""
    w = 2 * np.pi * t / spec.period_frames
    tilt = np.deg2rad(spec.tilt_deg)
    rvec = np.array([tilt * np.sin(0.7 * w + 0.3), tilt * np.sin(w), 0.4 * np.sin(0.5 * w)])
    ax, ay = spec.amplitude_mm
    tvec = np.array(
        [ax * np.sin(w), ay * np.sin(1.3 * w + 0.5), spec.distance_mm + 80 * np.sin(0.6 * w)]
    )
    return rvec, tvec


def _occluder(spec: SequenceSpec, t: float) -> tuple[int, int, int, int]:
    """A vertical bar crossing the view from left to right once per period."""
    phase = (t / spec.period_frames) % 1.0
    x0 = int(-200 + phase * (spec.width + 400))
    return (x0, 0, x0 + 90, spec.height)


def mean_motion(
    spec: SequenceSpec, points: dict[int, tuple[float, float, float]], t: float
) -> np.ndarray:
    """Mean image displacement of the markers during the exposure around frame ``t``."""
    k, d = spec.camera_matrix, np.asarray(spec.dist_coeffs, np.float64)
    xy = np.array([(x, y) for x, y, _z in points.values()])
    ends = []
    for dt in (-spec.exposure / 2, spec.exposure / 2):
        rvec, tvec = board_pose(spec, t + dt)
        ends.append(camera_map(k, d, rvec, tvec)(xy))
    return (ends[1] - ends[0]).mean(axis=0)


def _motion_blur(image: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """Blur along ``motion`` (pixels) with a normalised line kernel centred on the pixel."""
    length = float(np.hypot(*motion))
    if length < 0.5:
        return image
    half = int(np.ceil(length / 2)) + 1
    kernel = np.zeros((2 * half + 1, 2 * half + 1), np.float32)
    for s in np.linspace(-0.5, 0.5, max(int(4 * length), 2)):
        x, y = half + s * motion[0], half + s * motion[1]
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0
        kernel[y0, x0] += (1 - fx) * (1 - fy)
        kernel[y0, x0 + 1] += fx * (1 - fy)
        kernel[y0 + 1, x0] += (1 - fx) * fy
        kernel[y0 + 1, x0 + 1] += fx * fy
    kernel /= kernel.sum()
    return cv2.filter2D(image, -1, kernel, borderType=cv2.BORDER_REPLICATE)


#: ``painter(image, id, (x, y) mm, radius_mm, to_image, ink)`` draws another kind of marker
#: (e.g. an ArUco square for a comparison) in a marker's place.
Painter = Callable[[np.ndarray, int, tuple[float, float], float, PlaneToImage, float], None]


def render_sequence(
    spec: SequenceSpec,
    n_frames: int,
    rng: np.random.Generator,
    start: int = 0,
    painter: Painter | None = None,
) -> Iterator[SequenceFrame]:
    """Render frames ``start .. start + n_frames - 1`` (see the module docstring)."""
    points = board_points(spec)
    k, d = spec.camera_matrix, np.asarray(spec.dist_coeffs, np.float64)
    outline = np.column_stack(
        (np.cos(np.linspace(0, 2 * np.pi, 24)), np.sin(np.linspace(0, 2 * np.pi, 24)))
    )
    xx = np.arange(spec.width)[None, :]
    look = spec.look
    for index in range(start, start + n_frames):
        rvec, tvec = board_pose(spec, index)
        to_image = camera_map(k, d, rvec, tvec)
        image = look.canvas((spec.width, spec.height))
        centers: dict[int, tuple[float, float]] = {}
        extents: dict[int, np.ndarray] = {}
        for mid, (x, y, _z) in points.items():
            extents[mid] = to_image(np.array([x, y]) + RING_OUTER * spec.radius_mm * outline)
            quiet = to_image(np.array([x, y]) + QUIET_RADIUS * spec.radius_mm * outline)
            cx, cy = to_image(np.array([[x, y]]))[0]
            centers[mid] = (float(cx), float(cy))
            lo, hi = quiet.min(axis=0), quiet.max(axis=0)
            if hi[0] < 0 or hi[1] < 0 or lo[0] > spec.width - 1 or lo[1] > spec.height - 1:
                continue
            if painter is None:
                draw_marker(image, mid, (x, y), spec.radius_mm, to_image=to_image, ink=look.ink)
            else:
                painter(image, mid, (x, y), spec.radius_mm, to_image, look.ink)
        if spec.motion_blur:
            image = _motion_blur(image, mean_motion(spec, points, index))
        if spec.light:
            phase = 2 * np.pi * index / spec.period_frames
            gain = 0.85 + 0.15 * np.sin(phase) + 0.1 * np.cos(phase) * (xx / spec.width - 0.5)
            image = image * gain
        box = _occluder(spec, index) if spec.occluder else None
        if box is not None:
            image[:, max(box[0], 0) : max(min(box[2], spec.width), 0)] = 0.6 * spec.paper
        visible = set()
        for mid, ring in extents.items():
            lo, hi = ring.min(axis=0), ring.max(axis=0)
            inside = (
                lo[0] >= 2 and lo[1] >= 2 and hi[0] <= spec.width - 3 and hi[1] <= spec.height - 3
            )
            clear = box is None or hi[0] < box[0] - 2 or lo[0] > box[2] + 2
            if inside and clear:
                visible.add(mid)
        yield SequenceFrame(
            index,
            look.develop(image, rng),
            centers,
            frozenset(visible),
            rvec,
            tvec,
        )
