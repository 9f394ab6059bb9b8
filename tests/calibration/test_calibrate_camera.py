"""Camera calibration on renders of a known camera: intrinsics, distortion, view rejection."""

from __future__ import annotations

import numpy as np
import pytest
from calibration_helpers import CAMERA, SIZE

import labauto
from labauto.errors import CalibrationError
from labauto.vision.board_points import find_board_points
from labauto.vision.calibration import ViewPoints
from labauto.vision.calibration import calibrate_camera as calibrate_views


def _check_intrinsics(k: np.ndarray) -> None:
    assert abs(k[0, 0] / CAMERA[0, 0] - 1) < 1e-3  # fx within 0.1 %
    assert abs(k[1, 1] / CAMERA[1, 1] - 1) < 1e-3
    assert abs(k[0, 2] - CAMERA[0, 2]) < 0.5  # cx within 0.5 px
    assert abs(k[1, 2] - CAMERA[1, 2]) < 0.5


def test_coded_board_points_are_the_true_image_points(coded_views) -> None:
    for image, truth in zip(coded_views.images, coded_views.truth, strict=True):
        view = find_board_points(image, coded_views.board)
        assert len(view) == len(coded_views.board.ids)  # every marker, tilts up to 60 deg
        rows = [int(np.flatnonzero(coded_views.board.ids == i)[0]) for i in view.ids]
        err = np.hypot(*(view.image_points - truth[rows]).T)
        assert np.median(err) < 0.05 and err.max() < 0.3


def test_coded_board_calibrates_the_camera(coded_views) -> None:
    result = labauto.calibrate_camera(coded_views.board, coded_views.images)
    _check_intrinsics(result.camera_matrix)
    assert result.rms_px < 0.1
    assert all(v.used and v.reason is None for v in result.views)
    doc = result.to_dict()
    assert doc["image_size"] == list(SIZE) and len(doc["dist_coeffs"]) == 5
    assert set(doc["views"][0]) == {"image", "markers", "rms_px", "used", "reason"}


def test_circle_grid_with_bias_removed_from_the_pose(circle_views) -> None:
    result = labauto.calibrate_camera(circle_views.board, circle_views.images)
    _check_intrinsics(result.camera_matrix)
    assert result.rms_px < 0.1


def test_an_outlying_view_is_set_aside_with_its_reason(coded_views) -> None:
    views = []
    for k, image in enumerate(coded_views.images):
        v = find_board_points(image, coded_views.board)
        pts = v.image_points.copy()
        if k == 2:  # a view whose points were shaken (a moved board, a bad frame)
            pts += np.random.default_rng(1).normal(0, 3.0, pts.shape)
        views.append(ViewPoints(f"v{k}", pts, v.object_points))
    views.append(ViewPoints("few", views[0].image_points[:5], views[0].object_points[:5]))
    result = calibrate_views(views, SIZE)
    status = {v.image: v for v in result.views}
    assert not status["v2"].used and "outlier" in status["v2"].reason
    assert not status["few"].used and "only 5 board points" in status["few"].reason
    assert sum(v.used for v in result.views) == len(coded_views.images) - 1
    _check_intrinsics(result.camera_matrix)


def test_too_few_views_say_how_many_were_usable_and_why(coded_views) -> None:
    blank = np.full((SIZE[1], SIZE[0]), 200, np.uint8)
    with pytest.raises(CalibrationError) as err:
        labauto.calibrate_camera(coded_views.board, [coded_views.images[0], blank, blank])
    message = str(err.value)
    assert "1 of 3" in message and "2 x no board found" in message and "\n" not in message


def test_views_that_share_a_name_are_reported_each_on_its_own() -> None:
    """The same file given twice, or names=["a", "a"]: a view set aside was reported used
    (with the RMS of the other) because the results were keyed by name."""
    import cv2

    grid = np.array([(x, y, 0.0) for y in range(0, 50, 10) for x in range(0, 70, 10)], float)
    views = []
    for k, (rx, ry) in enumerate([(0.3, 0.0), (0.0, 0.3), (-0.3, 0.1), (0.2, -0.3)]):
        pose = np.array([rx, ry, 0.0]), np.array([-30.0, -20.0, 150.0 + 10 * k])
        pixels, _ = cv2.projectPoints(grid, *pose, CAMERA, None)
        views.append(ViewPoints("same.png", pixels.reshape(-1, 2), grid))
    views.append(ViewPoints("same.png", views[0].image_points[:3], grid[:3]))
    result = calibrate_views(views, SIZE)
    assert [v.used for v in result.views] == [True] * 4 + [False]
    assert result.views[4].reason == "only 3 board points (needs 8)"
    assert result.views[4].rms_px is None


def test_names_that_do_not_match_the_images_are_refused_in_one_line() -> None:
    from labauto.vision.boards import coded_board

    image = np.full((64, 64), 200, np.uint8)
    with pytest.raises(CalibrationError, match=r"^1 names for 2 images$"):
        labauto.calibrate_camera(coded_board(2, 2, 20.0), [image, image], names=["a"])
