"""Plate analysis sizes in millimetres: the same plate at any camera scale reads the same.

Synthetic plates are drawn at ~10 px/mm. Resized to a webcam's 6 px/mm or a photo's 35 px/mm,
the same colonies must be found with the same classes (positions mapped back), because every
size is derived from the dish (or a configured ``px_per_mm``) and fine images are analysed on
a copy resampled to ``analysis_px_per_mm``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from labauto.synthetic.plates import generate_plate, score_plate
from labauto.vision.plate import PlateParams, analyze_plate
from labauto.vision.plate_scale import WorkingCopy, working_copy

REAL = Path(__file__).resolve().parents[3] / "shared" / "realplates"


@pytest.mark.parametrize("factor", [0.6, 3.5])
def test_same_plate_at_another_camera_scale_reads_the_same(factor: float) -> None:
    img, truth = generate_plate(5, agar="amber")
    resized = cv2.resize(
        img, None, fx=factor, fy=factor,
        interpolation=cv2.INTER_AREA if factor < 1 else cv2.INTER_CUBIC,
    )  # fmt: skip
    result = analyze_plate(resized)
    score = score_plate(truth, result.colonies, scale=factor)
    assert score.found == score.n_truth == 30
    assert score.correct >= 29
    assert score.false_positives == 0
    assert result.dish.radius == pytest.approx(truth.dish.radius * factor, rel=0.01)
    # contours and areas are in the given image's pixels
    biggest = max(result.colonies, key=lambda c: c.area_px)
    xs = biggest.contour[:, 0]
    assert xs.max() - xs.min() == pytest.approx(2 * np.sqrt(biggest.area_px / np.pi), rel=0.6)


def test_px_per_mm_from_a_calibration_overrides_the_dish() -> None:
    img, _ = generate_plate(7, agar="clear")
    found = analyze_plate(img)
    # a calibration saying 200 px/mm makes every colony (at most 47 px across) smaller than
    # 0.25 mm: none is a colony any more (below the dust limit of 0.3 mm)
    tiny = analyze_plate(img, PlateParams(px_per_mm=200.0))
    assert len(found.colonies) >= 25 and tiny.colonies == []


def test_pixel_overrides_win_over_millimetres() -> None:
    img, _ = generate_plate(7, agar="clear")
    result = analyze_plate(img, PlateParams(min_colony_area_px=1e6, max_colony_area_px=2e6))
    assert result.colonies == []


def test_working_copy_maps_pixel_centres_both_ways() -> None:
    image = np.zeros((400, 600, 3), np.uint8)
    copy = working_copy(image, (100.0, 50.0, 500.0, 350.0), 40.0, PlateParams())
    assert isinstance(copy, WorkingCopy)
    assert copy.factor == pytest.approx(12.0 / 40.0, rel=0.01)
    assert copy.px_per_mm == pytest.approx(12.0, rel=0.01)
    pts = np.array([[123.25, 77.5], [499.0, 349.0]])
    np.testing.assert_allclose(copy.to_original(copy.to_working(pts)), pts, atol=1e-9)
    # an image between the two scales is used as it is
    same = working_copy(image, (0.0, 0.0, 599.0, 399.0), 9.0, PlateParams())
    assert same.factor == 1.0 and same.image is image
    # a webcam frame is resampled up to the analysis scale
    webcam = working_copy(image, (100.0, 50.0, 500.0, 350.0), 6.0, PlateParams())
    assert webcam.factor == pytest.approx(2.0, rel=0.01)
    assert webcam.px_per_mm == pytest.approx(12.0, rel=0.01)
    np.testing.assert_allclose(webcam.to_original(webcam.to_working(pts)), pts, atol=1e-9)
    off = working_copy(image, (0.0, 0.0, 599.0, 399.0), 6.0, PlateParams(min_analysis_px_per_mm=0))
    assert off.factor == 1.0


@pytest.mark.parametrize(("diameter_mm", "params"), [
    (0.9, PlateParams()),  # above the default line opening (0.75 mm)
    # smaller colonies on a clean plate, by config (line opening lowered)
    (0.45, PlateParams(open_mm=0.3)),
])  # fmt: skip
def test_small_colonies_on_a_photo_survive_the_resampling(
    diameter_mm: float, params: PlateParams
) -> None:
    px_per_mm = 30.0
    radius = 45.0 * px_per_mm
    size = int(2 * radius + 200)
    img = np.full((size, size, 3), 20, np.uint8)
    c = size / 2
    cv2.circle(img, (int(c), int(c)), int(radius), (90, 140, 160), -1, cv2.LINE_AA)
    rng = np.random.default_rng(3)
    spots = []
    for _ in range(12):
        r, a = rng.uniform(0, radius * 0.8), rng.uniform(0, 2 * np.pi)
        x, y = c + r * np.cos(a), c + r * np.sin(a)
        spots.append((x, y))
        r_px = round(diameter_mm / 2 * px_per_mm)
        cv2.circle(img, (int(x), int(y)), r_px, (230, 235, 240), -1, cv2.LINE_AA)
    result = analyze_plate(img, params)
    got = np.array([col.centroid for col in result.colonies]).reshape(-1, 2)
    for x, y in spots:
        assert np.min(np.hypot(got[:, 0] - x, got[:, 1] - y)) < 0.3 * px_per_mm
    if params == PlateParams():  # with the lower floor, bits of the drawn dish edge pass too
        assert result.counts["colonies_estimate"] == len(spots)


@pytest.mark.skipif(not (REAL / "agar-boxes").is_dir(), reason="real plate photos not present")
def test_real_agar_plate_when_the_data_are_present() -> None:
    """One real AGAR photo (349: 99 boxed colonies, a printed label): most colonies found."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from bench_real_plates import read_boxes, score_boxes

    image = cv2.imread(str(REAL / "agar-boxes" / "images" / "349.jpg"), cv2.IMREAD_COLOR)
    boxes = read_boxes(REAL / "agar-boxes" / "labels" / "349.txt", image.shape[1], image.shape[0])
    score = score_boxes(analyze_plate(image), boxes)
    assert score.truth == 99
    assert score.matched >= 80 and score.reported <= 110
    # every box not matched has its cause (where its centre lies, how large it is)
    assert sum(score.missed.values()) == score.truth - score.matched
    # and every box, matched or not, in one band of distance from the dish's edge
    assert [sum(v) for v in zip(*score.by_edge.values(), strict=True)] == [
        score.truth,
        score.matched,
    ]


