"""The vectorised (all contours at once) functions equal their per-contour references."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.synthetic import shapes
from labauto.vision.contours import canny_contours
from labauto.vision.descriptors import (
    drop_repeated_points,
    drop_repeated_points_batch,
    polygon_area_centroid,
    polygon_area_centroid_batch,
    shape_descriptors,
    shape_descriptors_batch,
)
from labauto.vision.detector import DetectorParams, detect
from labauto.vision.ellipse_fit import fit_ellipse_geometric
from labauto.vision.gradient import color_gradient
from labauto.vision.harmonics import classify_shape, classify_shapes
from labauto.vision.shape_angle import shape_angles


def _concat(contours: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    offsets = np.concatenate(([0], np.cumsum([len(c) for c in contours]))).astype(np.int64)
    return np.concatenate(contours).astype(np.float64), offsets


def _random_contours(seed: int) -> list[np.ndarray]:
    """Star-shaped and ragged polygons, with repeated points, plus degenerate cases."""
    gen = np.random.default_rng(seed)
    out = []
    for _ in range(40):
        n = int(gen.integers(3, 120))
        t = np.sort(gen.uniform(0, 2 * np.pi, n))
        r = gen.uniform(5, 40) * (1 + gen.uniform(0, 0.6) * gen.standard_normal(n).clip(-1, 1))
        pts = np.column_stack((50 + np.abs(r) * np.cos(t), 60 + np.abs(r) * np.sin(t)))
        if gen.random() < 0.3:
            pts = np.rint(pts)  # pixel chains repeat points
        if gen.random() < 0.2:
            pts = np.vstack((pts, pts[:1]))  # last point equals the first
        if gen.random() < 0.2:
            pts = pts[: max(3, n // 3)]  # an open arc
        out.append(pts)
    out.append(np.array([[1.0, 1.0]] * 5))  # one distinct point
    out.append(np.array([[0.0, 0.0], [3.0, 4.0], [0.0, 0.0], [3.0, 4.0]]))  # two distinct
    out.append(np.array([[0.0, 0.0], [1.0, 1.0]]))  # too short
    out.append(np.column_stack((np.arange(30.0), 2 * np.arange(30.0))))  # a straight line
    out.append(np.array([[0, 0], [10, 10], [10, 0], [0, 10]], float))  # a bow tie
    return out


def _scene_contours() -> tuple[np.ndarray, np.ndarray, object]:
    img, _ = shapes.make_scene(np.random.default_rng(11), 480, 360, 10, 14)
    contours = canny_contours(img)
    angles = shape_angles(contours.points, contours.gradients, contours.offsets, contours.closed)
    return contours.points, contours.offsets, angles


def _single_label(points: np.ndarray, **kw: object) -> str | None:
    try:
        return classify_shape(points, **kw)
    except ValueError:
        return None


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_drop_repeated_points_batch(seed: int) -> None:
    contours = _random_contours(seed)
    pts, offsets = _concat(contours)
    q, q_off = drop_repeated_points_batch(pts, offsets)
    for k, c in enumerate(contours):
        assert np.array_equal(q[q_off[k] : q_off[k + 1]], drop_repeated_points(c, closed=True))


@pytest.mark.parametrize("seed", [0, 1])
def test_polygon_area_centroid_batch(seed: int) -> None:
    contours = _random_contours(seed)
    area, centroid = polygon_area_centroid_batch(*_concat(contours))
    for k, c in enumerate(contours):
        a, cen = polygon_area_centroid(np.asarray(c, float))
        assert area[k] == pytest.approx(a, rel=1e-9, abs=1e-9)
        assert centroid[k] == pytest.approx(cen, rel=1e-9, abs=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2, "scene"])
def test_shape_descriptors_batch_equals_single(seed: int | str) -> None:
    if seed == "scene":
        pts, offsets, _ = _scene_contours()
        contours = [pts[offsets[k] : offsets[k + 1]] for k in range(len(offsets) - 1)]
    else:
        contours = _random_contours(int(seed))
        pts, offsets = _concat(contours)
    batch = shape_descriptors_batch(pts, offsets)
    for k, c in enumerate(contours):
        try:
            single = shape_descriptors(c)
        except ValueError:
            assert not batch.valid[k]
            continue
        assert batch.valid[k]
        for name in ("area", "semi_major", "semi_minor", "rectangularity"):
            assert getattr(batch, name)[k] == pytest.approx(
                getattr(single, name), rel=1e-5, abs=1e-6
            ), name
        assert batch.centroid[k] == pytest.approx(single.centroid, rel=1e-9, abs=1e-7)
        assert batch.elongation[k] == pytest.approx(single.elongation, rel=1e-5)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("with_centroids", [False, True])
def test_classify_shapes_equals_classify_shape_on_random_polygons(
    seed: int, with_centroids: bool
) -> None:
    contours = _random_contours(seed)
    pts, offsets = _concat(contours)
    gen = np.random.default_rng(seed + 100)
    k = len(contours)
    d_alpha = gen.uniform(0, 90, k)
    d_alpha[3] = np.nan
    inside = gen.random(k) < 0.8
    centroids = np.array([np.mean(c, axis=0) for c in contours]) if with_centroids else None
    labels = classify_shapes(
        pts,
        offsets,
        d_alpha=d_alpha,
        centroid_inside=inside,
        des_threshold_deg=60.0,
        centroids=centroids,
    )
    for j, c in enumerate(contours):
        centroid = None if centroids is None else tuple(centroids[j])
        expected = _single_label(
            c,
            d_alpha=d_alpha[j],
            centroid_inside=bool(inside[j]),
            des_threshold_deg=60.0,
            centroid=centroid,
        )
        assert labels[j] == expected, j


def test_classify_shapes_equals_classify_shape_on_a_scene() -> None:
    pts, offsets, angles = _scene_contours()
    labels = classify_shapes(
        pts,
        offsets,
        d_alpha=angles.d_alpha_median,
        centroid_inside=angles.centroid_inside,
        des_threshold_deg=60.0,
        centroids=angles.centroid,
    )
    assert {"ellipse", "rectangle"} <= set(labels)
    for k in range(len(offsets) - 1):
        expected = _single_label(
            pts[offsets[k] : offsets[k + 1]],
            d_alpha=float(angles.d_alpha_median[k]),
            centroid_inside=bool(angles.centroid_inside[k]),
            des_threshold_deg=60.0,
            centroid=tuple(angles.centroid[k]),
        )
        assert labels[k] == expected, k


def test_classify_shapes_edge_cases() -> None:
    assert classify_shapes(np.zeros((0, 2)), np.array([0]), d_alpha=[], centroid_inside=[]) == []
    with pytest.raises(ValueError, match="offsets"):
        classify_shapes(np.zeros((5, 2)), np.array([0, 4]), d_alpha=[1.0], centroid_inside=[1])
    nan_pts = np.array([[0, 0], [1, 0], [np.nan, 1], [5, 5], [6, 5], [6, 7]], float)
    labels = classify_shapes(
        nan_pts, np.array([0, 3, 6]), d_alpha=[10.0, 10.0], centroid_inside=[True, True]
    )
    assert labels[0] is None and labels[1] is not None


def test_detector_labels_and_fits_equal_the_per_contour_functions() -> None:
    img, _ = shapes.make_scene(np.random.default_rng(4), 480, 360, 10, 14)
    params = DetectorParams()
    result = detect(img, params)
    fitted = 0
    for obj in result.objects:
        expected = _single_label(
            obj.points,
            d_alpha=obj.d_alpha_median,
            centroid_inside=obj.centroid_inside,
            closed=obj.closed,
            des_threshold_deg=params.des_threshold_deg,
            centroid=obj.centroid,
        )
        assert obj.shape == ("unknown" if expected is None else expected)
        if obj.is_des and obj.shape in ("circle", "ellipse"):
            single = fit_ellipse_geometric(obj.points)  # fully converged, tol 1e-9
            assert obj.ellipse is not None
            assert obj.ellipse.center == pytest.approx(single.ellipse.center, abs=1e-4)
            assert obj.ellipse.axes == pytest.approx(single.ellipse.axes, abs=1e-4)
            fitted += 1
    assert fitted >= 8


def _reference_gradient(image: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Channel by channel: blur, 3x3 Sobel, keep the first channel of largest L1 magnitude."""
    best = gx = gy = None
    for c in range(image.shape[2]):
        channel = image[..., c].copy()
        if sigma > 0:
            k = 2 * max(1, round(2.0 * sigma)) + 1
            channel = cv2.GaussianBlur(channel, (k, k), sigma)
        dx, dy = cv2.spatialGradient(channel)
        strength = np.abs(dx.astype(np.int32)) + np.abs(dy.astype(np.int32))
        if best is None:
            best, gx, gy = strength, dx.copy(), dy.copy()
        else:
            stronger = strength > best
            gx[stronger], gy[stronger] = dx[stronger], dy[stronger]
            best = np.maximum(best, strength)
    return gx, gy


@pytest.mark.parametrize("sigma", [0.0, 0.7, 1.2])
def test_color_gradient_picks_the_strongest_channel(sigma: float) -> None:
    gen = np.random.default_rng(int(10 * sigma))
    img = gen.integers(0, 256, (31, 45, 3), dtype=np.uint8)
    img[5:20, 10:30] = (200, 40, 90)
    gx, gy = color_gradient(img, sigma)
    rx, ry = _reference_gradient(img, sigma)
    assert np.array_equal(gx, rx) and np.array_equal(gy, ry)
