"""The agar's edge (``labauto.vision.dish.find_dish``): lines across the agar are passed."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.vision.dish import find_dish

AGAR = (150, 200, 185)
SURROUND = (40, 60, 55)
RADIUS = 400  # px: 8.9 px per mm for a 90 mm dish
CENTRE = (520, 500)


def _dish(line_radius: int | None, line_px: int) -> np.ndarray:
    """Agar disc on a dark surround, with a dark line ``line_px`` wide at ``line_radius``."""
    rng = np.random.default_rng(3)
    img = np.full((1000, 1040, 3), SURROUND, np.uint8)
    cv2.circle(img, CENTRE, RADIUS, AGAR, -1, cv2.LINE_AA)
    if line_radius is not None:
        cv2.circle(img, CENTRE, line_radius, (95, 130, 120), line_px, cv2.LINE_AA)
    noise = rng.normal(0.0, 2.0, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


def test_plain_agar_edge() -> None:
    dish = find_dish(_dish(None, 0))
    assert abs(dish.radius - RADIUS) < 2.0
    assert np.hypot(dish.center[0] - CENTRE[0], dish.center[1] - CENTRE[1]) < 2.0


@pytest.mark.parametrize("line_radius", [360, 372])  # 4.5 mm and 3 mm inside the edge
def test_a_line_with_agar_beyond_it_is_not_the_edge(line_radius: int) -> None:
    # 13 px (1.5 mm) wide: it lasts a millimetre, as the wall does, but the agar comes back
    dish = find_dish(_dish(line_radius, 13))
    assert abs(dish.radius - RADIUS) < 2.0


def test_a_ring_at_the_edge_is_the_edge() -> None:
    # a dark ring on the agar's rim with the surround beyond: the agar ends at the ring
    dish = find_dish(_dish(RADIUS - 7, 13))
    assert abs(dish.radius - (RADIUS - 13)) < 3.0


def _dish_with_lid_and_wall() -> np.ndarray:
    """Agar (radius ``RADIUS``) with a slightly brighter meniscus, a line of the lid over it,
    the dish's wall beyond and the lid's rim further out: circles that all draw Hough votes."""
    rng = np.random.default_rng(3)
    img = np.full((1000, 1040, 3), SURROUND, np.uint8)
    cv2.circle(img, CENTRE, RADIUS + 36, (120, 140, 135), 8, cv2.LINE_AA)  # the lid's rim
    cv2.circle(img, CENTRE, RADIUS + 12, (200, 215, 210), -1, cv2.LINE_AA)  # the wall
    cv2.circle(img, CENTRE, RADIUS, AGAR, -1, cv2.LINE_AA)
    cv2.circle(img, CENTRE, RADIUS - 8, (155, 205, 190), 16, cv2.LINE_AA)  # the meniscus
    cv2.circle(img, CENTRE, RADIUS - 32, (95, 130, 120), 3, cv2.LINE_AA)  # a line of the lid
    noise = rng.normal(0.0, 2.0, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("offset", [0, 4, 8, 12, 16, 20])
def test_the_dish_found_does_not_depend_on_the_framing(offset: int) -> None:
    # the subsampled Hough guess lands on the lid's rim, the wall or the lid's line depending
    # on where its pixels fall; the agar's edge found from the strongest edge does not
    dish = find_dish(_dish_with_lid_and_wall()[offset:, offset:])
    assert abs(dish.radius - RADIUS) < 2.0
    assert np.hypot(dish.center[0] + offset - CENTRE[0], dish.center[1] + offset - CENTRE[1]) < 2.0


@pytest.mark.parametrize("factor", [0.5, 0.35])
def test_the_dish_found_does_not_depend_on_the_camera_scale(factor: float) -> None:
    small = cv2.resize(
        _dish_with_lid_and_wall(), None, fx=factor, fy=factor, interpolation=cv2.INTER_AREA
    )
    dish = find_dish(small)
    assert abs(dish.radius / factor - RADIUS) < 3.0
