"""Scoring a tracker's output against the truth of a rendered sequence (tests, benchmarks).

For each frame the tracker's markers are compared with the sequence's truth
(:class:`labauto.synthetic.marker_sequences.SequenceFrame`):

* an **id swap** is a reported marker nearer another marker's true centre than its own;
* a **visible** marker (wholly in view, clear of the occluder) counts as *reported* when its id
  is among the frame's markers. A miss is *excused* when the marker (re)entered the view after
  the last full-frame search: the tracker only looks for new markers there, so
  ``reported_rate`` counts every miss and ``tracked_rate`` only the others;
* the **re-entry latency** of a marker that comes into view is the number of frames from the
  first full-frame search at or after its entry to its first report (the issue asks for <= 1);
* the **centre error** is measured on visible markers only (a partly hidden centre circle has
  no well-defined centre).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["TrackingScore", "score_tracking"]


@dataclass
class TrackingScore:
    """What :func:`score_tracking` measured."""

    frames: int = 0
    swaps: int = 0
    visible: int = 0
    reported: int = 0
    excused: int = 0
    errors_px: list[float] = field(default_factory=list)
    latencies: list[int] = field(default_factory=list)
    roi_ms: list[float] = field(default_factory=list)
    full_ms: list[float] = field(default_factory=list)

    @property
    def reported_rate(self) -> float:
        """Share of visible markers reported, every miss counted."""
        return self.reported / max(self.visible, 1)

    @property
    def tracked_rate(self) -> float:
        """Share of visible markers reported, misses before the next full search excused."""
        return (self.reported + self.excused) / max(self.visible, 1)

    def error(self, q: float) -> float:
        """The ``q``-th percentile of the centre error (pixels)."""
        return float(np.percentile(self.errors_px, q)) if self.errors_px else float("nan")

    def summary(self) -> dict[str, Any]:
        """The figures, for a table."""
        return {
            "frames": self.frames,
            "swaps": self.swaps,
            "reported_rate": self.reported_rate,
            "tracked_rate": self.tracked_rate,
            "max_latency": max(self.latencies) if self.latencies else None,
            "error_median_px": self.error(50),
            "error_p99_px": self.error(99),
            "error_max_px": self.error(100),
        }


def score_tracking(results: Sequence[Any], frames: Iterable[Any]) -> TrackingScore:
    """Score tracker ``results`` (:class:`~labauto.vision.tracking.FrameResult`) on ``frames``."""
    score = TrackingScore()
    entered: dict[int, list[int | None]] = {}  # marker -> [frame it came into view, 1st full]
    previously: frozenset[int] = frozenset()
    for result, frame in zip(results, frames, strict=True):
        score.frames += 1
        (score.roi_ms if result.mode == "roi" else score.full_ms).append(result.timing_ms)
        found = result.centers()
        for mid, (x, y) in found.items():
            truth = frame.centers.get(mid)
            own = np.inf if truth is None else np.hypot(x - truth[0], y - truth[1])
            others = [np.hypot(x - c[0], y - c[1]) for o, c in frame.centers.items() if o != mid]
            if others and min(others) < own:
                score.swaps += 1
            if mid in frame.visible:
                score.errors_px.append(float(own))
        if frame.index > 0:
            for mid in frame.visible - previously:
                entered[mid] = [frame.index, None]
        for mid in list(entered):
            if mid not in frame.visible:
                del entered[mid]
            elif result.mode == "full" and entered[mid][1] is None:
                entered[mid][1] = frame.index
        for mid in frame.visible:
            score.visible += 1
            if mid in found:
                score.reported += 1
                if mid in entered:
                    first_full = entered.pop(mid)[1]
                    score.latencies.append(0 if first_full is None else frame.index - first_full)
            elif mid in entered and entered[mid][1] is None:
                score.excused += 1  # no full-frame search since it came into view
        previously = frame.visible
    return score
