"""Which observation continues which track: by position, then by code, with the id-swap guard.

See "Searching" and "Id-swap guard" in :mod:`labauto.vision.tracking`. In short: a centre
candidate continues the track of a marker seen in the previous frame when it is that track's
one clear candidate and no other track claims it; codes are read where position does not
decide; a coded detection only ever continues the track of its own id, and the guard rejects
detections that are more likely another marker misread than a jump.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from labauto.vision.marker_codes import QUIET_RADIUS
from labauto.vision.roi_mosaic import Rect
from labauto.vision.tracking_motion import Track, WindowModel
from labauto.vision.tracking_search import Obs
from labauto.vision.tracking_types import TrackerStats

__all__ = ["Association"]


@dataclass
class Association:
    """The tracks as they stand before frame ``frame``, and the rules to extend them.

    Parameters
    ----------
    tracks : dict of int to Track
        The tracks by id (not changed here).
    frame : int
        Index of the frame searched.
    model : WindowModel
        Predictions and window sizes.
    coast_frames : int
        Frames a lost track is still searched.
    gate_factor : float
        A tracked id found further than this many window half-sizes from its prediction, in
        another marker's window, is rejected as a misread.
    stats : TrackerStats
        Counters updated (code reads, ambiguous, rejected jumps).
    """

    tracks: dict[int, Track]
    frame: int
    model: WindowModel
    coast_frames: int
    gate_factor: float
    stats: TrackerStats

    def associate(
        self,
        observed: list[Obs],
        read_codes: Callable[[list[Obs]], list[Obs]],
        windows: dict[int, Rect] | None,
    ) -> dict[int, Obs]:
        """Markers found by id: candidates by position, then codes (module docstring).

        Parameters
        ----------
        observed : list of Obs
            What the search found (frame pixels).
        read_codes : callable
            ``read_codes(candidates) -> coded observations`` for the candidates position does
            not decide.
        windows : dict of int to Rect, optional
            The window of each track searched; None for a full-frame search.
        """
        found: dict[int, Obs] = {}
        coded = [o for o in observed if o.id is not None]
        candidates = [o for o in observed if o.id is None]
        if candidates:
            to_read = self.by_position(candidates, found, full=windows is None)
            if to_read:
                self.stats.code_reads += len(to_read)
                coded += read_codes(to_read)
        for mid, places in _group_by_id(coded).items():
            hit = self.take_coded(mid, places, windows)
            if hit is not None:
                found[mid] = hit
        return found

    def by_position(self, candidates: list[Obs], found: dict[int, Obs], full: bool) -> list[Obs]:
        """Give tracks seen in the previous frame their one clear candidate (into ``found``).

        Returns the candidates whose code must be read. Vectorised over tracks x candidates.
        """
        model = self.model
        tracks = [t for t in self.tracks.values() if t.missed <= self.coast_frames]
        positions = np.array([c.position for c in candidates])
        radii = np.array([c.radius for c in candidates])
        whole = np.array([c.whole for c in candidates])
        if not tracks:
            eligible = np.zeros((0, len(candidates)), bool)
            missed = np.zeros(0, np.int64)
        else:
            predicted = np.array([model.predict(t, self.frame) for t in tracks])
            half = np.array([model.half_size(t, self.frame) for t in tracks])
            radius = np.array([t.radius for t in tracks])
            missed = np.array([t.missed for t in tracks])
            delta = positions[None, :, :] - predicted[:, None, :]
            box = np.abs(delta).max(axis=2)
            euclid = np.hypot(delta[..., 0], delta[..., 1])
            reach = half - radius * model.extent_factor + 1.0
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
        # tracks seen last frame with a candidate: the nearest one is theirs when it is clear (no
        # other within twice its distance + 2 px) and no other track claims it
        rows = np.flatnonzero((missed == 0) & eligible.any(axis=1))
        if rows.size:
            distance = np.where(eligible[rows], euclid[rows], np.inf)
            nearest = np.argsort(distance, axis=1, kind="stable")[:, :2]
            best = nearest[:, 0]
            d1 = distance[np.arange(rows.size), best]
            d2 = (
                distance[np.arange(rows.size), nearest[:, 1]]
                if nearest.shape[1] > 1
                else np.full(rows.size, np.inf)
            )
            taken_clearly = (d2 > 2.0 * d1 + 2.0) & (claimed[best] == 1)
            for row, k in zip(rows[taken_clearly], best[taken_clearly], strict=True):
                found[tracks[int(row)].id] = candidates[int(k)]
            unclear = rows[~taken_clearly]
            self.stats.ambiguous += int(unclear.size)
            if unclear.size:
                near = box[unclear] <= half[unclear, None]
                to_read.update(np.flatnonzero(near.any(axis=0)).tolist())
        quiet = ~_near_any(positions, list(found.values()))  # not in a found marker's ring
        to_read.update(np.flatnonzero(eligible[missed > 0].any(axis=0) & quiet).tolist())
        if full:
            to_read.update(np.flatnonzero((claimed == 0) & whole & quiet).tolist())
        return [candidates[k] for k in sorted(to_read)]

    def take_coded(
        self, mid: int, places: list[Obs], windows: dict[int, Rect] | None
    ) -> Obs | None:
        """The detection that continues (or starts) the track of ``mid``, with the guard."""
        track = self.tracks.get(mid)
        if windows is not None:
            if mid not in windows:
                return None  # another id in a window: left to the next full-frame search
            places = [p for p in places if _inside(p.position, windows[mid])]
            if not places:
                return None
        if track is not None and track.missed <= self.coast_frames:
            predicted = self.model.predict(track, self.frame)
            distances = [float(np.linalg.norm(p.position - predicted)) for p in places]
            hit = places[int(np.argmin(distances))]
            far = min(distances) > self.gate_factor * self.model.half_size(track, self.frame)
            if track.missed == 0 and far and self.near_other_track(mid, hit.position):
                self.stats.rejected_jumps += 1
                return None
            return hit
        hit = places[0]
        spread = max(float(np.linalg.norm(p.position - hit.position)) for p in places)
        if spread > max(hit.radius * self.model.extent_factor, 1.0):
            self.stats.ambiguous += 1
            return None
        if self.near_other_track(mid, hit.position):
            self.stats.rejected_jumps += 1  # a new id where a tracked marker is: a misread
            return None
        return hit

    def near_other_track(self, mid: int, position: np.ndarray) -> bool:
        """True when ``position`` is inside the window of another id's track."""
        for other in self.tracks.values():
            if other.id != mid and other.missed <= self.coast_frames:
                predicted = self.model.predict(other, self.frame)
                distance = float(np.max(np.abs(position - predicted)))
                if distance <= self.model.half_size(other, self.frame):
                    return True
        return False


def _group_by_id(observed: list[Obs]) -> dict[int, list[Obs]]:
    groups: dict[int, list[Obs]] = {}
    for obs in observed:
        groups.setdefault(int(obs.id), []).append(obs)  # type: ignore[arg-type]
    return groups


def _near_any(points: np.ndarray, found: list[Obs]) -> np.ndarray:
    """(n,) bool: each of ``points`` (n, 2) lies within the code ring of a marker already
    found (its sectors)."""
    if not found or not len(points):
        return np.zeros(len(points), bool)
    centres = np.array([obs.position for obs in found], np.float64)
    reach = QUIET_RADIUS * np.array([obs.radius for obs in found], np.float64)
    delta = np.asarray(points, np.float64)[:, None, :] - centres[None, :, :]
    return (np.hypot(delta[..., 0], delta[..., 1]) <= reach[None, :]).any(axis=1)


def _inside(point: np.ndarray, rect: Rect) -> bool:
    """True when ``point`` lies in the pixels of ``rect`` (half-open, pixel-centre origin)."""
    x0, y0, x1, y1 = rect
    return bool(x0 - 0.5 <= point[0] <= x1 - 0.5 and y0 - 0.5 <= point[1] <= y1 - 0.5)
