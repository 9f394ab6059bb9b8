"""The shape kernel (labauto.vision.kernels.shape) against independent plain numpy references."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from labauto.vision.descriptors import (
    convex_hull,
    measure_contours,
    min_area_box,
    polygon_area_centroid,
    shape_descriptors,
    shape_descriptors_batch,
)
from labauto.vision.harmonics import classify_shapes, polar_fourier_series
from labauto.vision.kernels import shape as kernel


def _concat(contours: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    offsets = np.concatenate(([0], np.cumsum([len(c) for c in contours]))).astype(np.int64)
    points = np.concatenate(contours) if contours else np.zeros((0, 2))
    return np.ascontiguousarray(points, dtype=np.float64), offsets


def _star_polygon(gen: np.random.Generator, n: int) -> np.ndarray:
    """A random polygon star-shaped about (30, 40): n >= 5 vertices at radii 5-25, angular
    steps below 0.76 pi, so every edge passes at least 1.8 from (30, 40)."""
    t = (np.arange(n) + gen.uniform(0, 0.9, n)) * 2 * np.pi / n
    r = gen.uniform(5, 25, n)
    return np.column_stack((30 + r * np.cos(t), 40 + r * np.sin(t)))


# ------------------------------------------------------------------------- references


def _hull_reference(points: np.ndarray) -> set[tuple[float, float]]:
    """Hull vertices by brute force: p is a vertex iff the directions from p to all other
    points leave a gap wider than pi (a line through p has them all strictly on one side)."""
    pts = np.unique(points, axis=0)
    out = set()
    for i, p in enumerate(pts):
        d = np.delete(pts, i, axis=0) - p
        if len(d) == 0:
            out.add(tuple(p))
            continue
        a = np.sort(np.arctan2(d[:, 1], d[:, 0]))
        gaps = np.append(np.diff(a), 2 * np.pi - (a[-1] - a[0]))
        if gaps.max() > np.pi + 1e-9:
            out.add(tuple(p))
    return out


def _box_reference(points: np.ndarray) -> tuple[float, float]:
    """Minimum-area box by trying every hull edge direction against every point (numpy); of
    boxes with the same area, the least elongated."""
    hull = convex_hull(points)
    if len(hull) < 3:
        return min_area_box(points)
    boxes = []
    for i in range(len(hull)):
        e = hull[(i + 1) % len(hull)] - hull[i]
        u = e / np.hypot(*e)
        v = np.array([-u[1], u[0]])
        a, b = np.ptp(points @ u), np.ptp(points @ v)
        boxes.append((a * b, max(a, b), min(a, b)))
    best = min(area for area, _, _ in boxes)
    ties = [(long_ / short, long_, short) for area, long_, short in boxes if area <= best * 1.0001]
    return min(ties)[1:]


def _series_reference(points: np.ndarray, centre: np.ndarray, n: int, power: int) -> np.ndarray:
    """Coefficients of r**power about centre by Gauss-Legendre quadrature along every edge
    (8 pieces of 48 nodes): theta' = cross(p, e) / |p|^2 per unit of the edge parameter."""
    x, w = np.polynomial.legendre.leggauss(48)
    s = ((x[None, :] + 1) / 2 + np.arange(8)[:, None]).ravel() / 8
    w = np.tile(w / 16, 8)
    p0 = points - centre
    e = np.roll(p0, -1, axis=0) - p0
    p = p0[:, None, :] + s[None, :, None] * e[:, None, :]
    r2 = (p**2).sum(axis=-1)
    cross = p0[:, 0] * e[:, 1] - p0[:, 1] * e[:, 0]
    dtheta = cross[:, None] / r2 * w
    z = (p[..., 0] + 1j * p[..., 1]) / np.sqrt(r2)
    winding = round(dtheta.sum() / (2 * np.pi))
    coeffs = np.array([np.sum(r2 ** (power / 2) * z**k * dtheta) for k in range(n + 1)])
    return coeffs / (np.pi * winding)


