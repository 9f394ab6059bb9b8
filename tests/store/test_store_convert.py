"""Rows from labauto's stable JSON results, stored and read back."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.store import (
    InvalidValue,
    Store,
    colony_rows,
    detection_rows,
    plate_detection_rows,
)

DETECTION_JSON = {
    "width": 300,
    "height": 200,
    "method": "segmentation",
    "timing_ms": 3.2,
    "objects": [
        {
            "id": 0,
            "centroid": [80.0, 100.0],
            "n_points": 189,
            "closed": True,
            "d_alpha_median": 17.4,
            "d_alpha_mean": 17.5,
            "centroid_inside": True,
            "is_des": True,
            "shape": "ellipse",
            "ellipse": {"center": [80.0, 100.5], "axes": [40.5, 25.4], "angle": 29.5},
            "future_key": "ignored",
        },
        {
            "id": 1,
            "centroid": [210.0, 90.0],
            "n_points": 12,
            "closed": False,
            "d_alpha_median": 61.0,
            "d_alpha_mean": 58.0,
            "centroid_inside": False,
            "is_des": False,
            "shape": "other",
            "ellipse": None,
        },
    ],
}
PLATE_JSON = {
    "width": 300,
    "height": 200,
    "colonies": [
        {
            "id": 0,
            "centroid": [80.0, 100.0],
            "class": "authentic",
            "area_px": 3200.0,
            "d_alpha_median": 4.1,
            "estimated_count": 1,
            "mix_score": 0.02,
            "contour": [[40.0, 100.0], [80.0, 75.0], [120.0, 100.0]],
        },
        {
            "id": 1,
            "centroid": [210.0, 90.0],
            "class": "merged",
            "area_px": 5100.0,
            "d_alpha_median": 22.0,
            "estimated_count": 2,
            "mix_score": 0.05,
            "contour": [[180.0, 90.0], [240.0, 90.0]],
        },
    ],
}


def test_detection_json_round_trip(store: Store, scene):
    ids = store.add_detections(scene.run_id, scene.image_id, detection_rows(DETECTION_JSON))
    first, second = store.detections(scene.image_id)
    assert [first.id, second.id] == ids
    assert (first.object_index, first.method, first.centroid_x, first.centroid_y) == (
        0, "segmentation", 80.0, 100.0,
    )  # fmt: skip
    assert (first.ellipse_cx, first.ellipse_cy, first.ellipse_a, first.ellipse_b) == (
        80.0, 100.5, 40.5, 25.4,
    )  # fmt: skip
    assert first.ellipse_angle == 29.5 and first.is_des and first.shape == "ellipse"
    assert second.ellipse_a is None and not second.closed and second.n_points == 12


def test_colony_json_round_trip_linked_to_detections(store: Store, scene):
    det_ids = store.add_detections(scene.run_id, scene.image_id, detection_rows(DETECTION_JSON))
    rows = colony_rows(PLATE_JSON, detection_ids={0: det_ids[0]})
    store.add_colonies(scene.run_id, scene.image_id, rows)
    first, second = store.colonies(scene.run_id)
    assert (first.colony_index, first.klass, first.detection_id) == (0, "authentic", det_ids[0])
    assert first.contour == PLATE_JSON["colonies"][0]["contour"]
    assert (second.klass, second.estimated_count, second.mix_score) == ("merged", 2, 0.05)
    assert second.detection_id is None


def test_plate_colonies_become_detections_by_the_same_rows(store: Store, scene):
    rows = plate_detection_rows(PLATE_JSON, "plate:canny")
    store.add_detections(scene.run_id, scene.image_id, rows)
    first, second = store.detections(scene.image_id)
    assert (first.object_index, first.method, first.centroid_x, first.n_points) == (
        0, "plate:canny", 80.0, 3,
    )  # fmt: skip
    assert (first.is_des, first.closed, first.area_px, first.d_alpha_median) == (
        True, True, 3200.0, 4.1,
    )  # fmt: skip
    assert not second.is_des and second.n_points == 2
    # what the plate analysis does not measure is not made up
    assert first.centroid_inside is None and second.centroid_inside is None
    assert first.d_alpha_mean is None and first.shape is None and first.ellipse_a is None
    with pytest.raises(InvalidValue, match="object 1: missing 'id'"):
        plate_detection_rows({"colonies": [PLATE_JSON["colonies"][0], {"centroid": [1, 2]}]}, "p")


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"objects": []}, "must have 'method' and 'objects'"),
        ({"method": "canny", "objects": [{"centroid": [1, 2]}]}, "object 0: missing 'id'"),
        (
            {"method": "canny", "objects": [{"id": 3, "centroid": 5}]},
            r"'centroid' must be \[x, y\]",
        ),
    ],
)
def test_malformed_detection_json_is_named(bad, message):
    with pytest.raises(InvalidValue, match=message):
        detection_rows(bad)


def test_real_detector_output_is_stored(store: Store, scene):
    # The vision layer's own output on a rendered ellipse (centre (80, 100), semi-axes 40, 25).
    from labauto.vision.detector import detect

    image = np.full((200, 300, 3), 230, np.uint8)
    cv2.ellipse(image, (80, 100), (40, 25), 30, 0, 360, (40, 90, 160), -1)
    result = detect(image).to_dict()
    store.add_detections(scene.run_id, scene.image_id, detection_rows(result))
    stored = store.detections(scene.image_id)
    assert len(stored) == len(result["objects"]) >= 1
    nearest = min(stored, key=lambda d: (d.centroid_x - 80) ** 2 + (d.centroid_y - 100) ** 2)
    assert abs(nearest.centroid_x - 80) < 1.5 and abs(nearest.centroid_y - 100) < 1.5
    assert nearest.method == result["method"]
