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
    A square of half-size ``extent + margin_px + min(speed_gain * |v| * dt + grow_px * missed,
    max_allowance_px)`` around the prediction. ``extent`` is what must be seen of the marker,
    its centre circle's radius times ``extent_factor``: 1.6 by default (the centre circle and
    its edge, all the DES centroid needs), 3.6 when the whole marker is read in the window
    (``fit=True`` or a detector of one's own: code ring and quiet zone). So the window holds
    that much of the marker wherever it is within the allowance. The allowance is the prediction
    error the window tolerates: ``margin_px`` for an acceleration from standstill and for
    jitter, and a share of the speed (``speed_gain``; 0.5: the velocity may change by half
    between two frames) since faster motion changes more. A marker just found has no velocity
    yet; its allowance is ``initial_speed_px`` per frame in full (it may move that fast in any
    direction). Windows are clipped to the frame; windows that overlap are merged into one; all
    of them are packed into one mosaic and the detector runs once
    (:mod:`labauto.vision.roi_mosaic`).
Full-frame search
    On the first frame, every ``full_interval`` frames (so markers entering the view are picked
    up within ``full_interval`` frames: a marker that re-enters is reported in the next
    full-frame search), and in the same frame whenever a marker seen in the previous frame is
    not found in its window (it may have moved past its window, e.g. a jerk, or left the view):
    then the windowed results are discarded and the frame is searched whole (``mode`` is
    ``"full"``). A marker missing from the full-frame search too is *lost*; its track coasts
    for ``coast_frames`` frames (15: searched in a window growing by ``grow_px`` per missed
    frame, which re-finds a marker coming out from behind an occluder without waiting for the
    next full-frame search; a window outside the frame costs nothing), then it is forgotten
    until a full-frame search finds it again.
Searching
    By default (DES centroids) a search finds the *centre candidates* of the searched pixels,
    the DES of a centre circle's size, with contours and the shape angle only
    (:func:`labauto.vision.marker_candidates.centre_candidates`, no fits, no code reads). A
    candidate continues the track of a marker seen in the previous frame when it is the one
    candidate near that marker's prediction: within the allowance and within one centre radius +
    1 px (nearer than the code ring's sectors, which can pass for a centre circle; further off,
    the code decides), whole (its area centroid and the mean of its contour points within 0.45
    px + 0.02 radii: a circle cut by an occluder or the frame edge is not centrally symmetric, a
    projected, blurred circle is), with an area-equivalent radius within 0.8-1.25 of the
    marker's reference radius (which follows a candidate only when within 8 %, so a circle
    covered bit by bit cannot drag it along; a code read resets it), and the next candidate more
    than twice as far plus 2 px; and it is near no other marker's prediction. Codes are read, by
    the whole detector in small windows
    (:func:`~labauto.vision.marker_candidates.read_markers_at`), only where that does not
    decide: a candidate two markers compete for or a marker with two candidates, a candidate in
    the window of a lost (coasting) marker, and in a full-frame search every whole candidate no
    marker took (new markers). With ``fit=True`` (fitted, bias-corrected centres) or a detector
    of one's own, every search runs the whole detector on the searched pixels instead.
Id-swap guard
    A marker's identity is its decoded code: a coded detection can only continue the track of
    its own id, never another's, and a track is taken up by position only from one frame to the
    next (a marker seen in the previous frame, with one clear candidate that no other marker
    claims); a lost marker is taken up again only by its code. Beyond that, (1) in a window only
    a detection of the window's own id counts, and only inside the window; (2) when one id is
    found at more than one place, the one nearest the prediction is taken for a track that was
    seen in the previous frame, and for a new track the id is not reported at all unless the
    places are within the marker's own radius (the same marker found twice); (3) a detection of
    a tracked id (seen in the previous frame) further than ``gate_factor`` window half-sizes
    from its prediction and inside another marker's window is taken for that marker's code
    misread, not for a jump, and rejected (far from every other marker it is taken for a jump);
    (4) a new id found inside the window of a tracked marker of another id is taken for that
    marker misread, and rejected. So a misread code can at worst lose a marker for a frame; it
    cannot move another marker's id.