def _moments_reference(points: np.ndarray) -> tuple[float, np.ndarray, float, float]:
    """Area, centroid and moment semi-axes of a polygon by a fan of triangles from vertex 0."""
    a, b, c = points[0], points[1:-1], points[2:]
    cross = (b[:, 0] - a[0]) * (c[:, 1] - a[1]) - (b[:, 1] - a[1]) * (c[:, 0] - a[0])
    area = 0.5 * cross  # signed triangle areas
    cen = (area[:, None] * (a + b + c) / 3).sum(axis=0) / area.sum()
    # second moments of a triangle about the origin: A/6 (sum of v_i v_j^T over i <= j pairs)
    pa, pb, pc = a - cen, b - cen, c - cen
    m = np.zeros((2, 2))
    for k in range(len(area)):
        v = np.stack((pa, pb[k], pc[k]))
        s = v.sum(axis=0)
        m += area[k] / 12 * (np.outer(s, s) + v.T @ v)
    m /= area.sum()
    l2, l1 = np.linalg.eigvalsh(m)
    return abs(area.sum()), cen, 2 * math.sqrt(l1), 2 * math.sqrt(max(l2, 0.0))


# ------------------------------------------------------------------------------ tests


@pytest.mark.parametrize("seed", range(6))
def test_convex_hull_and_box_against_brute_force(seed: int) -> None:
    gen = np.random.default_rng(seed)
    for n in (1, 2, 3, 5, 17, 60):
        pts = gen.uniform(-50, 50, (n, 2))
        if seed % 2:
            pts = np.rint(pts / 5) * 5  # ties, repeats and collinear runs
        hull = convex_hull(pts)
        assert {tuple(p) for p in hull} == _hull_reference(pts)
        if len(hull) >= 3:  # counter-clockwise and strictly convex
            d1 = np.roll(hull, -1, axis=0) - hull
            d2 = np.roll(hull, -2, axis=0) - np.roll(hull, -1, axis=0)
            assert np.all(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0] > 0)
        long_, short = min_area_box(pts)
        ref_long, ref_short = _box_reference(pts)
        assert long_ * short == pytest.approx(ref_long * ref_short, rel=1e-12, abs=1e-9)
        assert long_ / max(short, 1e-300) <= ref_long / max(ref_short, 1e-300) * (1 + 1e-9)
        if len(np.unique(pts, axis=0)) >= 3:
            (_, (w, h), _) = cv2.minAreaRect(pts.astype(np.float32))
            assert long_ * short == pytest.approx(w * h, rel=1e-5, abs=1e-3)


@pytest.mark.parametrize("seed", range(4))
def test_hull_and_box_of_pixel_contours_and_points_on_the_split_line(seed: int) -> None:
    """The hull splits the sorted points by the line from the first to the last one: points on
    that line, many points per column, and long hulls (the calipers' many small steps)."""
    gen = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    a, b, phi = gen.uniform(20, 60), gen.uniform(3, 20), gen.uniform(0, np.pi)
    ellipse = np.column_stack(
        (
            100 + a * np.cos(t) * np.cos(phi) - b * np.sin(t) * np.sin(phi),
            80 + a * np.cos(t) * np.sin(phi) + b * np.sin(t) * np.cos(phi),
        )
    )
    on_line = np.column_stack((np.arange(0.0, 11.0), 0.5 * np.arange(0.0, 11.0)))
    cases = [
        np.rint(ellipse),  # a pixel contour
        ellipse,  # a long hull
        on_line,  # every point on the line from the first to the last
        np.vstack((on_line, [[4.0, 5.0], [6.0, -3.0], [3.0, 1.5]])),  # and off it
        np.vstack((gen.uniform(0, 10, (30, 2)) * [3, 1], [[0.0, 0.0], [30.0, 10.0], [15.0, 5.0]])),
    ]
    for pts in cases:
        hull = convex_hull(pts)
        assert {tuple(p) for p in hull} == _hull_reference(pts)
        long_, short = min_area_box(pts)
        ref_long, ref_short = _box_reference(pts)
        assert long_ * short == pytest.approx(ref_long * ref_short, rel=1e-12, abs=1e-9)
        assert long_ / max(short, 1e-300) <= ref_long / max(ref_short, 1e-300) * (1 + 1e-9)


