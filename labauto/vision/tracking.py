"""Real-time tracking of coded markers through an image sequence (the paper's section 4.3).

The paper tracks about 35 coded markers on a moving car at 5 frames per second (210 ms per
1.3-Mpixel image, DES centroids as centres) and notes that "the computation speed can be
drastically increased if a search is only performed in a defined range that changes between two
images in a sequence". :class:`MarkerTracker` does that: each marker found in one frame is
searched in the next only inside a window around where its motion says it will be.

Design choices
--------------
Prediction model
    Constant velocity in the image: a marker seen at ``p`` with velocity ``v`` (pixels per
    frame, the displacement between its last two sightings divided by the frames between them)
    is predicted at ``p + v * dt``, ``dt`` the frames since it was last seen. No smoothing: the
    centres are precise to a few hundredths of a pixel, so the last displacement is the best
    estimate of the next one, and it follows a turn within one frame.
Window size
    A square of half-size ``extent + margin_px + speed_gain * |v| * dt + grow_px * missed``
    around the prediction. ``extent`` is the marker's own radius in the image (its fitted
    ellipse's semi-major axis times ``extent_factor``, the ratio of the whole marker, code ring
    included, to the ellipse the detector reports), so the window holds the whole marker
    wherever it is within the allowance. The allowance is the prediction error the window
    tolerates: ``margin_px`` for an acceleration from standstill and for jitter, and a share of
    the speed (``speed_gain``; 0.5: the velocity may change by half between two frames) since
    faster motion changes more. A marker just found has no velocity yet; its allowance is
    ``initial_speed_px`` per frame in full (it may move that fast in any direction). Windows
    are clipped to the frame; windows that overlap are merged into one; all of them are packed
    into one mosaic and the detector runs once (:mod:`labauto.vision.roi_mosaic`).
Full-frame search
    On the first frame, every ``full_interval`` frames (so markers entering the view are picked
    up within ``full_interval`` frames: a marker that re-enters is reported in the next
    full-frame search), and in the same frame whenever a marker seen in the previous frame is
    not found in its window (it may have moved past its window, e.g. a jerk, or left the view):
    then the windowed results are discarded and the frame is searched whole (``mode`` is
    ``"full"``). A marker missing from the full-frame search too is *lost*; its track coasts
    for ``coast_frames`` frames (searched in a window growing by ``grow_px`` per missed frame,
    which re-finds a marker after a short occlusion without waiting for the next full-frame
    search), then it is forgotten until a full-frame search finds it again.
Id-swap guard
    A marker's identity is its decoded code: a detection can only continue the track of its
    own id, never another's. Beyond that, (1) in a window only a detection of the window's own
    id counts, and only inside the window; (2) when one id is found at more than one place, the
    one nearest the prediction is taken for a track that was seen in the previous frame, and
    for a new track the id is not reported at all unless the places are within the marker's
    own radius (the same marker found twice); (3) a detection of a tracked id (seen in the
    previous frame) further than ``gate_factor`` window half-sizes from its prediction and
    inside another marker's window is taken for that marker's code misread, not for a jump,
    and rejected (far from every other marker it is taken for a jump). So a misread code can
    at worst lose a marker for a frame; it cannot move another marker's id.

The detector is any function ``detect(image) -> markers`` whose markers have ``id``,
``centroid`` (the DES centroid, the paper's choice and the default centre), ``center`` (the
fitted, bias-corrected centre, taken with ``fit=True``), ``ellipse`` (with ``axes``) and
``score``; the default is :func:`labauto.vision.markers.detect_markers` (imported when first
needed). It must work on any sub-image, as that detector does.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from labauto.vision.roi_mosaic import Rect, build_mosaic, clip_rect, merge_overlapping

__all__ = ["FrameResult", "MarkerLike", "MarkerTracker", "TrackedMarker"]


class MarkerLike(Protocol):
    """What the tracker reads from a detected marker."""

    @property
    def id(self) -> int: ...

    @property
    def center(self) -> Any: ...

    @property
    def centroid(self) -> Any: ...

    @property
    def ellipse(self) -> Any: ...


@dataclass(frozen=True)
class TrackedMarker:
    """One marker reported in a frame: its id and centre in frame pixels."""

    id: int
    center: tuple[float, float]

    def to_dict(self) -> dict[str, Any]:
        """``{"id": int, "center": [x, y]}``."""
        return {"id": int(self.id), "center": [float(self.center[0]), float(self.center[1])]}


@dataclass(frozen=True)
class FrameResult:
    """What the tracker found in one frame.

    Attributes
    ----------
    frame : int
        Index of the frame in the sequence (0 for the first).
    timing_ms : float
        Time spent on the frame (search and bookkeeping).
    mode : str
        ``"roi"`` (windowed search only) or ``"full"`` (the frame was searched whole).
    markers : list of TrackedMarker
        Markers found, ordered by id.
    lost : list of int
        Ids found in the previous frame and not in this one.
    appeared : list of int
        Ids found in this frame and not in the previous one.
    """

    frame: int
    timing_ms: float
    mode: str
    markers: list[TrackedMarker]
    lost: list[int]
    appeared: list[int]

    def to_dict(self) -> dict[str, Any]:
        """The JSON line of ``labauto track --json-lines``."""
        return {
            "frame": self.frame,
            "timing_ms": round(self.timing_ms, 3),
            "mode": self.mode,
            "markers": [m.to_dict() for m in self.markers],
            "lost": list(self.lost),
            "appeared": list(self.appeared),
        }

    def centers(self) -> dict[int, tuple[float, float]]:
        """``{id: (x, y)}`` of the markers found."""
        return {m.id: m.center for m in self.markers}


@dataclass
class _Track:
    id: int
    position: np.ndarray
    velocity: np.ndarray
    extent: float
    last_frame: int
    known_velocity: bool = False
    missed: int = 0


@dataclass
class _Found:
    position: np.ndarray
    extent: float


@dataclass
class TrackerStats:
    """Counts kept over a sequence (for benchmarks and tests)."""

    frames: int = 0
    full_searches: int = 0
    fallbacks: int = 0
    rejected_jumps: int = 0
    ambiguous: int = 0
    window_pixels: list[int] = field(default_factory=list)


class MarkerTracker:
    """Track coded markers frame by frame (see the module docstring for the design).

    Parameters
    ----------
    detect : callable, optional
        ``detect(image) -> list of markers``; default
        :func:`labauto.vision.markers.detect_markers` with ``detect_options``.
    fit : bool
        Report fitted, bias-corrected centres (``marker.center``) instead of DES centroids.
    full_interval : int
        A full-frame search every this many frames (1: every frame is searched whole).
    extent_factor : float
        Whole marker radius over the semi-major axis of the ellipse the detector reports.
    margin_px, speed_gain, initial_speed_px, grow_px : float
        The window allowance (module docstring).
    coast_frames : int
        Frames a lost marker is still searched in a window around its prediction.
    gate_factor : float
        A tracked id found further than this many window half-sizes from its prediction, in
        another marker's window, is rejected as a misread.
    **detect_options
        Passed to the default detector.

    Examples
    --------
    >>> tracker = MarkerTracker()  # doctest: +SKIP
    >>> for image in frames:  # doctest: +SKIP
    ...     result = tracker.update(image)
    ...     print(result.mode, result.centers())
    """

    def __init__(
        self,
        detect: Callable[[np.ndarray], Sequence[MarkerLike]] | None = None,
        *,
        fit: bool = False,
        full_interval: int = 10,
        extent_factor: float = 3.0,
        margin_px: float = 6.0,
        speed_gain: float = 0.5,
        initial_speed_px: float = 12.0,
        grow_px: float = 8.0,
        coast_frames: int = 3,
        gate_factor: float = 4.0,
        **detect_options: Any,
    ) -> None:
        if full_interval < 1:
            raise ValueError(f"full_interval must be >= 1, got {full_interval}")
        if coast_frames < 0:
            raise ValueError(f"coast_frames must be >= 0, got {coast_frames}")
        for name, value in (
            ("extent_factor", extent_factor),
            ("margin_px", margin_px),
            ("speed_gain", speed_gain),
            ("initial_speed_px", initial_speed_px),
            ("grow_px", grow_px),
            ("gate_factor", gate_factor),
        ):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if detect is None:
            detect = _default_detector(detect_options)
        elif detect_options:
            raise TypeError("detect_options are for the default detector only")
        self.detect = detect
        self.fit = fit
        self.full_interval = int(full_interval)
        self.extent_factor = float(extent_factor)
        self.margin_px = float(margin_px)
        self.speed_gain = float(speed_gain)
        self.initial_speed_px = float(initial_speed_px)
        self.grow_px = float(grow_px)
        self.coast_frames = int(coast_frames)
        self.gate_factor = float(gate_factor)
        self.stats = TrackerStats()
        self._tracks: dict[int, _Track] = {}
        self._frame = 0
        self._last_full = -(10**9)
        self._previous: set[int] = set()

    # -- public --------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget every track (the next frame is searched whole)."""
        self._tracks.clear()
        self._frame = 0
        self._last_full = -(10**9)
        self._previous = set()
        self.stats = TrackerStats()

    @property
    def frame_index(self) -> int:
        """Index the next frame will get."""
        return self._frame

    def predicted(self) -> dict[int, tuple[float, float]]:
        """Where each track expects its marker in the next frame."""
        return {tid: tuple(self._prediction(t)) for tid, t in self._tracks.items()}  # type: ignore[misc]

    def update(self, image: np.ndarray) -> FrameResult:
        """Search one frame and update the tracks.

        Parameters
        ----------
        image : ndarray
            The frame, grey (H, W) or colour (H, W, 3), ``uint8``.
        """
        started = time.perf_counter()
        image = np.asarray(image)
        if image.ndim not in (2, 3) or image.shape[0] == 0 or image.shape[1] == 0:
            raise ValueError(f"expected an (H, W) or (H, W, C) image, got shape {image.shape}")
        index = self._frame
        due = not self._tracks or index - self._last_full >= self.full_interval
        mode = "full"
        if due:
            found = self._search_full(image)
        else:
            found = self._search_windows(image)
            expected = [t.id for t in self._tracks.values() if t.missed == 0]
            if any(tid not in found for tid in expected):
                self.stats.fallbacks += 1
                found = self._search_full(image)
            else:
                mode = "roi"
        self._apply(found, index)
        markers = [
            TrackedMarker(tid, (float(f.position[0]), float(f.position[1])))
            for tid, f in sorted(found.items())
        ]
        now = set(found)
        lost = sorted(self._previous - now)
        appeared = sorted(now - self._previous)
        self._previous = now
        self._frame += 1
        self.stats.frames += 1
        elapsed = (time.perf_counter() - started) * 1000.0
        return FrameResult(index, elapsed, mode, markers, lost, appeared)

    # -- search --------------------------------------------------------------------------------
    def _search_full(self, image: np.ndarray) -> dict[int, _Found]:
        self._last_full = self._frame
        self.stats.full_searches += 1
        detections = [self._measure(m, 0.0, 0.0) for m in self.detect(image)]
        return self._associate(detections, windows=None)

    def _search_windows(self, image: np.ndarray) -> dict[int, _Found]:
        height, width = image.shape[:2]
        ids, rects = [], []
        for track in self._tracks.values():
            rect = clip_rect(self._window(track), width, height)
            if rect is not None:
                ids.append(track.id)
                rects.append(rect)
        if not rects:
            return {}
        merged = merge_overlapping(rects)
        mosaic = build_mosaic(image, merged)
        self.stats.window_pixels.append(int(mosaic.image.shape[0] * mosaic.image.shape[1]))
        detections = []
        for marker in self.detect(mosaic.image):
            point = self._center_of(marker)
            tile = mosaic.owner_of(point)
            if tile is None:
                continue  # in the padding: a piece of an object cut by its window
            dx, dy = mosaic.offsets[tile]
            detections.append(self._measure(marker, float(dx), float(dy)))
        windows = {tid: rects[i] for i, tid in enumerate(ids)}
        return self._associate(detections, windows=windows)

    def _associate(
        self,
        detections: list[tuple[int, np.ndarray, float]],
        windows: dict[int, Rect] | None,
    ) -> dict[int, _Found]:
        """Assign detections to ids with the id-swap guard of the module docstring."""
        by_id: dict[int, list[tuple[np.ndarray, float]]] = {}
        for mid, position, extent in detections:
            by_id.setdefault(mid, []).append((position, extent))
        found: dict[int, _Found] = {}
        for mid, places in by_id.items():
            track = self._tracks.get(mid)
            if windows is not None:
                if mid not in windows:
                    continue  # another id in a window: left to the next full-frame search
                x0, y0, x1, y1 = windows[mid]
                places = [p for p in places if _inside(p[0], (x0, y0, x1, y1))]
                if not places:
                    continue
            if track is not None and track.missed <= self.coast_frames:
                predicted = self._prediction(track)
                distances = [float(np.linalg.norm(p[0] - predicted)) for p in places]
                best = int(np.argmin(distances))
                position, extent = places[best]
                far = distances[best] > self.gate_factor * self._half_size(track)
                if track.missed == 0 and far and self._near_other_track(mid, position):
                    self.stats.rejected_jumps += 1
                    continue
            else:
                position, extent = places[0]
                spread = max(float(np.linalg.norm(p[0] - position)) for p in places)
                if spread > max(extent, 1.0):
                    self.stats.ambiguous += 1
                    continue
            found[mid] = _Found(position, extent)
        return found

    def _near_other_track(self, mid: int, position: np.ndarray) -> bool:
        """True when ``position`` is inside the window of another id's track."""
        for other in self._tracks.values():
            if other.id != mid and other.missed <= self.coast_frames:
                distance = float(np.max(np.abs(position - self._prediction(other))))
                if distance <= self._half_size(other):
                    return True
        return False

    # -- tracks --------------------------------------------------------------------------------
    def _apply(self, found: dict[int, _Found], index: int) -> None:
        for mid, hit in found.items():
            track = self._tracks.get(mid)
            if track is None or track.missed > self.coast_frames:
                self._tracks[mid] = _Track(
                    mid, hit.position, np.zeros(2), hit.extent, index, known_velocity=False
                )
                continue
            dt = index - track.last_frame
            track.velocity = (hit.position - track.position) / max(dt, 1)
            track.known_velocity = True
            track.position = hit.position
            track.extent = hit.extent
            track.last_frame = index
            track.missed = 0
        for mid in list(self._tracks):
            if mid in found:
                continue
            track = self._tracks[mid]
            track.missed += 1
            if track.missed > self.coast_frames:
                del self._tracks[mid]

    def _prediction(self, track: _Track) -> np.ndarray:
        dt = self._frame - track.last_frame
        return track.position + track.velocity * dt

    def _half_size(self, track: _Track) -> float:
        dt = max(self._frame - track.last_frame, 1)
        if track.known_velocity:
            allowance = self.speed_gain * float(np.hypot(*track.velocity)) * dt
        else:  # no velocity yet: it may have moved initial_speed_px per frame, any way
            allowance = self.initial_speed_px * dt
        return track.extent + self.margin_px + allowance + self.grow_px * track.missed

    def _window(self, track: _Track) -> Rect:
        cx, cy = self._prediction(track)
        half = self._half_size(track)
        return (
            math.floor(cx - half),
            math.floor(cy - half),
            math.ceil(cx + half) + 1,
            math.ceil(cy + half) + 1,
        )

    # -- markers -------------------------------------------------------------------------------
    def _center_of(self, marker: MarkerLike) -> tuple[float, float]:
        point = marker.center if self.fit else marker.centroid
        return (float(point[0]), float(point[1]))

    def _measure(self, marker: MarkerLike, dx: float, dy: float) -> tuple[int, np.ndarray, float]:
        x, y = self._center_of(marker)
        axes = getattr(marker.ellipse, "axes", None)
        if axes is None and isinstance(marker.ellipse, dict):
            axes = marker.ellipse.get("axes")
        semi_major = float(axes[0]) if axes is not None else 5.0
        return int(marker.id), np.array([x - dx, y - dy]), semi_major * self.extent_factor


def _inside(point: np.ndarray, rect: Rect) -> bool:
    """True when ``point`` lies in the pixels of ``rect`` (half-open, pixel-centre origin)."""
    x0, y0, x1, y1 = rect
    return bool(x0 - 0.5 <= point[0] <= x1 - 0.5 and y0 - 0.5 <= point[1] <= y1 - 0.5)


def _default_detector(options: dict[str, Any]) -> Callable[[np.ndarray], Sequence[MarkerLike]]:
    """:func:`labauto.vision.markers.detect_markers` with ``options`` (issue 14's detector)."""
    from labauto.vision.markers import detect_markers

    def detect(image: np.ndarray) -> Sequence[MarkerLike]:
        return detect_markers(image, **options)

    return detect
