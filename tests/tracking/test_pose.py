"""Pose of a rigid marker set and two-camera triangulation on rendered views (issue 15 point 3, 7).

The pose error measured against the render's truth must lie within what the reprojection
residual predicts (the covariance of :func:`labauto.vision.pose.estimate_pose`).
"""

from __future__ import annotations

import numpy as np
import pytest

from labauto.synthetic.marker_sequences import board_points
from labauto.synthetic.markers import camera_map, draw_marker, finish
from labauto.vision.markers import detect_markers
from labauto.vision.pose import CameraView, estimate_pose, rotation_error_deg, triangulate
from labauto.vision.tracking import MarkerTracker


def pose_errors(spec, frames, fit):
    points = board_points(spec)
    tracker = MarkerTracker(fit=fit)
    rows = []
    for frame in frames:
        centers = tracker.update(frame.image).centers()
        pose = estimate_pose(centers, points, spec.camera_matrix, spec.dist_coeffs)
        if pose is None:
            continue
        t_err = float(np.linalg.norm(pose.tvec - frame.tvec))
        r_err = rotation_error_deg(pose.rvec, frame.rvec)
        rows.append((t_err, r_err, pose.std_translation_mm, pose.std_rotation_deg, pose.rms_px))
    return np.array(rows)


@pytest.mark.parametrize("fit", [False, True])
def test_pose_error_is_within_what_the_reprojection_error_predicts(hard_spec, hard_sequence, fit):
    rows = pose_errors(hard_spec, hard_sequence, fit)
    assert len(rows) >= 0.9 * len(hard_sequence)
    t_err, r_err, t_std, r_std, rms = rows.T
    assert np.median(rms) < 0.2
    # within 3 predicted standard errors in (almost) every frame, and small in absolute terms
    assert np.mean(t_err <= 3 * t_std + 0.01) >= 0.95
    assert np.mean(r_err <= 3 * r_std + 0.01) >= 0.95
    assert np.median(t_err) < 0.5 and np.median(r_err) < 0.1  # mm at 450 mm, degrees


def test_too_few_markers_give_no_pose():
    points = {1: (0, 0, 0), 2: (10, 0, 0), 3: (0, 10, 0), 4: (10, 10, 0)}
    k = np.array([[800.0, 0, 400], [0, 800, 300], [0, 0, 1]])
    assert estimate_pose({1: (1, 1), 2: (5, 5), 3: (9, 1)}, points, k) is None
    with pytest.raises(ValueError, match="min_markers"):
        estimate_pose({}, points, k, min_markers=3)


def render_view(points, view, size=(800, 600), radius=5.0):
    image = np.full((size[1], size[0]), 215.0)
    to_image = camera_map(view.camera_matrix, view.dist_coeffs, view.rvec, view.tvec)
    for mid, (x, y, _z) in points.items():
        draw_marker(image, mid, (x, y), radius, to_image=to_image, ink=25.0)
    return finish(image, blur_sigma=0.7, noise_sigma=1.0, rng=np.random.default_rng(mid))


def test_two_calibrated_cameras_triangulate_the_markers(hard_spec):
    points = board_points(hard_spec)  # the board is the world: z = 0
    k = np.array([[900.0, 0, 399.5], [0, 900, 299.5], [0, 0, 1]])
    dist = np.array([-0.05, 0.01, 0, 0, 0])
    left = CameraView(k, dist, np.array([0.25, -0.2, 0.02]), np.array([-60.0, 0.0, 480.0]))
    right = CameraView(k, dist, np.array([0.2, 0.25, -0.03]), np.array([60.0, 10.0, 470.0]))
    seen = []
    for view in (left, right):
        markers = detect_markers(render_view(points, view))
        seen.append({m.id: m.center for m in markers})
    found = triangulate(seen[0], seen[1], left, right)
    assert {p.id for p in found} == set(points)
    errors = [np.linalg.norm(np.subtract(p.position, points[p.id])) for p in found]
    assert np.median(errors) < 0.1 and max(errors) < 0.5  # mm
    assert max(max(p.errors_px) for p in found) < 0.5
    assert found[0].to_dict()["position_mm"] == pytest.approx(list(found[0].position))