def test_box_of_a_triangle_is_the_least_elongated_of_its_three() -> None:
    tri = np.array([[0.0, 0.0], [40.0, 0.0], [25.0, 30.0]])  # acute
    boxes = []
    for i in range(3):  # every edge's box has area 2 * triangle area = 1200
        e = tri[(i + 1) % 3] - tri[i]
        u = e / np.hypot(*e)
        a, b = np.ptp(tri @ u), np.ptp(tri @ np.array([-u[1], u[0]]))
        boxes.append((max(a, b), min(a, b)))
    expected = min(boxes, key=lambda s: s[0] / s[1])
    for start in range(3):
        for pts in (np.roll(tri, start, axis=0), np.roll(tri, start, axis=0)[::-1]):
            assert min_area_box(pts) == pytest.approx(expected, rel=1e-12)


def test_box_of_degenerate_point_sets() -> None:
    assert min_area_box(np.array([[3.0, 4.0]])) == (0.0, 0.0)
    assert min_area_box(np.array([[0.0, 0.0], [3.0, 4.0], [0.0, 0.0]])) == (5.0, 0.0)
    line = np.column_stack((np.arange(10.0), 2 * np.arange(10.0)))
    assert min_area_box(line) == pytest.approx((math.hypot(9, 18), 0.0))
    assert len(convex_hull(line)) == 2
    assert min_area_box(np.array([[0, 0], [4, 0], [4, 3], [0, 3]], float)) == (4.0, 3.0)


@pytest.mark.parametrize("seed", range(4))
def test_area_centroid_and_moments_against_triangle_fan(seed: int) -> None:
    gen = np.random.default_rng(seed)
    contours = [_star_polygon(gen, int(gen.integers(5, 40))) for _ in range(12)]
    pts, off = _concat(contours)
    measured = measure_contours(pts, off)
    v = measured.values
    assert np.all(measured.status == kernel.OK)
    for k, c in enumerate(contours):
        area, cen, a, b = _moments_reference(c)
        assert v["area"][k] == pytest.approx(area, rel=1e-12)
        assert (v["centroid_x"][k], v["centroid_y"][k]) == pytest.approx(tuple(cen), rel=1e-12)
        assert v["semi_major"][k] == pytest.approx(a, rel=1e-10)
        assert v["semi_minor"][k] == pytest.approx(b, rel=1e-10)
        seg = np.hypot(*(np.roll(c, -1, axis=0) - c).T)
        assert v["perimeter"][k] == pytest.approx(seg.sum(), rel=1e-13)
        assert v["closing"][k] == pytest.approx(seg[-1], rel=1e-13)
        assert polygon_area_centroid(c)[0] == pytest.approx(area, rel=1e-12)


@pytest.mark.parametrize("power", [1, -2])
@pytest.mark.parametrize("seed", range(4))
def test_polar_series_against_quadrature(seed: int, power: int) -> None:
    gen = np.random.default_rng(seed)
    contours = [_star_polygon(gen, int(gen.integers(5, 50))) for _ in range(10)]
    pts, off = _concat(contours)
    centres = np.array([[30.0, 40.0]] * len(contours)) + gen.uniform(-1, 1, (len(contours), 2))
    measured = measure_contours(pts, off, centroids=centres, n_r=8, n_rho=8)
    assert np.all(measured.series_status == kernel.SERIES_OK)
    for k, c in enumerate(contours):
        ref = _series_reference(c, centres[k], 8, power)
        got = measured.r[k] if power == 1 else measured.rho[k]
        assert np.abs(got - ref).max() <= 1e-11 * abs(ref[0])
        a, b = polar_fourier_series(c, tuple(centres[k]), 8, power=power)
        assert np.array_equal(a + 1j * b, got)  # the single-contour function: a batch of one


