"""D_alpha (eq. 3) against values computed from the exact geometry.

Base size: every shape fits a circle of radius R0 = 120 px at scale 1 (square: half-diagonal
R0; triangle and star: circumradius R0; ellipses: semi-major axis R0; line: length 2 R0, 4 px
wide), so scales 0.5x-4x span radii 60-480 px. The error of a rendered shape is dominated by
corners, which the blur and the 3x3 Sobel round over ~1.5 px, so it falls as 1/size: at a
circumradius of 40 px squares/triangles/stars read up to ~2-3 degrees low (measured, see the
report), at 60 px and more they stay within 2 degrees. Circles and ellipses stay within 1 degree
at all sizes tested.
"""

from __future__ import annotations

import math
import statistics
from fractions import Fraction

import numpy as np
import pytest
from vision_helpers import analytic_d_alpha, largest, render_alone

from labauto.synthetic import shapes
from labauto.vision.detector import DetectorParams, detect
from labauto.vision.shape_angle import (
    OPEN_MIN_AREA_RATIO,
    gap_fractions,
    points_in_polygons,
    polygon_centroids,
    shape_angle,
    shape_angles,
)

R0 = 120.0
FAST = DetectorParams(classify=False, fit_ellipses=False)


def make(kind: str, scale: float, angle: float) -> shapes.Shape:
    r = R0 * scale
    size = 2 * r + 24
    c = (size / 2 + 0.37, size / 2 - 0.21)  # sub-pixel centre
    if kind == "circle":
        return shapes.ellipse(c, (r, r), angle)
    if kind.startswith("ellipse"):
        ratio = float(kind.split(":")[1])
        return shapes.ellipse(c, (r, r / ratio), angle)
    if kind == "square":
        return shapes.square(c, r * np.sqrt(2.0), angle)
    if kind == "triangle":
        return shapes.triangle(c, r, angle)
    if kind == "star":
        return shapes.star(c, r, 0.5 * r, 5, angle)
    if kind == "line":
        d = np.array([np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))]) * r
        return shapes.line(np.array(c) - d, np.array(c) + d, 4.0)
    raise ValueError(kind)


KINDS = ["circle", "ellipse:1.5", "ellipse:2", "ellipse:3", "ellipse:4"]
KINDS += ["square", "triangle", "star", "line"]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("scale", [0.5, 1.0, 2.0, 4.0])
def test_rendered_d_alpha_matches_exact_geometry(kind: str, scale: float) -> None:
    for angle in (0.0, 37.0, 90.0, 151.0):
        shape = make(kind, scale, angle)
        size = int(2 * R0 * scale + 24)
        obj = largest(detect(render_alone(shape, size), FAST))
        median, mean = analytic_d_alpha(shape)
        assert obj.d_alpha_median == pytest.approx(median, abs=2.0), (angle, obj)
        assert obj.d_alpha_mean == pytest.approx(mean, abs=2.0), (angle, obj)
        assert obj.centroid_inside
        assert np.hypot(*(np.array(obj.centroid) - shape.centroid)) < 0.5


def test_analytic_reference_values() -> None:
    """The exact-geometry helper reproduces the closed forms quoted in the issue."""
    median, mean = analytic_d_alpha(shapes.square((0, 0), 10.0, 0.0), spacing=0.001)
    assert mean == pytest.approx(45.0 - np.degrees(np.log(2.0)) / 2.0, abs=1e-3)
    assert median == pytest.approx(np.degrees(np.arctan(0.5)), abs=1e-3)
    circle = shapes.ellipse((0, 0), (9.0, 9.0))
    assert analytic_d_alpha(circle)[0] == pytest.approx(0.0, abs=0.1)  # 2048-gon normals


@pytest.mark.parametrize("radius", [10.0, 14.5, 25.0, 60.0])
@pytest.mark.parametrize("bright", [True, False])
def test_circle_is_nearly_zero(radius: float, bright: bool) -> None:
    size = int(2 * radius + 20)
    shape = shapes.ellipse((size / 2 + 0.3, size / 2 - 0.4), (radius, radius))
    fg, bg = (210.0, 30.0) if bright else (30.0, 210.0)
    obj = largest(detect(render_alone(shape, size, background=bg, color=fg), FAST))
    assert obj.d_alpha_median < 6.0
    assert obj.d_alpha_mean < 6.0
    assert obj.is_des


