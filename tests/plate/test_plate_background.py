"""The pieces of the plate background, on drawn masks and images with known answers."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.vision import plate_background
from labauto.vision.plate import PlateParams, analyze_plate
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


def test_thin_ring_lines_leave_the_radial_profile_and_the_meniscus_stays() -> None:
    # at 10 px/mm: a dark meniscus 1.5 mm wide at the edge, a lid's line 0.2 mm wide 3 mm in
    img = np.full((400, 400, 3), 120, np.uint8)
    cv2.circle(img, (200, 200), 175, (60, 60, 60), 15)
    cv2.circle(img, (200, 200), 152, (70, 70, 70), 2)
    usable = np.zeros((400, 400), np.uint8)
    cv2.circle(usable, (200, 200), 182, 255, -1)
    cells = local_background(img, usable, 8, 600.0)

    def dev(px_per_mm: float) -> np.ndarray:
        profile = rim_profile(img, (200.0, 200.0, 182.0), 40.0, px_per_mm)
        return deviation(img, with_radial_rim(cells, profile), (1.0, 1.0, 1.0))

    lines_out = dev(10.0)
    assert lines_out[200, 375] < 300  # the meniscus is still the agar's colour there
    assert lines_out[200, 352] > 3000  # the thin line is not: it stands out (and is opened away)
    assert dev(0.0)[200, 352] < 1000  # without the running median the line was background


def test_a_colony_that_a_lid_line_crosses_at_the_rim_stays_whole(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # eight translucent colonies 2.8 mm across on a line of the lid 2.5 mm inside the agar's
    # edge, the line in front of them: where it crosses a colony, the colony is as dark as the
    # line is over the agar
    yy, xx = np.mgrid[0:700, 0:700]
    d = np.hypot(xx - 350.0, yy - 350.0)
    agar = np.array([120.0, 180.0, 205.0])
    img = np.full((700, 700, 3), 30.0)
    img[d < 300] = agar + np.clip((d[d < 300, None] - 285) / 15, 0, 1) * 40  # a bright meniscus
    for k in range(8):
        t = k * np.pi / 4
        at = (round(350 + 275 * np.cos(t)), round(350 + 275 * np.sin(t)))
        cv2.circle(img, at, 14, (100, 150, 170), -1, cv2.LINE_AA)
    line = np.abs(d - 275) < 1.0
    img[line] *= 0.4
    img = cv2.GaussianBlur(img, (0, 0), 0.8) + np.random.default_rng(0).normal(0, 2, img.shape)
    img = np.clip(img, 0, 255).astype(np.uint8)
    params = PlateParams(region=(350.0, 350.0, 300.0), px_per_mm=10.0)
    assert [c.estimated_count for c in analyze_plate(img, params).colonies] == [1] * 8
    # with the line in the profile, colonies were cut along it into pieces
    monkeypatch.setattr(plate_background, "_RIM_LINE_MM", 0.0)
    assert len(analyze_plate(img, params).colonies) < 8