def test_polar_series_of_every_length_against_quadrature() -> None:
    """The kernel works on the vertices and edges 8 at a time (vectorised, 8 partial sums):
    contours of every length around multiples of 8, both orientations, up to harmonic 12."""
    gen = np.random.default_rng(7)
    contours = []
    for n in [*range(3, 20), 31, 32, 33, 63, 64, 65]:
        t = (np.arange(n) + gen.uniform(0, 0.5, n)) * 2 * np.pi / n
        rad = gen.uniform(8, 12, n)
        c = np.column_stack((30 + rad * np.cos(t), 40 + rad * np.sin(t)))
        contours += [c, c[::-1].copy()]
    pts, off = _concat(contours)
    centres = np.array([[30.0, 40.0]] * len(contours)) + gen.uniform(-1, 1, (len(contours), 2))
    measured = measure_contours(pts, off, centroids=centres, n_r=12, n_rho=12)
    assert np.all(measured.series_status == kernel.SERIES_OK)
    assert np.array_equal(measured.values["winding"], np.tile([1.0, -1.0], len(contours) // 2))
    for k, c in enumerate(contours):
        for power, got in ((1, measured.r[k]), (-2, measured.rho[k])):
            ref = _series_reference(c, centres[k], 12, power)
            assert np.abs(got - ref).max() <= 1e-11 * abs(ref[0])


def test_polar_series_with_edges_through_the_centre() -> None:
    # an edge on a ray from the centre and a vertex at the centre (a "pac-man" whose mouth
    # corner is the centre) add nothing: their weights are 0 (and the vertex's direction too)
    radial = np.array([[5.0, 0.0], [10.0, 0.0], [0.0, 10.0], [-10.0, 0.0], [0.0, -10.0]])
    pacman = np.array(
        [[0.0, 0.0], [10.0, 0.0], [7.0, 8.0], [-9.0, 6.0], [-6.0, -9.0], [0.0, -11.0]]
    )
    pts, off = _concat([radial, pacman])
    centres = np.zeros((2, 2))
    measured = measure_contours(pts, off, centroids=centres, n_r=8, n_rho=8)
    assert np.all(measured.series_status == kernel.SERIES_OK)
    assert np.array_equal(measured.values["winding"], [1.0, 1.0])
    for k, c in enumerate((radial, pacman)):
        for power, got in ((1, measured.r[k]), (-2, measured.rho[k])):
            ref = _series_reference(c, centres[k], 8, power)
            assert np.abs(got - ref).max() <= 1e-11 * abs(ref[0])


def test_threads_do_not_change_results() -> None:
    gen = np.random.default_rng(5)
    contours = [_star_polygon(gen, int(gen.integers(5, 200))) for _ in range(60)]
    pts, off = _concat(contours)
    want = np.ones(len(contours), np.uint8)
    centres = np.zeros((len(contours), 2))
    one = kernel.measure_contours(pts, off, 3, want, centres, False, math.inf, 3, 8, 1)
    two = kernel.measure_contours(pts, off, 3, want, centres, False, math.inf, 3, 8, 2)
    for x, y in zip(one, two, strict=True):
        assert np.array_equal(x, y, equal_nan=True)


def test_status_of_degenerate_contours() -> None:
    contours = [
        np.array([[0.0, 0.0], [1.0, 1.0]]),  # too few points
        np.array([[0.0, 0.0], [1.0, np.nan], [2.0, 0.0]]),  # not finite
        np.array([[2.0, 2.0]] * 4),  # one distinct point
        np.array([[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]], float),  # closed square
        np.column_stack((np.arange(9.0), np.zeros(9))),  # a straight line: no area
    ]
    measured = measure_contours(*_concat(contours), n_r=3, n_rho=8)
    assert measured.status.tolist() == [
        kernel.TOO_FEW_POINTS,
        kernel.NON_FINITE,
        kernel.ONE_POINT,
        kernel.OK,
        kernel.OK,
    ]
    assert measured.series_status.tolist()[3:] == [kernel.SERIES_OK, kernel.SERIES_NO_AREA]
    assert np.isnan(measured.values["area"][:3]).all()
    assert measured.values["area"][3] == 100.0 and measured.values["rectangularity"][3] == 1.0
    assert measured.values["elongation"][4] == math.inf and measured.values["area"][4] == 0.0
    assert measured.values["centroid_x"][4] == pytest.approx(4.0)  # the curve centroid


def test_empty_batch_and_one_contour() -> None:
    measured = measure_contours(np.zeros((0, 2)), np.array([0]), n_r=3, n_rho=8)
    assert measured.status.shape == (0,) and measured.r.shape == (0, 4)
    assert shape_descriptors_batch(np.zeros((0, 2)), np.array([0])).valid.shape == (0,)
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], float)
    batch = shape_descriptors_batch(square, np.array([0, 4]))
    single = shape_descriptors(square)
    assert batch.valid[0] and batch.area[0] == single.area == 16.0
    assert batch.elongation[0] == single.elongation == 1.0
    with pytest.raises(ValueError, match="offsets"):
        measure_contours(square, np.array([0, 3]))


