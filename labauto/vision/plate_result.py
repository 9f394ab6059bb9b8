"""What plate analysis reports: the colonies found and the plate's result (JSON contract).

:func:`labauto.vision.plate.analyze_plate` makes them; ``labauto plate IMAGE --json`` prints
:meth:`PlateResult.to_dict`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labauto.vision.dish import Dish

KLASSES = ("authentic", "merged", "mixed")


@dataclass
class Colony:
    """One colony (or merged body) on the plate.

    Attributes
    ----------
    id : int
        Index in :attr:`PlateResult.colonies`.
    centroid : tuple of float
        Centre of gravity ``(x, y)`` of the contour's polygon.
    klass : str
        ``"authentic"``, ``"merged"`` or ``"mixed"``.
    area_px : float
        Pixels inside the contour.
    d_alpha_median : float
        Median shape angle D_alpha in degrees.
    estimated_count : int
        Colonies in the body: 1 for authentic; for merged, the peaks of its distance transform
        (1 when it is one colony whose shape is not a DES); for a merged or mixed body 1.5 times
        as wide as the plate's single colonies, one more for every small colony seen sitting
        on it (:mod:`labauto.vision.plate`, step 5).
    contour : ndarray, shape (n, 2)
        Outline ``(x, y)`` in image pixels.
    mix_score : float
        Fraction of the colony's inner pixels that do not follow one species' colour.
    """

    id: int
    centroid: tuple[float, float]
    klass: str
    area_px: float
    d_alpha_median: float
    estimated_count: int
    contour: np.ndarray = field(repr=False)
    mix_score: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (contour as a list of ``[x, y]``)."""
        return {
            "id": self.id,
            "centroid": [round(float(self.centroid[0]), 3), round(float(self.centroid[1]), 3)],
            "class": self.klass,
            "area_px": float(self.area_px),
            "d_alpha_median": round(float(self.d_alpha_median), 3),
            "estimated_count": int(self.estimated_count),
            "mix_score": round(float(self.mix_score), 4),
            "contour": np.asarray(self.contour, dtype=float).round(2).tolist(),
        }


@dataclass
class PlateResult:
    """Everything :func:`analyze_plate` found on one plate.

    ``rejected`` counts the objects dropped per reason (dust, large, thin, elongated, stroke,
    rim_arc, ring_line, ink, sliver, rim); ``stage_ms`` is the time taken per stage of
    :func:`analyze_plate`
    (``dish``: dish and usable area; ``objects``: segmentation, contours and D_alpha;
    ``measures``: artefact tests and waists; ``classes``: mixed-colony test, merged counts and
    the result). Both are diagnostic and not part of the JSON.
    """

    width: int
    height: int
    timing_ms: float
    dish: Dish
    colonies: list[Colony]
    rejected: dict[str, int] = field(default_factory=dict)
    stage_ms: dict[str, float] = field(default_factory=dict)

    @property
    def counts(self) -> dict[str, int]:
        """Colonies per class and ``colonies_estimate`` (merged bodies by their count)."""
        out = {k: sum(c.klass == k for c in self.colonies) for k in KLASSES}
        out["colonies_estimate"] = sum(c.estimated_count for c in self.colonies)
        return out

    def to_dict(self) -> dict[str, Any]:
        """Return the public JSON form (``labauto plate IMAGE --json``)."""
        return {
            "width": self.width,
            "height": self.height,
            "timing_ms": round(float(self.timing_ms), 3),
            "dish": self.dish.to_dict(),
            "colonies": [c.to_dict() for c in self.colonies],
            "counts": self.counts,
        }
