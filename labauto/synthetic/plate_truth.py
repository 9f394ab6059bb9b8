"""Ground truth of a synthetic plate: the dish, the colonies and the artefacts as drawn.

The records :func:`labauto.synthetic.plates.generate_plate` returns, with their JSON form
(``to_dict`` / ``PlateTruth.from_dict``: the bundled sample plates carry it). Coordinates follow
DESIGN.md: origin at the centre of the top-left pixel, x right, y down.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labauto.vision.ellipse import Ellipse

__all__ = ["ArtefactTruth", "ColonyTruth", "DishTruth", "PlateTruth"]


@dataclass(frozen=True)
class DishTruth:
    """The dish: ``center`` (x, y) and ``radius`` of the agar disc, ``rim_width`` of the wall."""

    center: tuple[float, float]
    radius: float
    rim_width: float

    def to_dict(self) -> dict[str, Any]:
        """Return ``{"center": [x, y], "radius": r, "rim_width": w}``."""
        return {
            "center": [self.center[0], self.center[1]],
            "radius": self.radius,
            "rim_width": self.rim_width,
        }


@dataclass(frozen=True)
class ColonyTruth:
    """One colony (or merged group) as drawn.

    Attributes
    ----------
    id : int
        Index in :attr:`PlateTruth.colonies`.
    kind : str
        ``"authentic"``, ``"merged"`` or ``"mixed"``.
    center : tuple of float
        Area centroid ``(x, y)`` of the drawn body (pixels where the body covers more than half).
    count : int
        Number of colonies in the body: 1 for authentic and mixed, 2 or 3 for merged.
    ellipses : list of Ellipse
        The undeformed ellipse of every member (one for authentic and mixed).
    contour : ndarray, shape (n, 2)
        Outline polygon ``(x, y)`` of the body (exact for DES, traced for merged groups).
    area_px : int
        Pixels covered by more than half.
    colours_rgb : list of tuple
        The species colours (two for a mixed colony).
    mix_style : str
        ``"sector"`` or ``"speckles"`` for mixed colonies, ``""`` otherwise.
    near_agar : bool
        True if the colony has nearly the agar's colour.
    """

    id: int
    kind: str
    center: tuple[float, float]
    count: int
    ellipses: list[Ellipse]
    contour: np.ndarray
    area_px: int
    colours_rgb: list[tuple[int, int, int]]
    mix_style: str = ""
    near_agar: bool = False

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (contour as a list of ``[x, y]``)."""
        return {
            "id": self.id,
            "kind": self.kind,
            "center": [self.center[0], self.center[1]],
            "count": self.count,
            "ellipses": [e.to_dict() for e in self.ellipses],
            "contour": np.round(self.contour, 2).tolist(),
            "area_px": self.area_px,
            "colours_rgb": [list(c) for c in self.colours_rgb],
            "mix_style": self.mix_style,
            "near_agar": self.near_agar,
        }


@dataclass(frozen=True)
class ArtefactTruth:
    """One artefact: ``kind`` is dust, scratch, pen, label or glare; ``points`` its polyline,
    polygon or centre; ``on_agar`` is True when it lies inside the agar disc (not on the rim)."""

    kind: str
    points: np.ndarray
    on_agar: bool

    def __post_init__(self) -> None:
        # stored rounded to 0.01 px, as in the JSON, so a round trip is exact
        pts = np.round(np.asarray(self.points, dtype=float).reshape(-1, 2), 2)
        object.__setattr__(self, "points", pts)

    @property
    def center(self) -> tuple[float, float]:
        """Mean of the artefact's points."""
        m = self.points.reshape(-1, 2).mean(axis=0)
        return float(m[0]), float(m[1])

    def to_dict(self) -> dict[str, Any]:
        """Return ``{"kind", "points", "on_agar", "center"}``."""
        return {
            "kind": self.kind,
            "points": self.points.tolist(),
            "on_agar": self.on_agar,
            "center": list(self.center),
        }


@dataclass(frozen=True)
class PlateTruth:
    """Ground truth of a generated plate."""

    seed: int
    width: int
    height: int
    agar: str
    stage: str
    dish: DishTruth
    colonies: list[ColonyTruth] = field(default_factory=list)
    artefacts: list[ArtefactTruth] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        """Number of colonies per kind and the total number of colonies (merged count summed)."""
        out = {k: sum(c.kind == k for c in self.colonies) for k in ("authentic", "merged", "mixed")}
        out["colonies_total"] = sum(c.count for c in self.colonies)
        return out

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form of the whole truth."""
        return {
            "seed": self.seed,
            "width": self.width,
            "height": self.height,
            "agar": self.agar,
            "stage": self.stage,
            "dish": self.dish.to_dict(),
            "colonies": [c.to_dict() for c in self.colonies],
            "artefacts": [a.to_dict() for a in self.artefacts],
            "counts": self.counts(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PlateTruth:
        """Rebuild a truth from :meth:`to_dict` output (e.g. a sample plate's JSON)."""
        dish = DishTruth(
            tuple(data["dish"]["center"]), data["dish"]["radius"], data["dish"]["rim_width"]
        )
        colonies = [
            ColonyTruth(
                id=c["id"],
                kind=c["kind"],
                center=tuple(c["center"]),
                count=c["count"],
                ellipses=[
                    Ellipse(tuple(e["center"]), tuple(e["axes"]), e["angle"]) for e in c["ellipses"]
                ],
                contour=np.asarray(c["contour"], dtype=float),
                area_px=c["area_px"],
                colours_rgb=[tuple(x) for x in c["colours_rgb"]],
                mix_style=c["mix_style"],
                near_agar=c["near_agar"],
            )
            for c in data["colonies"]
        ]
        artefacts = [
            ArtefactTruth(a["kind"], np.asarray(a["points"], dtype=float), a["on_agar"])
            for a in data["artefacts"]
        ]
        return cls(
            data["seed"],
            data["width"],
            data["height"],
            data["agar"],
            data["stage"],
            dish,
            colonies,
            artefacts,
        )
