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
    (:mod:`labauto.vision.roi_mosaic`). A coded marker found beyond its allowance, so that its
    window does not hold its extent (its code ring runs into the mosaic's padding and the ring
    fits behind the fitted centre are off, by 0.1 px and more), is searched again in a window
    of its own before it is taken (:meth:`~labauto.vision.tracking_search.MarkerSearch.
    in_windows`).
Full-frame search
    On the first frame, ``full_interval`` frames after the last full-frame search (so markers
    entering the view are picked up within ``full_interval`` frames: a marker that re-enters is
    reported in the next full-frame search), and in the same frame whenever a marker seen in
    the previous frame is not found in its window (it may have moved past its window, e.g. a
    jerk, or left the view):
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
    found at more than one place, the one nearest the prediction is taken for a track (seen in
    the previous frame or coasting), and for a new track the id is not reported at all unless
    the places are within ``extent_factor`` of its radii (at least 1 px) of the first (the
    same marker found twice); (3) a detection of
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

Modules
-------
:mod:`~labauto.vision.tracking_types`
    The result types (:class:`FrameResult`, :class:`TrackedMarker`, :class:`TrackerStats`) and
    what is read from a detected marker (:class:`MarkerLike`); re-exported here.
:mod:`~labauto.vision.tracking_motion`
    Tracks, their constant-velocity prediction and their search windows.
:mod:`~labauto.vision.tracking_search`
    Searching pixels: a frame or a mosaic of windows, centre candidates or coded markers,
    code reads at candidates.
:mod:`~labauto.vision.tracking_assoc`
    Association of what was found with the tracks, and the id-swap guard.
This module: :class:`MarkerTracker`, the frame loop (when to search whole) and the tracks'
bookkeeping.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from labauto.vision.marker_candidates import grey_image
from labauto.vision.marker_codes import QUIET_RADIUS
from labauto.vision.markers import find_markers, marker_params
from labauto.vision.roi_mosaic import Rect, clip_rect
from labauto.vision.tracking_assoc import Association
from labauto.vision.tracking_motion import Track, WindowModel, follow
from labauto.vision.tracking_search import Detect, MarkerSearch, Obs
from labauto.vision.tracking_types import FrameResult, MarkerLike, TrackedMarker, TrackerStats

__all__ = ["FrameResult", "MarkerLike", "MarkerTracker", "TrackedMarker", "TrackerStats"]


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
        detect: Detect | None = None,
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
        if full_interval < 1:
            raise ValueError(f"full_interval must be >= 1, got {full_interval}")
        if coast_frames < 0:
            raise ValueError(f"coast_frames must be >= 0, got {coast_frames}")
        candidates = detect is None and not fit
        if extent_factor is None:
            extent_factor = 1.6 if candidates else QUIET_RADIUS
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
        params = marker_params(**detect_options)
        if detect is None:

            def detect(image: np.ndarray) -> Sequence[MarkerLike]:
                return find_markers(image, params).markers

        self.full_interval = int(full_interval)
        self.coast_frames = int(coast_frames)
        self.gate_factor = float(gate_factor)
        self.window_model = WindowModel(
            extent_factor=float(extent_factor),
            margin_px=float(margin_px),
            speed_gain=float(speed_gain),
            initial_speed_px=float(initial_speed_px),
            grow_px=float(grow_px),
            max_allowance_px=float(max_allowance_px),
        )
        self.search = MarkerSearch(detect, params, candidates, bool(fit))
        self.reset()

    # -- public --------------------------------------------------------------------------------
    @property
    def detect(self) -> Detect:
        """The whole detector (run where codes are read, or on every search)."""
        return self.search.detect

    @property
    def fit(self) -> bool:
        """True when fitted, bias-corrected centres are reported."""
        return self.search.fit

    @property
    def params(self) -> Any:
        """The built-in detector's :class:`~labauto.vision.markers.MarkerParams`."""
        return self.search.params

    @property
    def extent_factor(self) -> float:
        """What of a marker a window holds, in centre radii."""
        return self.window_model.extent_factor

    def reset(self) -> None:
        """Forget every track (the next frame is searched whole)."""
        self._tracks: dict[int, Track] = {}
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
        return {
            tid: tuple(self.window_model.predict(t, self._frame))  # type: ignore[misc]
            for tid, t in self._tracks.items()
        }

    def update(self, image: np.ndarray) -> FrameResult:
        """Search one frame and update the tracks.

        Parameters
        ----------
        image : ndarray
            The frame, grey (H, W) or colour (H, W, 3, BGR), as
            :func:`~labauto.vision.markers.detect_markers` takes it (``uint8``, or float on a
            0-1 or 0-255 scale).
        """
        started = time.perf_counter()
        grey = grey_image(image) if self.search.candidates else np.asarray(image)
        if grey.ndim not in (2, 3) or grey.shape[0] == 0 or grey.shape[1] == 0:
            raise ValueError(f"expected an (H, W) or (H, W, C) image, got shape {grey.shape}")
        index = self._frame
        due = not self._tracks or index - self._last_full >= self.full_interval
        mode = "full"
        if due:
            found = self._search_frame(grey, full=True)
        else:
            found = self._search_frame(grey, full=False)
            expected = [t.id for t in self._tracks.values() if t.missed == 0]
            if any(tid not in found for tid in expected):
                self.stats.fallbacks += 1
                found = self._search_frame(grey, full=True)
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
    def _search_frame(self, frame: np.ndarray, *, full: bool) -> dict[int, Obs]:
        """Search the whole frame or the windows of the tracks; the markers found by id."""
        association = Association(
            self._tracks,
            self._frame,
            self.window_model,
            self.coast_frames,
            self.gate_factor,
            self.stats,
        )

        def read_codes(candidates: list[Obs]) -> list[Obs]:
            return self.search.read_codes(frame, candidates)

        if full:
            self._last_full = self._frame
            self.stats.full_searches += 1
            return association.associate(self.search.observe(frame), read_codes, windows=None)
        height, width = frame.shape[:2]
        windows: dict[int, Rect] = {}
        for track in self._tracks.values():
            rect = clip_rect(self.window_model.window(track, self._frame), width, height)
            if rect is not None:
                windows[track.id] = rect
        if not windows:
            return {}
        observed, pixels = self.search.in_windows(
            frame, windows.values(), self.window_model.extent_factor
        )
        self.stats.window_pixels.append(pixels)
        return association.associate(observed, read_codes, windows=windows)

    # -- tracks --------------------------------------------------------------------------------
    def _apply(self, found: dict[int, Obs], index: int) -> None:
        """Start or move the tracks of the markers found; age (and in time drop) the others."""
        for mid, hit in found.items():
            track = self._tracks.get(mid)
            if track is None:  # (tracks missed for longer than coast_frames are dropped below)
                self._tracks[mid] = Track(mid, hit.position, np.zeros(2), hit.radius, index)
            else:
                follow(track, hit.position, hit.radius, hit.id is not None, index)
        for mid in list(self._tracks):
            if mid in found:
                continue
            track = self._tracks[mid]
            track.missed += 1
            if track.missed > self.coast_frames:
                del self._tracks[mid]