A detector of one's own is any function ``detect(image) -> markers`` whose markers have
``id``, ``centroid`` (the DES centroid, the paper's choice and the default centre), ``center``
(the fitted, bias-corrected centre, taken with ``fit=True``) and ``ellipse`` (with ``axes``),
as :func:`labauto.vision.markers.detect_markers` gives; it must work on any sub-image.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
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
    radius: float
    last_frame: int
    known_velocity: bool = False
    missed: int = 0


@dataclass(frozen=True)
class _Obs:
    """A detection in frame pixels: a coded marker (``id``) or a centre candidate (``None``)."""

    id: int | None
    position: np.ndarray
    radius: float
    whole: bool = True  # a centre candidate that is centrally symmetric (not cut off)


@dataclass
class TrackerStats:
    """Counts kept over a sequence (for benchmarks and tests)."""

    frames: int = 0
    full_searches: int = 0
    fallbacks: int = 0
    code_reads: int = 0
    rejected_jumps: int = 0
    ambiguous: int = 0
    window_pixels: list[int] = field(default_factory=list)


class MarkerTracker:
    """Track coded markers frame by frame (see the module docstring for the design).

    Parameters
    ----------
    detect : callable, optional
        ``detect(image) -> list of markers`` run on every searched image instead of the
        default search (centre candidates, codes read where needed).
    fit : bool
        Report fitted, bias-corrected centres (``marker.center``, the whole detector on every
        searched image) instead of DES centroids.
    full_interval : int
        A full-frame search every this many frames (1: every frame is searched whole).
    extent_factor : float, optional
        What of a marker a window must hold, in centre radii (default 1.6, or 3.6 when the
        whole marker is detected in the window).
    margin_px, speed_gain, initial_speed_px, grow_px, max_allowance_px : float
        The window allowance (module docstring).
    coast_frames : int
        Frames a lost marker is still searched in a window around its prediction.
    gate_factor : float
        A tracked id found further than this many window half-sizes from its prediction, in
        another marker's window, is rejected as a misread.
    **detect_options
        Fields of :class:`labauto.vision.markers.MarkerParams` for the built-in search.

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
        extent_factor: float | None = None,
        margin_px: float = 6.0,
        speed_gain: float = 0.5,
        initial_speed_px: float = 12.0,
        grow_px: float = 4.0,
        max_allowance_px: float = 120.0,
        coast_frames: int = 15,
        gate_factor: float = 4.0,
        **detect_options: Any,
    ) -> None:
        from labauto.vision.marker_codes import QUIET_RADIUS
        from labauto.vision.markers import find_markers, marker_params

        if full_interval < 1:
            raise ValueError(f"full_interval must be >= 1, got {full_interval}")
        if coast_frames < 0:
            raise ValueError(f"coast_frames must be >= 0, got {coast_frames}")
        self._candidates = detect is None and not fit
        if extent_factor is None:
            extent_factor = 1.6 if self._candidates else QUIET_RADIUS
        for name, value in (
            ("extent_factor", extent_factor),
            ("margin_px", margin_px),
            ("speed_gain", speed_gain),
            ("initial_speed_px", initial_speed_px),
            ("grow_px", grow_px),
            ("max_allowance_px", max_allowance_px),
            ("gate_factor", gate_factor),
        ):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if detect is not None and detect_options:
            raise TypeError("detect_options are for the built-in search only")
        self.params = marker_params(**detect_options)
        if detect is None:
            params = self.params

            def detect(image: np.ndarray) -> Sequence[MarkerLike]:
                return find_markers(image, params).markers

        self.detect = detect
        self.fit = fit
        self.full_interval = int(full_interval)
        self.extent_factor = float(extent_factor)
        self.margin_px = float(margin_px)
        self.speed_gain = float(speed_gain)
        self.initial_speed_px = float(initial_speed_px)
        self.grow_px = float(grow_px)
        self.max_allowance_px = float(max_allowance_px)
        self.coast_frames = int(coast_frames)
        self.gate_factor = float(gate_factor)
        self.reset()

    # -- public --------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget every track (the next frame is searched whole)."""
        self._tracks: dict[int, _Track] = {}
        self._frame = 0
        self._last_full = -(10**9)
        self._previous: set[int] = set()
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
            The frame, grey (H, W) or colour (H, W, 3, BGR), ``uint8`` (or float 0-255).
        """
        from labauto.vision.marker_candidates import grey_image

        started = time.perf_counter()
        grey = grey_image(image) if self._candidates else np.asarray(image)
        if grey.ndim not in (2, 3) or grey.shape[0] == 0 or grey.shape[1] == 0:
            raise ValueError(f"expected an (H, W) or (H, W, C) image, got shape {grey.shape}")
        index = self._frame
        due = not self._tracks or index - self._last_full >= self.full_interval
        mode = "full"
        if due:
            found = self._search(grey, full=True)
        else:
            found = self._search(grey, full=False)
            expected = [t.id for t in self._tracks.values() if t.missed == 0]
            if any(tid not in found for tid in expected):
                self.stats.fallbacks += 1
                found = self._search(grey, full=True)
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
    def _search(self, frame: np.ndarray, *, full: bool) -> dict[int, _Obs]:
        """Search the whole frame or the windows of the tracks; the markers found by id."""
        if full:
            self._last_full = self._frame
            self.stats.full_searches += 1
            return self._associate(self._observe(frame), frame, windows=None)
        height, width = frame.shape[:2]
        windows: dict[int, Rect] = {}
        for track in self._tracks.values():
            rect = clip_rect(self._window(track), width, height)
            if rect is not None:
                windows[track.id] = rect
        if not windows:
            return {}
        mosaic = build_mosaic(frame, merge_overlapping(list(windows.values())))
        self.stats.window_pixels.append(int(mosaic.image.shape[0] * mosaic.image.shape[1]))
        inside = self._observe(mosaic.image)
        tiles = mosaic.owners(np.array([o.position for o in inside]).reshape(-1, 2))
        observed = [  # a tile of -1: in the padding, a piece of an object cut by its window
            _Obs(o.id, o.position - mosaic.offsets[t], o.radius, o.whole)
            for o, t in zip(inside, tiles.tolist(), strict=True)
            if t >= 0
        ]
        return self._associate(observed, frame, windows=windows)

    def _observe(self, image: np.ndarray) -> list[_Obs]:
        """Centre candidates (default) or coded markers (``fit`` or an own detector)."""
        if self._candidates:
            from labauto.vision.marker_candidates import centre_candidates

            found = centre_candidates(image, self.params)
            whole = found.asymmetry <= 0.45 + 0.02 * found.radii
            return [
                _Obs(None, found.centroids[i].copy(), float(found.radii[i]), bool(whole[i]))
                for i in range(len(found))
            ]
        return _present(self._coded(marker) for marker in self.detect(image))

    def _coded(self, marker: MarkerLike) -> _Obs | None:
        """The observation of a coded marker; ``None`` for a centre circle cut off in part.

        The centroid of a whole (projected) circle's contour is the centre of its ellipse; an
        occluder or the frame edge cutting the circle moves the two apart. With ``fit``, a
        bias-corrected centre further from the ellipse's centre than 0.25 px + 0.02 radii (more
        than perspective can move it at these sizes) is not trusted: the ellipse's centre is
        taken instead.
        """
        point = marker.center if self.fit else marker.centroid
        ellipse = marker.ellipse
        axes = getattr(ellipse, "axes", None)
        if axes is None and isinstance(ellipse, dict):
            axes = ellipse.get("axes")
        radius = float(axes[0]) if axes is not None else 5.0
        centre = getattr(ellipse, "center", None)
        if centre is not None:
            apart = math.hypot(centre[0] - marker.centroid[0], centre[1] - marker.centroid[1])
            if apart > 0.3 + 0.02 * radius:
                return None
            if self.fit and math.hypot(point[0] - centre[0], point[1] - centre[1]) > (
                0.25 + 0.02 * radius
            ):  # a perspective correction larger than any perspective bias: not trusted
                point = centre
        return _Obs(int(marker.id), np.array([float(point[0]), float(point[1])]), radius)

    def _associate(
        self, observed: list[_Obs], frame: np.ndarray, windows: dict[int, Rect] | None
    ) -> dict[int, _Obs]:
        """Markers found by id: candidates by position, then codes (module docstring)."""
        found: dict[int, _Obs] = {}
        coded = [o for o in observed if o.id is not None]
        candidates = [o for o in observed if o.id is None]
        if candidates:
            to_read = self._by_position(candidates, found, full=windows is None)
            if to_read:
                coded += self._read_codes(frame, to_read)
        for mid, places in _group_by_id(coded).items():
            hit = self._take_coded(mid, places, windows)
            if hit is not None:
                found[mid] = hit
        return found

    def _by_position(
        self, candidates: list[_Obs], found: dict[int, _Obs], full: bool
    ) -> list[_Obs]:
        """Give tracks seen in the previous frame their one clear candidate (into ``found``).

        Returns the candidates whose code must be read. Vectorised over tracks x candidates.
        """
        tracks = [t for t in self._tracks.values() if t.missed <= self.coast_frames]
        positions = np.array([c.position for c in candidates])
        radii = np.array([c.radius for c in candidates])
        whole = np.array([c.whole for c in candidates])
        if not tracks:
            eligible = np.zeros((0, len(candidates)), bool)
            missed = np.zeros(0, np.int64)
        else:
            predicted = np.array([self._prediction(t) for t in tracks])
            half = np.array([self._half_size(t) for t in tracks])
            radius = np.array([t.radius for t in tracks])
            missed = np.array([t.missed for t in tracks])
            delta = positions[None, :, :] - predicted[:, None, :]
            box = np.abs(delta).max(axis=2)
            euclid = np.hypot(delta[..., 0], delta[..., 1])
            reach = half - radius * self.extent_factor + 1.0
            # seen last frame: never as far as the code ring's sectors (2-3 radii out)
            continuing = missed == 0
            reach = np.where(continuing, np.minimum(reach, radius + 1.0), reach)
            offset = np.where(continuing[:, None], euclid, box)
            ratio = radii[None, :] / np.maximum(radius, 1e-6)[:, None]
            eligible = (
                (offset <= reach[:, None]) & whole[None, :] & (ratio >= 0.8) & (ratio <= 1.25)
            )
        claimed = eligible.sum(axis=0)
        to_read: set[int] = set()
        for row in np.flatnonzero(missed == 0):
            options = np.flatnonzero(eligible[row])
            if len(options) == 0:
                continue
            distance = euclid[row, options]
            order = np.argsort(distance)
            best = int(options[order[0]])
            clear = len(options) == 1 or distance[order[1]] > 2.0 * distance[order[0]] + 2.0
            if clear and claimed[best] == 1:
                found[tracks[row].id] = candidates[best]
            else:
                self.stats.ambiguous += 1
                to_read.update(np.flatnonzero(box[row] <= half[row]).tolist())
        taken = list(found.values())
        coasting = np.flatnonzero(eligible[missed > 0].any(axis=0)) if len(tracks) else []
        to_read.update(k for k in coasting if not _near_any(positions[k], taken))
        if full:
            for k in np.flatnonzero((claimed == 0) & whole).tolist():
                if not _near_any(positions[k], taken):
                    to_read.add(k)
        return [candidates[k] for k in sorted(to_read)]

    def _read_codes(self, frame: np.ndarray, candidates: list[_Obs]) -> list[_Obs]:
        """Read the codes at ``candidates`` with the whole detector (in frame pixels)."""
        from labauto.vision.marker_candidates import read_markers_at
        from labauto.vision.marker_codes import QUIET_RADIUS

        self.stats.code_reads += len(candidates)
        window_area = sum((2.6 * QUIET_RADIUS * c.radius + 8) ** 2 for c in candidates)
        if window_area > 0.5 * frame.shape[0] * frame.shape[1]:  # e.g. the first frame
            return _present(self._coded(m) for m in self.detect(frame))
        markers = read_markers_at(
            frame,
            np.array([c.position for c in candidates]),
            np.array([c.radius for c in candidates]),
            self.params,
        )
        return _present(self._coded(m) for m in markers)

    def _take_coded(
        self, mid: int, places: list[_Obs], windows: dict[int, Rect] | None
    ) -> _Obs | None:
        """The detection that continues (or starts) the track of ``mid``, with the guard."""
        track = self._tracks.get(mid)
        if windows is not None:
            if mid not in windows:
                return None  # another id in a window: left to the next full-frame search
            places = [p for p in places if _inside(p.position, windows[mid])]
            if not places:
                return None
        if track is not None and track.missed <= self.coast_frames:
            predicted = self._prediction(track)
            distances = [float(np.linalg.norm(p.position - predicted)) for p in places]
            hit = places[int(np.argmin(distances))]
            far = min(distances) > self.gate_factor * self._half_size(track)
            if track.missed == 0 and far and self._near_other_track(mid, hit.position):
                self.stats.rejected_jumps += 1
                return None
            return hit
        hit = places[0]
        spread = max(float(np.linalg.norm(p.position - hit.position)) for p in places)
        if spread > max(hit.radius * self.extent_factor, 1.0):
            self.stats.ambiguous += 1
            return None
        if self._near_other_track(mid, hit.position):
            self.stats.rejected_jumps += 1  # a new id where a tracked marker is: a misread
            return None
        return hit

    def _near_other_track(self, mid: int, position: np.ndarray) -> bool:
        """True when ``position`` is inside the window of another id's track."""
        for other in self._tracks.values():
            if other.id != mid and other.missed <= self.coast_frames:
                distance = float(np.max(np.abs(position - self._prediction(other))))
                if distance <= self._half_size(other):
                    return True
        return False

    # -- tracks --------------------------------------------------------------------------------
    def _apply(self, found: dict[int, _Obs], index: int) -> None:
        for mid, hit in found.items():
            track = self._tracks.get(mid)
            if track is None or track.missed > self.coast_frames:
                self._tracks[mid] = _Track(mid, hit.position, np.zeros(2), hit.radius, index)
                continue
            dt = index - track.last_frame
            track.velocity = (hit.position - track.position) / max(dt, 1)
            track.known_velocity = True
            track.position = hit.position
            if hit.id is not None or abs(hit.radius / track.radius - 1.0) <= 0.08:
                track.radius = hit.radius
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
        extent = track.radius * self.extent_factor
        allowance = min(allowance + self.grow_px * track.missed, self.max_allowance_px)
        return extent + self.margin_px + allowance

    def _window(self, track: _Track) -> Rect:
        cx, cy = self._prediction(track)
        half = self._half_size(track)
        return (
            math.floor(cx - half),
            math.floor(cy - half),
            math.ceil(cx + half) + 1,
            math.ceil(cy + half) + 1,
        )


def _present(observations: Iterable[_Obs | None]) -> list[_Obs]:
    return [o for o in observations if o is not None]


def _group_by_id(observed: list[_Obs]) -> dict[int, list[_Obs]]:
    groups: dict[int, list[_Obs]] = {}
    for obs in observed:
        groups.setdefault(int(obs.id), []).append(obs)  # type: ignore[arg-type]
    return groups


def _near_any(point: np.ndarray, found: list[_Obs]) -> bool:
    """True when ``point`` lies within the code ring of a marker already found (its sectors)."""
    from labauto.vision.marker_codes import QUIET_RADIUS

    return any(
        float(np.hypot(*(point - obs.position))) <= QUIET_RADIUS * obs.radius for obs in found
    )


def _inside(point: np.ndarray, rect: Rect) -> bool:
    """True when ``point`` lies in the pixels of ``rect`` (half-open, pixel-centre origin)."""
    x0, y0, x1, y1 = rect
    return bool(x0 - 0.5 <= point[0] <= x1 - 0.5 and y0 - 0.5 <= point[1] <= y1 - 0.5)