def test_polarity_invariance() -> None:
    shape = shapes.deformed_ellipse((60.3, 60.6), (40, 25), 30)
    a = largest(detect(render_alone(shape, 121, background=30, color=220), FAST))
    b = largest(detect(render_alone(shape, 121, background=220, color=30), FAST))
    assert a.d_alpha_median == pytest.approx(b.d_alpha_median, abs=0.5)
    assert a.d_alpha_mean == pytest.approx(b.d_alpha_mean, abs=0.5)


def test_exact_points_give_exact_values() -> None:
    """On exact boundary samples with exact normals the function returns the analytic values."""
    shape = shapes.triangle((10.0, -3.0), 50.0, 12.0)
    pts, normals = shape.boundary_samples(0.05)
    median, mean = analytic_d_alpha(shape, spacing=0.05)
    got_median, got_mean, centroid, inside = shape_angle(pts, -3.0 * normals)
    # the function uses the centroid of the sampled polygon, 1e-6 px from the exact one
    assert got_median == pytest.approx(median, abs=1e-4)
    assert got_mean == pytest.approx(mean, abs=1e-4)
    assert centroid == pytest.approx(shape.centroid, abs=1e-5)
    assert inside


def test_line_points_read_90() -> None:
    x = np.arange(50.0)
    pts = np.column_stack((x, np.zeros_like(x)))
    grads = np.tile([0.0, 1.0], (50, 1))
    median, mean, _, inside = shape_angle(pts, grads)
    assert median == pytest.approx(90.0, abs=1e-6)
    assert mean == pytest.approx(90.0, abs=2.5)  # the two points nearest the centroid are 90
    assert not inside


def test_vectorised_equals_one_by_one(rng: np.random.Generator) -> None:
    contours, grads = [], []
    for n in (7, 50, 333, 8):
        t = np.sort(rng.uniform(0, 2 * np.pi, n))
        r = rng.uniform(5, 9, n)
        pts = np.column_stack((r * np.cos(t), r * np.sin(t))) + rng.uniform(-50, 50, 2)
        contours.append(pts)
        grads.append(rng.normal(size=(n, 2)))
    offsets = np.concatenate(([0], np.cumsum([len(c) for c in contours])))
    batch = shape_angles(np.vstack(contours), np.vstack(grads), offsets)
    for k, (pts, g) in enumerate(zip(contours, grads, strict=True)):
        median, mean, centroid, inside = shape_angle(pts, g)
        assert batch.d_alpha_median[k] == pytest.approx(median)
        assert batch.d_alpha_mean[k] == pytest.approx(mean)
        assert batch.d_alpha_median[k] == pytest.approx(
            np.median(_alpha(pts, g, np.array(centroid)))
        )
        assert tuple(batch.centroid[k]) == pytest.approx(centroid)
        assert bool(batch.centroid_inside[k]) == inside


def _alpha(pts: np.ndarray, g: np.ndarray, c: np.ndarray) -> np.ndarray:
    m = c - pts
    cos = np.abs((g * m).sum(1)) / (np.hypot(*g.T) * np.hypot(*m.T))
    return np.degrees(np.arccos(np.minimum(cos, 1.0)))  # eq. 3 as written


def test_polygon_centroid_and_inside() -> None:
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    # a thick L: its area centroid (2.5, 2.5) lies inside; a thin C's does not
    ell = np.array([[0, 0], [6, 0], [6, 3], [3, 3], [3, 6], [0, 6]], float)
    cee = np.array([[0, 0], [6, 0], [6, 1], [1, 1], [1, 5], [6, 5], [6, 6], [0, 6]], float)
    pts = np.vstack((square, ell, cee))
    offsets = np.array([0, 4, 10, 18])
    closed = np.array([True, True, True])
    centroid, area = polygon_centroids(pts, offsets, closed)
    assert centroid[0] == pytest.approx([2.0, 2.0])
    assert area == pytest.approx([16.0, 27.0, 16.0])
    assert centroid[1] == pytest.approx([2.5, 2.5])
    inside = points_in_polygons(centroid, pts, offsets)
    assert inside.tolist() == [True, True, False]
    # open contours: the chord-closed polygon, or the mean of the points for a line
    centroid_open, _ = polygon_centroids(pts, offsets, ~closed)
    assert centroid_open[1] == pytest.approx([2.5, 2.5])
    line = np.column_stack((np.arange(10.0), 0.002 * np.arange(10.0) ** 2))
    centroid_line, _ = polygon_centroids(line, np.array([0, 10]), np.array([False]))
    assert centroid_line[0] == pytest.approx(line.mean(axis=0))


