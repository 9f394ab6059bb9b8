"""What :class:`labauto.vision.tracking.MarkerTracker` reads and reports.

* :class:`MarkerLike`: what the tracker reads from a detected marker (the markers of
  :func:`labauto.vision.markers.detect_markers`, or of a detector of one's own);
* :class:`TrackedMarker` and :class:`FrameResult`: what it reports per frame (the JSON lines of
  ``labauto track --json-lines``);
* :class:`TrackerStats`: counts kept over a sequence, for benchmarks and tests.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

__all__ = ["FrameResult", "MarkerLike", "TrackedMarker", "TrackerStats"]


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
class TrackerStats:
    """Counts kept over a sequence (for benchmarks and tests).

    Attributes
    ----------
    frames, full_searches : int
        Frames seen, and how many of them were searched whole.
    fallbacks : int
        Windowed searches discarded for a full-frame search (a marker missing from its window).
    code_reads : int
        Centre candidates whose code was read.
    rejected_jumps : int
        Detections rejected by the id-swap guard.
    ambiguous : int
        Tracks or ids left undecided by position (more than one candidate or place).
    window_pixels : list of int
        Pixels of each windowed search's mosaic.
    """

    frames: int = 0
    full_searches: int = 0
    fallbacks: int = 0
    code_reads: int = 0
    rejected_jumps: int = 0
    ambiguous: int = 0
    window_pixels: list[int] = field(default_factory=list)
