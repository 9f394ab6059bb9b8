"""Plate analysis against generated plates with exact ground truth."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from labauto.synthetic.plates import generate_plate, score_plate
from labauto.vision.plate import PlateParams, PlateResult, analyze_plate, find_dish


@pytest.fixture(scope="module")
def analysed(plates: list) -> list[tuple[PlateResult, object]]:
    return [(analyze_plate(img), truth) for img, truth in plates]


def test_found_and_classified_rate_is_at_least_98_percent(analysed: list) -> None:
    n = found = correct = 0
    per_kind: dict[str, list[int]] = {}
    for result, truth in analysed:
        score = score_plate(truth, result.colonies)
        n, found, correct = n + score.n_truth, found + score.found, correct + score.correct
        for (kind, klass), k in score.confusion.items():
            per_kind.setdefault(kind, [0, 0])
            per_kind[kind][0] += k
            per_kind[kind][1] += k if kind == klass else 0
    print(f"found {found}/{n}, correctly classified {correct}/{n}; per kind {per_kind}")
    assert n == 12 * 30
    assert correct / n >= 0.98
    assert found / n >= 0.98
    for kind, (total, ok) in per_kind.items():  # every class, not just the bulk
        assert ok / total >= 0.95, kind


def test_no_artefact_is_reported_as_a_colony(analysed: list) -> None:
    for result, truth in analysed:
        score = score_plate(truth, result.colonies)
        assert score.false_positives == 0, truth.seed
        assert score.artefacts_reported == 0, truth.seed
        assert sum(result.rejected.values()) > 0  # the artefacts were seen and dropped


def test_merged_counts_are_estimated(analysed: list) -> None:
    ok = total = 0
    for result, truth in analysed:
        score = score_plate(truth, result.colonies)
        ok, total = ok + score.count_correct, total + score.n_merged_found
    print(f"merged count exact for {ok}/{total} merged bodies")
    assert total >= 70
    assert ok / total >= 0.85
    estimate = sum(r.counts["colonies_estimate"] for r, _ in analysed)
    actual = sum(t.counts()["colonies_total"] for _, t in analysed)
    assert abs(estimate - actual) <= 0.03 * actual


def test_dish_is_found_within_a_few_pixels(analysed: list) -> None:
    for result, truth in analysed:
        (cx, cy), r = result.dish.center, result.dish.radius
        assert math.hypot(cx - truth.dish.center[0], cy - truth.dish.center[1]) < 2.5
        assert abs(r - truth.dish.radius) < 3.0


def test_json_contract(analysed: list) -> None:
    result, _ = analysed[0]
    data = json.loads(json.dumps(result.to_dict()))
    assert set(data) == {"width", "height", "timing_ms", "dish", "colonies", "counts"}
    assert (data["width"], data["height"]) == (1280, 1024)
    assert set(data["dish"]) == {"center", "radius"} and len(data["dish"]["center"]) == 2
    assert set(data["counts"]) == {"authentic", "merged", "mixed", "colonies_estimate"}
    assert data["counts"]["authentic"] == sum(c["class"] == "authentic" for c in data["colonies"])
    colony = data["colonies"][0]
    for key in ("id", "centroid", "class", "area_px", "d_alpha_median", "estimated_count"):
        assert key in colony
    assert colony["class"] in ("authentic", "merged", "mixed")
    contour = np.asarray(colony["contour"])
    assert contour.ndim == 2 and contour.shape[1] == 2
    assert [c["id"] for c in data["colonies"]] == list(range(len(data["colonies"])))


def _hand_plate(colonies: list[tuple[float, float, float, tuple[int, int, int]]]) -> np.ndarray:
    """A plain dish (agar disc, light wall) with sharp discs drawn at sub-pixel positions."""
    img = np.full((600, 700, 3), 30, np.uint8)
    cv2.circle(img, (350 * 16, 300 * 16), 260 * 16, (200, 210, 215), -1, cv2.LINE_AA, 4)
    cv2.circle(img, (350 * 16, 300 * 16), 250 * 16, (60, 140, 200), -1, cv2.LINE_AA, 4)
    for x, y, r, colour in colonies:
        cv2.circle(img, (round(x * 16), round(y * 16)), round(r * 16), colour, -1, cv2.LINE_AA, 4)
    return img


def test_coordinates_have_their_origin_at_the_top_left_pixel_centre() -> None:
    img = _hand_plate([(300.0, 250.0, 15.0, (230, 230, 230)), (420.25, 330.5, 12.0, (40, 40, 40))])
    result = analyze_plate(img)
    assert result.dish.radius == pytest.approx(250.0, abs=1.5)
    assert result.dish.center[0] == pytest.approx(350.0, abs=0.75)
    assert result.dish.center[1] == pytest.approx(300.0, abs=0.75)
    got = sorted((c.centroid for c in result.colonies), key=lambda p: p[0])
    assert [c.klass for c in result.colonies] == ["authentic", "authentic"]
    assert got[0] == pytest.approx((300.0, 250.0), abs=0.3)
    assert got[1] == pytest.approx((420.25, 330.5), abs=0.3)


def test_merged_and_mixed_on_a_hand_drawn_plate() -> None:
    img = _hand_plate(
        [
            (250.0, 300.0, 14.0, (230, 230, 230)),  # merged pair
            (273.0, 300.0, 13.0, (230, 230, 230)),
            (420.0, 260.0, 18.0, (230, 230, 230)),  # becomes a mixed colony below
        ]
    )
    cv2.ellipse(img, (420, 260), (18, 18), 0, 0, 110, (200, 60, 150), -1)  # a sector
    result = analyze_plate(img)
    by_x = sorted(result.colonies, key=lambda c: c.centroid[0])
    assert [c.klass for c in by_x] == ["merged", "mixed"]
    assert by_x[0].estimated_count == 2
    assert by_x[1].mix_score > 0.15
    assert result.counts == {"authentic": 0, "merged": 1, "mixed": 1, "colonies_estimate": 3}


def test_configured_regions_skip_dish_detection(plates: list) -> None:
    img, truth = plates[0]
    auto = analyze_plate(img)
    cx, cy = truth.dish.center
    circle = analyze_plate(img, PlateParams(region=(cx, cy, truth.dish.radius)))
    assert circle.dish.center == (cx, cy)
    assert score_plate(truth, circle.colonies).correct == score_plate(truth, auto.colonies).correct
    # a polygon: the left half of the usable disc; only colonies there are reported
    r = truth.dish.radius - 40
    poly = tuple((cx + r * math.cos(t), cy + r * math.sin(t)) for t in np.linspace(0.5, 2.6, 20))
    part = analyze_plate(img, PlateParams(region=((cx, cy), *poly)))
    assert 0 < len(part.colonies) < len(auto.colonies)
    path = np.array([(cx, cy), *poly], np.float32)
    for c in part.colonies:
        assert cv2.pointPolygonTest(path, c.centroid, False) >= 0


def test_detector_method_uses_v1_detector(plates: list) -> None:
    img, truth = plates[1]
    result = analyze_plate(img, PlateParams(method="detector"))
    score = score_plate(truth, result.colonies)
    assert score.correct >= 0.9 * score.n_truth
    assert score.artefacts_reported == 0


def test_empty_plate_has_no_colonies() -> None:
    img, truth = generate_plate(21, n_authentic=0, n_merged=0, n_mixed=0, agar="clear")
    result = analyze_plate(img)
    assert result.colonies == []
    assert result.counts["colonies_estimate"] == 0
    assert (
        math.hypot(
            result.dish.center[0] - truth.dish.center[0],
            result.dish.center[1] - truth.dish.center[1],
        )
        < 2.5
    )


def test_find_dish_alone() -> None:
    img, truth = generate_plate(31, agar="macconkey", stage="light")
    dish = find_dish(img)
    assert abs(dish.radius - truth.dish.radius) < 3.0


@pytest.mark.parametrize(
    ("image", "word"),
    [
        (np.zeros((0, 0, 3), np.uint8), "empty"),
        (np.zeros((100, 100, 2), np.uint8), "shape"),
        (np.zeros(1000, np.uint8), "shape"),
        (np.zeros((20, 20, 3), np.uint8), "64x64"),
        ([[1, 2], [3, 4]], "numpy array"),
        (np.full((100, 100, 3), np.nan), "NaN"),
        (np.full((200, 200, 3), 128, np.uint8), "no petri dish"),
    ],
)
def test_bad_images_raise_value_error(image: object, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        analyze_plate(image)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"method": "magic"}, "method"),
        ({"rim_margin_px": float("nan")}, "rim_margin_px"),
        ({"rim_margin_mm": float("inf")}, "rim_margin_mm"),
        ({"px_per_mm": 0.0}, "px_per_mm"),
        ({"dish_diameter_mm": -90.0}, "dish_diameter_mm"),
        ({"region": (1, 2)}, "region"),
        ({"region": (10, 10, -5)}, "radius"),
        ({"statistic": "mode"}, "statistic"),
        ({"background_scale": 0}, "background_scale"),
        ({"mix_fraction": 2.0}, "mix_fraction"),
        ({"min_colony_area_px": 10, "max_colony_area_px": 5}, "min_colony_area_px"),
    ],
)
def test_bad_params_raise_value_error(kwargs: dict, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        PlateParams(**kwargs)


def test_grey_and_float_images_are_accepted(plates: list) -> None:
    img, _ = plates[2]
    as_float = analyze_plate(img.astype(np.float32))
    assert len(as_float.colonies) == len(analyze_plate(img).colonies)
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    assert len(analyze_plate(grey).colonies) > 0


def test_shipped_sample_plates_are_read_right() -> None:
    from pathlib import Path

    from labauto.synthetic.plates import PlateTruth

    folder = Path(__file__).resolve().parents[2] / "labauto" / "data" / "plates"
    pngs = sorted(folder.glob("plate_*.png"))
    assert 3 <= len(pngs) <= 4
    for png in pngs:
        truth = PlateTruth.from_dict(json.loads(png.with_suffix(".json").read_text()))
        image = cv2.imread(str(png), cv2.IMREAD_COLOR)
        assert image.shape == (truth.height, truth.width, 3)
        score = score_plate(truth, analyze_plate(image).colonies)
        assert score.correct >= 0.95 * score.n_truth and score.false_positives == 0
