"""Pick planning: which colonies to pick, in which order, and where they are on the deck.

Rules (issue: pick planning):

* only colonies of the configured classes (authentic by default) are candidates;
* a candidate needs a clear gap to every other object on the plate: the gap is the distance
  between centroids minus both equivalent radii ``sqrt(area / pi)``, and must be at least
  ``min_neighbor_distance_px`` (so the pick tool does not touch a neighbour);
* it needs ``min_rim_distance_px`` between its edge and the dish rim (when the dish is known);
* at most ``max_picks`` are planned, in the configured order: ``largest`` area first,
  ``smallest`` first, ``roundest`` (lowest D_alpha) first, or ``scan`` (rows top to bottom in a
  serpentine, which keeps robot travel short);
* every planned pick carries its deck position in millimetres from the calibration.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from labauto.orchestrator.calibration import Calibration


class ColonyLike(Protocol):
    """What planning needs of a colony (``labauto.vision.plate.Colony`` has it)."""

    id: int
    centroid: tuple[float, float]
    klass: str
    area_px: float
    d_alpha_median: float


@dataclass(frozen=True)
class PlannedPick:
    """A colony chosen for picking, with its deck position."""

    colony_id: int
    sequence: int
    pixel: tuple[float, float]
    deck_mm: tuple[float, float]


@dataclass(frozen=True)
class PickRules:
    """The planning rules; see the module docstring."""

    max_picks: int = 8
    min_neighbor_distance_px: float = 12.0
    min_rim_distance_px: float = 20.0
    order: str = "largest"
    classes: tuple[str, ...] = ("authentic",)


def clearance(colonies: Sequence[ColonyLike]) -> np.ndarray:
    """Gap in pixels from each colony's edge to its nearest neighbour's edge (inf if alone)."""
    if not colonies:
        return np.zeros(0)
    centres = np.array([c.centroid for c in colonies], dtype=np.float64)
    radii = np.sqrt(np.array([c.area_px for c in colonies], dtype=np.float64) / np.pi)
    distance = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
    gaps = distance - radii[:, None] - radii[None, :]
    np.fill_diagonal(gaps, np.inf)
    return gaps.min(axis=1)


def rim_distance(colonies: Sequence[ColonyLike], dish: Any | None) -> np.ndarray:
    """Gap in pixels from each colony's edge to the dish rim (inf when the dish is unknown)."""
    if dish is None or not colonies:
        return np.full(len(colonies), np.inf)
    centres = np.array([c.centroid for c in colonies], dtype=np.float64)
    radii = np.sqrt(np.array([c.area_px for c in colonies], dtype=np.float64) / np.pi)
    centre = np.asarray(_dish_center(dish), dtype=np.float64)
    return _dish_radius(dish) - np.linalg.norm(centres - centre, axis=1) - radii


def plan_picks(
    colonies: Sequence[ColonyLike],
    calibration: Calibration,
    rules: PickRules = PickRules(),
    dish: Any | None = None,
) -> list[PlannedPick]:
    """Choose and order the colonies to pick.

    Parameters
    ----------
    colonies : sequence of colonies
        All objects found on the plate (every class: neighbours of any class count).
    calibration : Calibration
        Maps pixels to deck millimetres.
    rules : PickRules
        Classes, distances, maximum count and order.
    dish : object with ``center`` and ``radius`` (or a mapping), optional
        The dish, for the rim distance.

    Returns
    -------
    list of PlannedPick
        In picking order, ``sequence`` counting from 0.
    """
    if rules.order not in _ORDER_KEYS:
        raise ValueError(f"unknown pick order {rules.order!r} (expected {', '.join(_ORDER_KEYS)})")
    gaps = clearance(colonies)
    rim = rim_distance(colonies, dish)
    candidates = [
        c
        for c, gap, edge in zip(colonies, gaps, rim, strict=True)
        if c.klass in rules.classes
        and gap >= rules.min_neighbor_distance_px
        and edge >= rules.min_rim_distance_px
    ]
    chosen = _ORDER_KEYS[rules.order](candidates)[: rules.max_picks]
    if not chosen:
        return []
    pixels = np.array([c.centroid for c in chosen], dtype=np.float64)
    deck = calibration.to_deck(pixels)
    return [
        PlannedPick(c.id, i, (float(p[0]), float(p[1])), (float(d[0]), float(d[1])))
        for i, (c, p, d) in enumerate(zip(chosen, pixels, deck, strict=True))
    ]


def _serpentine(colonies: Sequence[ColonyLike], row_height: float = 100.0) -> list[ColonyLike]:
    rows: dict[int, list[ColonyLike]] = {}
    for c in colonies:
        rows.setdefault(int(c.centroid[1] // row_height), []).append(c)
    ordered: list[ColonyLike] = []
    for index, row in enumerate(sorted(rows)):
        ordered += sorted(rows[row], key=lambda c: c.centroid[0], reverse=index % 2 == 1)
    return ordered


_ORDER_KEYS = {
    "largest": lambda cs: sorted(cs, key=lambda c: (-c.area_px, c.id)),
    "smallest": lambda cs: sorted(cs, key=lambda c: (c.area_px, c.id)),
    "roundest": lambda cs: sorted(cs, key=lambda c: (c.d_alpha_median, c.id)),
    "scan": _serpentine,
}


def _dish_center(dish: Any) -> tuple[float, float]:
    return tuple(dish["center"] if isinstance(dish, dict) else dish.center)


def _dish_radius(dish: Any) -> float:
    return float(dish["radius"] if isinstance(dish, dict) else dish.radius)