def test_contours_touching_the_image_border() -> None:
    """Pixel chains of shapes cut by the image border (cv2.findContours on a clipped mask)."""
    mask = np.zeros((60, 80), np.uint8)
    cv2.ellipse(mask, (0, 30), (25, 15), 0, 0, 360, 255, -1)  # cut by the left border
    cv2.rectangle(mask, (60, -5), (90, 20), 255, -1)  # the top-right corner
    cv2.circle(mask, (40, 59), 10, 255, -1)  # the bottom border
    found, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    contours = [c[:, 0, :].astype(np.float64) for c in found]
    pts, off = _concat(contours)
    batch = shape_descriptors_batch(pts, off)
    for k, c in enumerate(contours):
        single = shape_descriptors(c)
        assert batch.valid[k]
        assert batch.area[k] == single.area == pytest.approx(cv2.contourArea(c.astype(np.float32)))
        assert batch.rectangularity[k] == single.rectangularity
        assert min_area_box(c) == pytest.approx(_box_reference(c), rel=1e-12)
    labels = classify_shapes(
        pts, off, d_alpha=np.full(len(contours), 10.0), centroid_inside=np.ones(len(contours))
    )
    assert "rectangle" in labels


def test_hull_values_do_not_depend_on_where_the_contour_starts() -> None:
    """The convex perimeter and the box (elongation) come from the sorted points only: the same
    bits for every start and both directions of a contour (the sort is handed the points from
    the contour's last run on, which changes with the start)."""
    gen = np.random.default_rng(11)
    mask = np.zeros((80, 80), np.uint8)
    cv2.ellipse(mask, (40, 40), (30, 12), 35, 0, 360, 255, -1)
    pixel = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0][0][:, 0, :]
    for c in (pixel.astype(np.float64), _star_polygon(gen, 40)):
        variants = [np.roll(c, s, axis=0) for s in range(0, len(c), 3)]
        variants += [v[::-1].copy() for v in variants]
        measured = measure_contours(*_concat(variants))
        for name in ("convex_perimeter", "elongation"):
            column = measured.values[name]
            assert (column == column[0]).all(), name
        assert min_area_box(c) == pytest.approx(_box_reference(c), rel=1e-12)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_non_finite_coordinate_anywhere_is_found(bad: float) -> None:
    square = np.array([[0, 0], [4, 0], [4, 4], [0, 4]], float)
    contours = []
    for i in range(8):
        c = square.copy()
        c.flat[i] = bad
        contours.append(c)
    measured = measure_contours(*_concat([*contours, square]))
    assert measured.status.tolist() == [kernel.NON_FINITE] * 8 + [kernel.OK]