def test_a_dish_cut_by_the_frame_is_named_or_analysed_whole_when_configured() -> None:
    img, _ = generate_plate(9, agar="amber")
    cut = np.ascontiguousarray(img[:, : img.shape[1] // 2 + 40])  # the right half is gone
    with pytest.raises(ValueError, match=r"cut by the image border.*detect_dish"):
        analyze_plate(cut)
    whole = analyze_plate(cut, PlateParams(detect_dish=False))
    assert len(whole.colonies) >= 8
    # a dish that only touches the frame (real photos do) is fine
    edge = np.ascontiguousarray(img[:, 100:])
    assert len(analyze_plate(edge).colonies) >= 25


@pytest.mark.parametrize("factor", [1.0, 3.5])
def test_a_plate_moved_by_whole_pixels_reads_the_same_when_its_dish_moves_with_it(
    factor: float,
) -> None:
    # nothing in the analysis depends on where the dish lies in the frame: moved by whole
    # pixels with its dish, the plate gives the same colonies, moved. (With the dish found
    # instead, a pixel's move can change the dish by a fraction of a pixel and with it the
    # working copy: that is all of the counts' spread in ``bench_real_plates.py --shifts``.)
    img, _ = generate_plate(5, agar="amber")
    if factor != 1.0:
        img = cv2.resize(img, None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC)
    dish = analyze_plate(img).dish
    (cx, cy), r = dish.center, dish.radius
    first = analyze_plate(img, PlateParams(region=(cx, cy, r)))
    assert len(first.colonies) >= 25
    for shift in (1, 3):
        moved = analyze_plate(img[shift:, shift:], PlateParams(region=(cx - shift, cy - shift, r)))
        assert [c.klass for c in moved.colonies] == [c.klass for c in first.colonies]
        assert [c.estimated_count for c in moved.colonies] == [
            c.estimated_count for c in first.colonies
        ]
        for a, b in zip(first.colonies, moved.colonies, strict=True):
            assert np.allclose(np.add(b.centroid, shift), a.centroid, atol=1e-6)
            assert np.allclose(b.contour + shift, a.contour, atol=1e-6)
