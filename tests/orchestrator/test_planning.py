"""Pick planning: classes, neighbour and rim distances, maximum count, order, deck positions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from labauto.orchestrator.calibration import Calibration
from labauto.orchestrator.planning import PickRules, clearance, plan_picks


@dataclass
class Col:
    id: int
    centroid: tuple[float, float]
    klass: str = "authentic"
    area_px: float = float(np.pi * 10**2)  # radius 10
    d_alpha_median: float = 10.0


PIXELS = np.array([[0, 0], [1000, 0], [1000, 1000], [0, 1000], [500, 500]], float)
CAL = Calibration.from_points(PIXELS, PIXELS * 0.1 + (20.0, 30.0))
DISH = {"center": (500.0, 500.0), "radius": 450.0}


def test_clearance_is_edge_to_edge():
    gaps = clearance([Col(0, (100, 100)), Col(1, (130, 100)), Col(2, (400, 100))])
    np.testing.assert_allclose(gaps, [10.0, 10.0, 250.0])


def test_only_authentic_clear_colonies_inside_the_rim_are_planned():
    colonies = [
        Col(0, (300, 300)),
        Col(1, (325, 300)),  # 5 px gap to colony 0: both too close
        Col(2, (600, 600), klass="merged"),
        Col(3, (700, 300), klass="mixed"),
        Col(4, (930, 500)),  # 450 - 430 - 10 = 10 px from the rim: too close
        Col(5, (500, 700)),
    ]
    picks = plan_picks(
        colonies, CAL, PickRules(min_neighbor_distance_px=12, min_rim_distance_px=20), DISH
    )
    assert [p.colony_id for p in picks] == [5]
    assert picks[0].deck_mm == pytest.approx((70.0, 100.0), abs=1e-6)


@pytest.mark.parametrize(
    ("order", "expected"),
    [("largest", [1, 2, 0]), ("smallest", [0, 2, 1]), ("roundest", [2, 0, 1])],
)
def test_order_and_sequence(order, expected):
    colonies = [
        Col(0, (200, 200), area_px=100.0, d_alpha_median=12.0),
        Col(1, (500, 200), area_px=400.0, d_alpha_median=20.0),
        Col(2, (800, 500), area_px=200.0, d_alpha_median=5.0),
    ]
    picks = plan_picks(colonies, CAL, PickRules(order=order), DISH)
    assert [p.colony_id for p in picks] == expected
    assert [p.sequence for p in picks] == [0, 1, 2]


def test_scan_order_is_a_serpentine_and_max_picks_holds():
    colonies = [
        Col(i, (x, y))
        for i, (x, y) in enumerate(
            [(200, 250), (600, 250), (400, 250), (300, 450), (700, 450), (500, 650)]
        )
    ]
    picks = plan_picks(colonies, CAL, PickRules(order="scan", max_picks=5), DISH)
    assert [p.colony_id for p in picks] == [0, 2, 1, 4, 3]


def test_unknown_order_is_refused():
    with pytest.raises(ValueError, match="unknown pick order 'random'"):
        plan_picks([Col(0, (500, 500))], CAL, PickRules(order="random"))