def test_bad_input_is_rejected() -> None:
    with pytest.raises(ValueError, match="points and gradients"):
        shape_angles(np.zeros((5, 2)), np.zeros((4, 2)), np.array([0, 5]))
    with pytest.raises(ValueError, match="offsets"):
        shape_angles(np.zeros((5, 2)), np.zeros((5, 2)), np.array([0, 4]))


# --- the compiled kernel against a plain-Python reference ---------------------------------------


def _exact_alpha(g: tuple[float, float], m: tuple[float, float]) -> float:
    """Eq. 3's angle (degrees, 90 without direction) from the exact dot and cross products.

    ``atan2(|g x m|, |g . m|)`` is eq. 3's ``arccos(|g . m| / (|g| |m|))``, but well-conditioned
    near 0 degrees too, where ``arccos`` turns a rounding of the cosine into up to 1e-8 rad.
    """
    (gx, gy), (mx, my) = [[Fraction(v) for v in pair] for pair in (g, m)]
    dot, cross = abs(gx * mx + gy * my), abs(gx * my - gy * mx)
    if dot == cross == 0:
        return 90.0
    scale = max(dot, cross)  # exact ratios of magnitude <= 1: no overflow or underflow
    return math.degrees(math.atan2(float(cross / scale), float(dot / scale)))


def _reference(pts: np.ndarray, grads: np.ndarray, closed: bool) -> dict:
    """Eq. 3 and the module's choices for one contour, written out in plain Python."""
    n = len(pts)
    xs, ys = [float(v) for v in pts[:, 0]], [float(v) for v in pts[:, 1]]
    mx, my = math.fsum(xs) / n, math.fsum(ys) / n
    rx, ry = [x - mx for x in xs], [y - my for y in ys]
    twice_area = cx = cy = spread = 0.0
    for i in range(n):
        j = (i + 1) % n
        cross = rx[i] * ry[j] - rx[j] * ry[i]
        twice_area += cross
        cx += (rx[i] + rx[j]) * cross
        cy += (ry[i] + ry[j]) * cross
        spread += rx[i] ** 2 + ry[i] ** 2
    ratio = 1e-6 if closed else OPEN_MIN_AREA_RATIO
    if abs(twice_area) / 2 > ratio * spread / n:
        centroid = (mx + cx / (3 * twice_area), my + cy / (3 * twice_area))
    else:
        centroid = (mx, my)
    alphas = [
        _exact_alpha(g, (centroid[0] - x, centroid[1] - y))
        for (x, y), g in zip(pts.tolist(), grads.tolist(), strict=True)
    ]
    hits = 0
    for i in range(n):
        (x0, y0), (x1, y1) = (xs[i], ys[i]), (xs[(i + 1) % n], ys[(i + 1) % n])
        if (y0 > centroid[1]) != (y1 > centroid[1]):
            hits += centroid[0] < x0 + (centroid[1] - y0) * (x1 - x0) / (y1 - y0)
    length = sum(math.hypot(xs[i + 1] - xs[i], ys[i + 1] - ys[i]) for i in range(n - 1))
    chord = math.hypot(xs[-1] - xs[0], ys[-1] - ys[0])
    gap = 0.0 if closed or length + chord == 0 else chord / (length + chord)
    return {
        "centroid": centroid,
        "mean": sum(alphas) / n,
        "median": statistics.median(alphas),
        "inside": hits % 2 == 1,
        "area": abs(twice_area) / 2,
        "gap": gap,
    }


