"""The synthetic plate generator's ground truth is exact and self-consistent."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from labauto.synthetic.plates import AGAR_COLOURS_RGB, PlateTruth, generate_plate


def _mask(contour: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.round(contour).astype(np.int32)], 1)
    return mask.astype(bool)


def test_same_seed_gives_the_same_plate() -> None:
    a_img, a_truth = generate_plate(42, agar="chocolate")
    b_img, b_truth = generate_plate(42, agar="chocolate")
    assert np.array_equal(a_img, b_img)
    assert a_truth.to_dict() == b_truth.to_dict()
    c_img, _ = generate_plate(43, agar="chocolate")
    assert not np.array_equal(a_img, c_img)


def test_image_is_bgr_uint8_of_the_requested_size() -> None:
    img, truth = generate_plate(5, width=800, height=640, agar="red_blood")
    assert img.shape == (640, 800, 3) and img.dtype == np.uint8
    assert (truth.width, truth.height) == (800, 640)
    # the agar colour shows in the middle of the dish (BGR order: red agar has R >> B)
    cx, cy = (round(v) for v in truth.dish.center)
    b, _g, r = img[cy - 3 : cy + 4, cx - 3 : cx + 4].reshape(-1, 3).mean(axis=0)
    assert r > b + 60


def test_counts_and_kinds(plates: list) -> None:
    for _, truth in plates:
        counts = truth.counts()
        assert counts["authentic"] == 20 and counts["merged"] == 6 and counts["mixed"] == 4
        for c in truth.colonies:
            assert c.count == len(c.ellipses)
            assert (c.count >= 2) == (c.kind == "merged")
            n_colours = {"authentic": 1, "mixed": 2, "merged": c.count}[c.kind]
            assert len(c.colours_rgb) == n_colours
        assert counts["colonies_total"] == sum(c.count for c in truth.colonies)


def test_colonies_lie_inside_the_dish_away_from_the_rim(plates: list) -> None:
    for _, truth in plates:
        cx, cy = truth.dish.center
        for c in truth.colonies:
            r = np.hypot(c.contour[:, 0] - cx, c.contour[:, 1] - cy)
            assert r.max() < truth.dish.radius - 30.0


def test_colonies_do_not_overlap_unless_merged(plates: list) -> None:
    for img, truth in plates[:4]:
        shape = img.shape[:2]
        cover = np.zeros(shape, np.int32)
        for c in truth.colonies:
            cover += _mask(c.contour, shape)
        assert cover.max() == 1  # no two colonies (or groups) share a pixel
        for c in truth.colonies:
            if c.kind != "merged":
                continue
            # members of a merged group overlap: their union is one connected body
            members = [_mask(e.sample(180), shape) for e in c.ellipses]
            union = np.any(members, axis=0).astype(np.uint8)
            assert cv2.connectedComponents(union)[0] == 2


def test_ellipses_are_des_within_the_stated_axis_ratio(plates: list) -> None:
    for _, truth in plates:
        for c in truth.colonies:
            for e in c.ellipses:
                a, b = e.axes
                assert a >= b > 0 and a / b <= 1.6 + 1e-9


def test_truth_area_matches_the_contour(plates: list) -> None:
    _, truth = plates[0]
    for c in truth.colonies:
        if c.kind != "merged":
            area = cv2.contourArea(c.contour.astype(np.float32))
            assert abs(area - c.area_px) < 0.1 * area + 10


def test_artefacts_on_the_agar_keep_clear_of_colonies_and_dust_is_small(plates: list) -> None:
    for img, truth in plates[:6]:
        kinds = {a.kind for a in truth.artefacts}
        assert {"dust", "glare", "pen", "label"} <= kinds
        colony_masks = np.zeros(img.shape[:2], np.uint8)
        for c in truth.colonies:
            colony_masks |= _mask(c.contour, img.shape[:2])
        dist = cv2.distanceTransform(1 - colony_masks, cv2.DIST_L2, 3)
        for a in truth.artefacts:
            if a.on_agar:
                pts = np.round(a.points.reshape(-1, 2)).astype(int)
                assert dist[pts[:, 1], pts[:, 0]].min() >= 5.0, a.kind
    # dust is smaller than the smallest colony
    smallest = min(c.area_px for _, t in plates for c in t.colonies)
    assert smallest > 13 * 3 > math.pi * 2.0**2


def test_truth_json_round_trip() -> None:
    _, truth = generate_plate(7, agar=None)
    assert truth.agar in AGAR_COLOURS_RGB
    data = json.loads(json.dumps(truth.to_dict()))
    again = PlateTruth.from_dict(data)
    assert again.to_dict() == data
    assert again.colonies[0].ellipses[0].axes == tuple(data["colonies"][0]["ellipses"][0]["axes"])


def test_no_artefacts_when_disabled() -> None:
    _, truth = generate_plate(3, artefacts=False, n_authentic=5, n_merged=1, n_mixed=1)
    assert truth.artefacts == []
    assert truth.counts()["authentic"] == 5


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"agar": "purple"}, "agar"),
        ({"stage": "grey"}, "stage"),
        ({"width": 100}, "width"),
        ({"n_merged": -1}, "n_merged"),
    ],
)
def test_bad_arguments_are_named(kwargs: dict, word: str) -> None:
    with pytest.raises(ValueError, match=word):
        generate_plate(1, **kwargs)
