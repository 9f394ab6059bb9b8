"""Arcs along the rim (``labauto.vision.plate_rim_arcs``): pieces of ring lines, not colonies."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

import labauto.vision.plate as plate
from labauto.synthetic.plates import generate_plate, score_plate
from labauto.vision.plate import analyze_plate
from labauto.vision.plate_rim_arcs import RimPolar, on_ring_lines, rim_arcs

PPM = 12.0  # px per mm
RIM = (600.0, 600.0, 540.0)  # the usable circle: 45 mm


def _contour(mask: np.ndarray) -> np.ndarray:
    found, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return max(found, key=cv2.contourArea)


def _arc(radius_mm: float, width_mm: float, degrees: float, at: float = 0.0) -> np.ndarray:
    """Mask of an arc of the circle ``RIM`` shrunk to ``radius_mm``, ``width_mm`` thick."""
    mask = np.zeros((1200, 1200), np.uint8)
    centre = (round(RIM[0]), round(RIM[1]))
    radius = round(radius_mm * PPM)
    thickness = max(round(width_mm * PPM), 1)
    cv2.ellipse(mask, centre, (radius, radius), at, 0, degrees, 255, thickness)
    return mask


def _disc(radius_mm: float, diameter_mm: float, at_deg: float = 0.0) -> np.ndarray:
    mask = np.zeros((1200, 1200), np.uint8)
    t = np.deg2rad(at_deg)
    x = RIM[0] + radius_mm * PPM * np.cos(t)
    y = RIM[1] + radius_mm * PPM * np.sin(t)
    cv2.circle(mask, (round(x), round(y)), round(diameter_mm * PPM / 2), 255, -1)
    return mask


def _test(masks: list[np.ndarray]) -> np.ndarray:
    contours = [_contour(m) for m in masks]
    area = np.array([float(np.count_nonzero(m)) for m in masks])
    return rim_arcs(RimPolar.of(contours, np.arange(len(contours)), RIM), area, PPM)


def test_pieces_and_arcs_along_the_rim_are_found_and_colonies_are_not() -> None:
    arcs = _test(
        [
            _arc(42.0, 1.0, 5.0),  # a piece of a lid's line 3 mm inside the rim: 3.7 mm long
            _arc(40.0, 1.2, 150.0, at=30.0),  # a long crescent (the meniscus' glow)
            _disc(42.0, 1.0, at_deg=200.0),  # a small colony there
            _disc(42.0, 3.0, at_deg=250.0),  # a large one
            _arc(30.0, 1.0, 5.0),  # a stroke of the same shape 15 mm inside the rim
        ]
    )
    assert arcs.tolist() == [True, True, False, False, False]


def test_two_colonies_touching_along_the_rim_are_not_an_arc() -> None:
    pair = cv2.bitwise_or(_disc(42.0, 2.0, at_deg=100.0), _disc(42.0, 2.0, at_deg=102.5))
    assert cv2.connectedComponents(pair)[0] == 2  # one body
    assert _test([pair]).tolist() == [False]


def test_no_body_no_arc() -> None:
    assert rim_arcs(RimPolar.of([], np.zeros(0, np.intp), RIM), np.zeros(0), PPM).shape == (0,)


@pytest.mark.parametrize(("seed", "gap_mm"), [(12, 0.5), (11, 0.8)])
def test_ring_lines_of_a_lid_on_a_webcam_frame_are_not_colonies(
    seed: int, gap_mm: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a lid's double ring line 3 mm inside the agar's edge, broken into arcs of 40 degrees,
    # on a 6 px/mm frame: the two lines blur into one band that the opening keeps
    img, truth = generate_plate(seed, agar="amber")
    (cx, cy), r = truth.dish.center, truth.dish.radius
    ppm = 2.0 * r / 90.0
    for k in (0.0, gap_mm):
        rr = round(r - (3.0 + k) * ppm)
        for start in range(0, 360, 60):
            cv2.ellipse(
                img, (round(cx), round(cy)), (rr, rr), 0, start, start + 40, (90, 90, 90),
                max(round(0.3 * ppm), 1), cv2.LINE_AA,
            )  # fmt: skip
    f = 0.6
    frame = cv2.resize(img, None, fx=f, fy=f, interpolation=cv2.INTER_AREA)

    def score(result: object) -> object:
        return score_plate(truth, result.colonies, scale=f)  # type: ignore[attr-defined]

    with_arcs = score(analyze_plate(frame))
    monkeypatch.setattr(plate, "rim_arcs", lambda polar, area, p: np.zeros(len(area), bool))
    without = score(analyze_plate(frame))
    # the pieces the opening leaves of the blurred band are colonies without the arc test
    assert with_arcs.false_positives <= 1  # type: ignore[attr-defined]
    assert with_arcs.false_positives < without.false_positives  # type: ignore[attr-defined]
    assert with_arcs.found == without.found  # type: ignore[attr-defined]


def _ring_line_test(body: np.ndarray, unopened: np.ndarray, which: bool = True) -> bool:
    contour = _contour(body)
    index = np.zeros(1, np.intp)
    found = on_ring_lines(RimPolar.of([contour], index, RIM), np.array([which]), PPM, unopened)
    return bool(found[0])


def test_a_piece_of_a_ring_line_that_goes_on_past_both_its_ends_is_found() -> None:
    band = _arc(42.0, 0.8, 60.0, at=80.0)  # a band 3 mm inside the rim, 0.8 mm wide
    piece = cv2.bitwise_and(band, _arc(42.0, 2.0, 2.0, at=109.0))  # 1.5 mm of it survived
    assert _ring_line_test(piece, band)
    # the same piece where the band ends just past it on one side is no piece of a line
    assert not _ring_line_test(piece, _arc(42.0, 0.8, 31.5, at=80.0))
    assert not _ring_line_test(piece, band, which=False)  # not asked


def test_a_colony_on_a_thin_ring_line_or_at_the_rim_alone_is_kept() -> None:
    line = _arc(42.0, 0.3, 60.0, at=80.0)
    colony = _disc(42.0, 2.0, at_deg=110.0)
    # past its ends the 0.3 mm line covers 0.15 of the colony's 2 mm radial span
    assert not _ring_line_test(colony, cv2.bitwise_or(line, colony))
    assert not _ring_line_test(colony, colony)  # nothing beyond it
    # a band as wide as the colony, 15 mm inside the rim: no ring line there
    inner = _arc(30.0, 2.0, 60.0, at=80.0)
    assert not _ring_line_test(cv2.bitwise_and(inner, _arc(30.0, 3.0, 3.0, at=109.0)), inner)


def test_no_body_no_ring_line() -> None:
    empty = np.zeros((1200, 1200), np.uint8)
    found = on_ring_lines(RimPolar.of([], np.zeros(0, np.intp), RIM), np.zeros(0, bool), PPM, empty)
    assert found.shape == (0,)


PHONE = Path(__file__).resolve().parents[3] / "shared" / "realplates" / "phone-counts"


@pytest.mark.skipif(not PHONE.is_dir(), reason="real plate photos not present")
def test_a_phone_photo_whose_meniscus_band_the_opening_shreds_when_the_data_are_present() -> None:
    """IMG_2528 (12 colonies counted by hand): the band of the meniscus and the wall's inner
    line, speckled, is foreground that the opening breaks into pieces; they were counted as
    24 colonies in all before the ring-line test."""
    image = cv2.imread(str(PHONE / "images" / "IMG_2528.JPG"), cv2.IMREAD_COLOR)
    result = analyze_plate(image)
    assert result.rejected.get("ring_line", 0) >= 5
    assert 12 <= result.counts["colonies_estimate"] <= 15
