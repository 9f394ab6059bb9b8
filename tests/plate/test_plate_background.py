"""The pieces of the plate background, on drawn masks and images with known answers."""

from __future__ import annotations

import cv2
import numpy as np

from labauto.vision.plate_background import (
    deviation,
    local_background,
    rim_profile,
    with_radial_rim,
)


def test_the_meniscus_ring_goes_into_the_background() -> None:
    img = np.full((400, 400, 3), 120, np.uint8)
    cv2.circle(img, (200, 200), 176, (60, 60, 60), 6)  # a dark meniscus ring near the edge
    cv2.circle(img, (200, 60), 6, (200, 200, 200), -1)  # a colony inside, away from it
    usable = np.zeros((400, 400), np.uint8)
    cv2.circle(usable, (200, 200), 182, 255, -1)
    bg = local_background(img, usable, 8, 600.0)
    ring_before = deviation(img, bg, (1.0, 1.0, 1.0))[200, 376]
    bg = with_radial_rim(bg, rim_profile(img, (200.0, 200.0, 182.0), 40.0))
    dev = deviation(img, bg, (1.0, 1.0, 1.0))
    assert ring_before > 3000  # the cell background does not follow a 6 px ring
    assert dev[200, 376] < 300 and dev[24, 200] < 300  # the radial profile does, all round
    assert dev[60, 200] > 3000  # the colony still stands out
