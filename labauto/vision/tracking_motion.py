"""Motion prediction and search windows of the marker tracker.

A track is predicted with constant velocity in the image: a marker seen at ``p`` with velocity
``v`` (pixels per frame, the displacement between its last two sightings divided by the frames
between them) is expected at ``p + v * dt``, ``dt`` the frames since it was last seen. Its
search window is a square of half-size ``extent + margin_px + min(speed_gain * |v| * dt +
grow_px * missed, max_allowance_px)`` around that prediction (see
:mod:`labauto.vision.tracking` for why).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from labauto.vision.roi_mosaic import Rect

__all__ = ["Track", "WindowModel", "follow"]


@dataclass
class Track:
    """One tracked marker.

    Attributes
    ----------
    id : int
        The marker's id.
    position, velocity : ndarray
        Last seen centre (frame pixels) and velocity (pixels per frame).
    radius : float
        Reference centre-circle radius (pixels).
    last_frame : int
        Index of the frame it was last seen in.
    known_velocity : bool
        False until it was seen in two frames.
    missed : int
        Frames since it was last seen.
    """

    id: int
    position: np.ndarray
    velocity: np.ndarray
    radius: float
    last_frame: int
    known_velocity: bool = False
    missed: int = 0


@dataclass(frozen=True)
class WindowModel:
    """Where a track is expected and how far around that it is searched.

    Parameters
    ----------
    extent_factor : float
        What of a marker a window must hold, in centre radii.
    margin_px : float
        Allowance for an acceleration from standstill and for jitter.
    speed_gain : float
        Share of the speed by which the velocity may change between two frames.
    initial_speed_px : float
        Speed (pixels per frame, any direction) allowed for a track with no velocity yet.
    grow_px : float
        Growth of the allowance per missed frame.
    max_allowance_px : float
        Cap of the allowance.
    """

    extent_factor: float
    margin_px: float
    speed_gain: float
    initial_speed_px: float
    grow_px: float
    max_allowance_px: float

    def predict(self, track: Track, frame: int) -> np.ndarray:
        """Where ``track`` expects its marker in frame ``frame`` (constant velocity)."""
        dt = frame - track.last_frame
        return track.position + track.velocity * dt

    def half_size(self, track: Track, frame: int) -> float:
        """Half-size (pixels) of the window of ``track`` in frame ``frame``."""
        dt = max(frame - track.last_frame, 1)
        if track.known_velocity:
            allowance = self.speed_gain * float(np.hypot(*track.velocity)) * dt
        else:  # no velocity yet: it may have moved initial_speed_px per frame, any way
            allowance = self.initial_speed_px * dt
        extent = track.radius * self.extent_factor
        allowance = min(allowance + self.grow_px * track.missed, self.max_allowance_px)
        return extent + self.margin_px + allowance

    def window(self, track: Track, frame: int) -> Rect:
        """The window of ``track`` in frame ``frame`` (integer pixels, not clipped)."""
        cx, cy = self.predict(track, frame)
        half = self.half_size(track, frame)
        return (
            math.floor(cx - half),
            math.floor(cy - half),
            math.ceil(cx + half) + 1,
            math.ceil(cy + half) + 1,
        )


def follow(track: Track, position: np.ndarray, radius: float, coded: bool, frame: int) -> None:
    """Move ``track`` to a new sighting at ``position`` in frame ``frame`` (in place).

    The velocity is the displacement over the frames since the last sighting. The reference
    radius follows a code read (``coded``), and a centre candidate only when within 8 % of it
    (so a circle covered bit by bit cannot drag it along).
    """
    dt = frame - track.last_frame
    track.velocity = (position - track.position) / max(dt, 1)
    track.known_velocity = True
    track.position = position
    if coded or abs(radius / track.radius - 1.0) <= 0.08:
        track.radius = radius
    track.last_frame = frame
    track.missed = 0