def _random_contours(
    rng: np.random.Generator, sizes: list[int]
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Noisy star-shaped outlines of the given sizes (at least 3 points: open arcs too)."""
    contours, grads = [], []
    for n in sizes:
        span = rng.choice([2 * np.pi, rng.uniform(0.5, 2 * np.pi)])
        t = np.sort(rng.uniform(0, span, n))
        r = rng.uniform(5, 60) * rng.uniform(0.7, 1.3, n)
        centre = rng.uniform(0, 1280, 2)
        contours.append(np.column_stack((r * np.cos(t), r * np.sin(t))) + centre)
        grads.append(rng.normal(size=(n, 2)) * rng.choice([1.0, 300.0]))
    return contours, grads


def _check_against_reference(
    contours: list[np.ndarray], grads: list[np.ndarray], closed: np.ndarray
) -> None:
    offsets = np.concatenate(([0], np.cumsum([len(c) for c in contours])))
    got = shape_angles(np.vstack(contours), np.vstack(grads), offsets, closed)
    assert len(got) == len(contours)
    for k, (pts, g) in enumerate(zip(contours, grads, strict=True)):
        ref = _reference(pts, g, bool(closed[k]))
        assert tuple(got.centroid[k]) == pytest.approx(ref["centroid"], rel=1e-12, abs=1e-9), k
        assert got.area[k] == pytest.approx(ref["area"], rel=1e-9, abs=1e-9), k
        assert got.gap_fraction[k] == pytest.approx(ref["gap"], rel=1e-12, abs=1e-15), k
        assert got.d_alpha_mean[k] == pytest.approx(ref["mean"], rel=1e-10, abs=1e-10), k
        assert got.d_alpha_median[k] == pytest.approx(ref["median"], rel=1e-10, abs=1e-10), k
        assert bool(got.centroid_inside[k]) == ref["inside"], k


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_kernel_matches_plain_python_reference(rng: np.random.Generator, dtype: type) -> None:
    # small and large contours, odd and even counts, up to a few thousand points
    sizes = [3, 4, 7, 8, 9, 16, 17, 127, 128, 129, 130, 256, 257, 300, 1031, 2500]
    sizes += rng.integers(3, 400, 40).tolist()
    contours, grads = _random_contours(rng, sizes)
    grads = [g.astype(dtype) for g in grads]
    closed = rng.random(len(sizes)) < 0.5
    _check_against_reference(contours, grads, closed)


def test_degenerate_contours_match_reference(rng: np.random.Generator) -> None:
    contours = [
        np.array([[3.0, 4.0]]),  # one point: its own centroid, alpha 90
        np.array([[3.0, 4.0], [7.0, 4.0]]),  # two points
        np.full((6, 2), 9.5),  # all points equal
        np.column_stack((np.arange(30.0), 2.0 * np.arange(30.0))),  # a straight line
        np.column_stack((np.arange(30.0), 0.001 * np.arange(30.0) ** 2)),  # a shallow arc
        np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]),  # a square
    ]
    grads = [rng.normal(size=c.shape) for c in contours]
    grads[2][:] = 0.0  # no direction anywhere: alpha 90
    for closed in (False, True):
        _check_against_reference(contours, grads, np.full(len(contours), closed))
    got = shape_angles(np.vstack(contours), np.vstack(grads), [0, 1, 3, 9, 39, 69, 73])
    assert got.d_alpha_median[0] == got.d_alpha_mean[0] == 90.0
    assert got.d_alpha_median[2] == got.d_alpha_mean[2] == 90.0
    assert tuple(got.centroid[2]) == (9.5, 9.5)
    assert not got.centroid_inside[:4].any()
    assert got.centroid_inside[5]


def test_contours_touching_the_image_border(rng: np.random.Generator) -> None:
    """Shapes cut by the image border: open arcs whose ends lie on row/column 0 or the last."""
    t = np.linspace(-np.pi / 2, np.pi / 2, 200)
    left = np.column_stack((30 * np.cos(t), 500 + 30 * np.sin(t)))  # half disk on column 0
    t = np.linspace(0, np.pi, 150)
    top = np.column_stack((640 + 40 * np.cos(t), 40 * np.sin(t)))  # half disk on row 0
    corner = np.array([[1279.0, 1000.0], [1250.0, 1000.0], [1250.0, 1023.0], [1279.0, 1023.0]])
    contours = [left, top, corner, np.vstack((left, left[::-1]))]
    grads = [rng.normal(size=c.shape) for c in contours]
    _check_against_reference(contours, grads, np.array([False, False, True, False]))
    got = shape_angles(np.vstack(contours), np.vstack(grads), [0, 200, 350, 354, 754])
    assert got.centroid_inside[:3].all()
    assert got.area[:2] == pytest.approx([np.pi * 30**2 / 2, np.pi * 40**2 / 2], rel=1e-3)
    assert got.gap_fraction[0] == pytest.approx(60 / (60 + np.pi * 30), rel=1e-3)
    assert got.area[3] < 1e-9  # there and back again: no area, the centroid is the points' mean
    assert tuple(got.centroid[3]) == pytest.approx(tuple(contours[3].mean(axis=0)), abs=1e-9)


def test_median_with_ties_and_orders(rng: np.random.Generator) -> None:
    """The selection gives the median for sorted, reversed, constant and tied angles."""
    n = 301
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    circle = np.column_stack((100 * np.cos(t), 100 * np.sin(t))) + 200
    radial = np.column_stack((np.cos(t), np.sin(t)))
    tangent = np.column_stack((-np.sin(t), np.cos(t)))
    angle = rng.uniform(0, np.pi / 2, n)
    mixes = {
        "increasing": np.sort(angle),
        "decreasing": np.sort(angle)[::-1],
        "constant": np.full(n, 0.3),
        "two values": np.where(rng.random(n) < 0.5, 0.1, 1.2),
        "few values": rng.choice([0.01, 0.5, 1.0, np.pi / 2], n),
        "near zero": rng.uniform(0, 1e-7, n),
        "random": angle,
    }
    for name, a in mixes.items():
        g = np.cos(a)[:, None] * radial + np.sin(a)[:, None] * tangent
        for m in (n, n - 1, 2, 3):  # odd and even counts
            pts, grads = circle[:m], g[:m]
            median, mean, _, _ = shape_angle(pts, grads, closed=True)
            ref = _reference(pts, grads, True)
            assert median == pytest.approx(ref["median"], abs=1e-10), (name, m)
            assert mean == pytest.approx(ref["mean"], abs=1e-10), (name, m)


def test_geometry_functions_match_reference(rng: np.random.Generator) -> None:
    contours, grads = _random_contours(rng, rng.integers(3, 200, 30).tolist())
    pts = np.vstack(contours)
    offsets = np.concatenate(([0], np.cumsum([len(c) for c in contours])))
    closed = rng.random(len(contours)) < 0.5
    centroid, area = polygon_centroids(pts, offsets, closed)
    gap = gap_fractions(pts, offsets, closed)
    inside = points_in_polygons(centroid, pts, offsets)
    assert inside.dtype == bool and inside.shape == (len(contours),)
    for k, (p, g) in enumerate(zip(contours, grads, strict=True)):
        ref = _reference(p, g, bool(closed[k]))
        assert tuple(centroid[k]) == pytest.approx(ref["centroid"], rel=1e-12, abs=1e-9)
        assert area[k] == pytest.approx(ref["area"], rel=1e-9, abs=1e-9)
        assert gap[k] == pytest.approx(ref["gap"], rel=1e-12, abs=1e-15)
        assert bool(inside[k]) == ref["inside"]
    # the default closed flags: ends that are 8-neighbours
    closed_default = polygon_centroids(pts, offsets)[0]
    ends = np.abs(np.rint(pts[offsets[:-1]]) - np.rint(pts[offsets[1:] - 1])).max(axis=1) <= 1
    assert np.array_equal(closed_default, polygon_centroids(pts, offsets, ends)[0])


def test_sums_against_exact_arithmetic(rng: np.random.Generator) -> None:
    """Centroid and area equal the exact (rational) values to about 1e-15 relative.

    (They used to equal numpy's ``np.add.reduceat`` to the last bit; the kernel now sums in
    point order relative to the first point, so only rounding is pinned.)
    """
    contours, _ = _random_contours(rng, [3, 9, 130, 700, 2049])
    offsets = np.concatenate(([0], np.cumsum([len(c) for c in contours])))
    closed = np.ones(len(contours), bool)
    centroid, area = polygon_centroids(np.vstack(contours), offsets, closed)
    for k, pts in enumerate(contours):
        xs = [Fraction(v) for v in pts[:, 0]]
        ys = [Fraction(v) for v in pts[:, 1]]
        twice = cx = cy = Fraction(0)
        for i in range(len(xs)):
            j = (i + 1) % len(xs)
            cross = xs[i] * ys[j] - xs[j] * ys[i]
            twice += cross
            cx += (xs[i] + xs[j]) * cross
            cy += (ys[i] + ys[j]) * cross
        assert area[k] == pytest.approx(float(abs(twice) / 2), rel=1e-13), k
        exact = (float(cx / (3 * twice)), float(cy / (3 * twice)))
        assert tuple(centroid[k]) == pytest.approx(exact, rel=1e-14, abs=1e-12), k


@pytest.mark.parametrize("scale", [1e-150, 1e-3, 1.0, 300.0, 1e150])
def test_angles_exact_near_0_45_and_90_degrees(scale: float) -> None:
    """Every alpha of a square whose gradients are its centroid vectors turned by theta.

    The kernel's angle is accurate to rounding at any theta and any gradient scale, including
    near 0 degrees (where eq. 3's ``arccos`` form is off by up to 1e-8 rad) and 90 degrees.
    """
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])  # centroid (2, 2) exact
    m = np.array([2.0, 2.0]) - square
    for theta in (0.0, 1e-12, 1e-9, 1e-6, 0.3, np.pi / 4, 1.2, np.pi / 2 - 1e-9, np.pi / 2):
        for sign in (1.0, -1.0):  # polarity
            c, s = np.cos(theta), np.sin(theta)
            g = (
                sign
                * scale
                * np.column_stack((c * m[:, 0] - s * m[:, 1], s * m[:, 0] + c * m[:, 1]))
            )
            median, mean, centroid, _ = shape_angle(square, g, closed=True)
            assert centroid == (2.0, 2.0)
            ref = sorted(_exact_alpha(tuple(gi), tuple(mi)) for gi, mi in zip(g, m, strict=True))
            assert median == pytest.approx((ref[1] + ref[2]) / 2, rel=1e-14, abs=1e-300), theta
            assert mean == pytest.approx(sum(ref) / 4, rel=1e-14, abs=1e-300), theta
            assert median == pytest.approx(np.degrees(theta), rel=1e-9, abs=1e-13), theta


def test_empty_input() -> None:
    got = shape_angles(np.empty((0, 2)), np.empty((0, 2), np.float32), np.array([0]))
    assert len(got) == 0
    assert got.centroid.shape == (0, 2)
    assert got.centroid_inside.dtype == bool
    assert got.is_des().shape == (0,)
    assert polygon_centroids(np.empty((0, 2)), np.array([0]))[0].shape == (0, 2)
    assert points_in_polygons(np.empty((0, 2)), np.empty((0, 2)), np.array([0])).shape == (0,)


def test_more_bad_input_is_rejected() -> None:
    pts, g = np.zeros((5, 2)), np.ones((5, 2))
    with pytest.raises(ValueError, match="offsets"):
        shape_angles(pts, g, np.array([1, 5]))
    with pytest.raises(ValueError, match="offsets"):
        shape_angles(pts, g, np.array([[0, 5]]))
    with pytest.raises(ValueError, match="at least one point"):
        shape_angles(pts, g, np.array([0, 3, 3, 5]))
    with pytest.raises(ValueError, match="at least one point"):
        polygon_centroids(pts, np.array([0, 4, 2, 5]))
    with pytest.raises(ValueError, match="closed"):
        shape_angles(pts, g, np.array([0, 5]), np.array([True, False]))
    with pytest.raises(ValueError, match="points and gradients"):
        shape_angles(np.zeros((5, 3)), np.zeros((5, 3)), np.array([0, 5]))
    with pytest.raises(ValueError, match="finite"):
        shape_angles(np.array([[0.0, 0.0], [np.nan, 1.0], [1.0, 1.0]]), g[:3], [0, 3])
    with pytest.raises(ValueError, match="finite"):
        shape_angles(pts, np.array([[0.0, 1.0]] * 4 + [[np.inf, 0.0]]), [0, 5])
    with pytest.raises(ValueError, match="query"):
        points_in_polygons(np.zeros((1, 3)), pts, np.array([0, 5]))
