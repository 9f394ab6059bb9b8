"""Polar harmonic analysis (eq. 4) and shape labels on exact point sets and rendered masks."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from labauto.vision.descriptors import polygon_area_centroid
from labauto.vision.ellipse import Ellipse
from labauto.vision.harmonics import (
    SHAPE_LABELS,
    classify_shape,
    polar_fourier_series,
    polar_harmonics,
    shape_features,
)

# ------------------------------------------------------------------------------- shapes


def rotate_scale(points: np.ndarray, deg: float, scale: float, shift=(0.0, 0.0)) -> np.ndarray:
    t = math.radians(deg)
    rot = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    return scale * points @ rot.T + np.asarray(shift)


def dense_polygon(vertices, per_edge: int = 60) -> np.ndarray:
    vertices = np.asarray(vertices, dtype=float)
    k = np.arange(per_edge) / per_edge
    nxt = np.roll(vertices, -1, axis=0)
    return np.concatenate([v + k[:, None] * (w - v) for v, w in zip(vertices, nxt, strict=True)])


def radial_shape(radius, n: int = 1440) -> np.ndarray:
    """Points at polar angle theta and radius radius(theta), theta uniform."""
    theta = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = radius(theta)
    return np.column_stack((r * np.cos(theta), r * np.sin(theta)))


def ellipse_radius(a: float, b: float):
    return lambda t: a * b / np.sqrt((b * np.cos(t)) ** 2 + (a * np.sin(t)) ** 2)


def des(a: float, b: float, eps=(0.05, 0.04, 0.03), phases=(1.0, 2.0, 0.5)):
    """A deformed ellipse: the ellipse radius modulated by small harmonics 3, 4, 5."""
    base = ellipse_radius(a, b)
    return lambda t: (
        base(t)
        * (
            1
            + sum(
                e * np.cos((k + 3) * t + p)
                for k, (e, p) in enumerate(zip(eps, phases, strict=True))
            )
        )
    )


def star(n_tips: int = 5, outer: float = 50.0, inner: float = 22.0) -> np.ndarray:
    ang = np.arange(2 * n_tips) * np.pi / n_tips
    r = np.where(np.arange(2 * n_tips) % 2 == 0, outer, inner)
    return dense_polygon(np.column_stack((r * np.cos(ang), r * np.sin(ang))), 40)


def crescent() -> np.ndarray:
    """Outer arc of radius 50 and inner arc of radius 40 centred 20 px to the right."""
    t_out = np.linspace(-2.2, 2.2, 400)
    outer = np.column_stack((50 * np.cos(t_out), 50 * np.sin(t_out)))
    t_in = np.linspace(1.75, -1.75, 300)
    inner = np.column_stack((20 + 40 * np.cos(t_in), 40 * np.sin(t_in)))
    inner = inner[np.hypot(*inner.T) < 50]
    return np.concatenate((outer, inner))


def d_alpha(points: np.ndarray) -> float:
    """Median shape angle (deg) from the contour's own normals about its area centroid."""
    _, c = polygon_area_centroid(points)
    tangent = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    normal = np.column_stack((tangent[:, 1], -tangent[:, 0]))
    m = c - points
    length = np.hypot(*normal.T) * np.hypot(*m.T)
    keep = length > 0  # a pixel chain that turns back (a 1-px spike tip) has no normal there
    cos = np.abs((normal * m).sum(axis=1))[keep] / length[keep]
    return float(np.degrees(np.median(np.arccos(np.clip(cos, 0.0, 1.0)))))


def label(points: np.ndarray, inside: bool = True, **kw) -> str:
    return classify_shape(points, d_alpha=d_alpha(points), centroid_inside=inside, **kw)


def rendered_contour(points: np.ndarray, size: int = 220) -> np.ndarray:
    """Pixel-chain contour (cv2.findContours) of the filled polygon, drawn at 1/16 px."""
    mask = np.zeros((size, size), np.uint8)
    poly = np.round((points + size / 2) * 16).astype(np.int32)
    cv2.fillPoly(mask, [poly], 255, lineType=cv2.LINE_8, shift=4)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return max(contours, key=len)[:, 0, :].astype(float)


SQUARE = [[25.0, 25.0], [-25.0, 25.0], [-25.0, -25.0], [25.0, -25.0]]
TRIANGLE = [
    [40 * math.cos(k * 2 * math.pi / 3), 40 * math.sin(k * 2 * math.pi / 3)] for k in range(3)
]

# ---------------------------------------------------------------------------- harmonics


def test_circle_has_only_harmonic_zero() -> None:
    pts = Ellipse((12.0, -7.0), (30.0, 30.0), 0.0).sample(500)
    amp = polar_harmonics(pts, n_harmonics=8)
    assert amp[0] == 1.0
    assert np.abs(amp[1:]).max() < 1e-12
    raw = polar_harmonics(pts, normalise=False)
    # mean radius of the inscribed 500-gon: r * (pi/n) / tan(pi/n) ... within (pi/n)^2
    assert raw[0] == pytest.approx(30.0, rel=1e-4)


def test_polygon_series_is_exact_whatever_the_sampling() -> None:
    # 4 corners and 4 x 60 edge points give the same coefficients: the integral is exact per edge
    a4, b4 = polar_fourier_series(np.array(SQUARE), n_harmonics=12)
    ad, bd = polar_fourier_series(dense_polygon(SQUARE), n_harmonics=12)
    assert np.allclose(a4, ad, atol=1e-12) and np.allclose(b4, bd, atol=1e-12)
    # against an independent FFT of the analytic r(theta) = s / (2 max(|cos|, |sin|))
    theta = np.linspace(0, 2 * np.pi, 1 << 16, endpoint=False)
    r = 25.0 / np.maximum(np.abs(np.cos(theta)), np.abs(np.sin(theta)))
    spectrum = 2 * np.fft.rfft(r)[:13] / len(r)
    assert np.allclose(a4, spectrum.real, atol=1e-6)
    assert np.allclose(b4, -spectrum.imag, atol=1e-6)
    # square about its centre: harmonics 0, 4, 8, 12 only; A4 = 0.1394 of the mean radius
    amp = polar_harmonics(np.array(SQUARE))
    assert amp[4] == pytest.approx(0.13941, abs=1e-4)
    assert np.abs(np.delete(amp, [0, 4, 8])).max() < 1e-12


def test_triangle_strong_third_ellipse_mostly_second() -> None:
    tri = polar_harmonics(np.array(TRIANGLE))
    assert tri[3] == pytest.approx(0.2751, abs=1e-4)
    assert np.abs(np.delete(tri, [0, 3, 6])).max() < 1e-12
    ell = polar_harmonics(Ellipse((0.0, 0.0), (45.0, 30.0), 20.0).sample(720))
    assert ell[2] == pytest.approx(0.2010, abs=1e-3)
    assert ell[2] > 5 * ell[4] > 0
    assert np.abs(ell[1::2]).max() < 1e-9  # central symmetry: no odd harmonics


@pytest.mark.parametrize("q", [1.5, 2.0, 3.0, 4.0])
def test_ellipse_axis_ratio_and_angle_come_out_exact(q: float) -> None:
    pts = Ellipse((40.0, 50.0), (60.0, 60.0 / q), 128.0).sample(720)
    f = shape_features(pts)
    assert f.axis_ratio == pytest.approx(1 / q, abs=1e-9)
    assert f.ellipse_angle == pytest.approx(128.0, abs=1e-7)
    assert f.ellipse_deviation < 1e-9
    assert f.star_shapedness == pytest.approx(1.0)


@pytest.mark.parametrize("shape", ["ellipse", "triangle", "star", "des"])
def test_harmonics_are_rotation_scale_and_orientation_invariant(shape: str) -> None:
    base = {
        "ellipse": Ellipse((0.0, 0.0), (50.0, 20.0), 0.0).sample(720),
        "triangle": dense_polygon(TRIANGLE),
        "star": star(),
        "des": radial_shape(des(50, 30)),
    }[shape]
    ref = polar_harmonics(base)
    for deg, scale in ((33.0, 1.0), (90.0, 3.0), (251.0, 0.2)):
        moved = rotate_scale(base, deg, scale, (300.0, -40.0))
        assert np.allclose(polar_harmonics(moved), ref, atol=1e-9)
        assert np.allclose(polar_harmonics(moved[::-1]), ref, atol=1e-9)


def test_centroid_outside_is_an_error() -> None:
    with pytest.raises(ValueError, match="wind around the centroid"):
        polar_harmonics(crescent())
    with pytest.raises(ValueError, match="wind around the centroid"):
        polar_harmonics(np.array(SQUARE), centroid=(100.0, 0.0))


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        polar_harmonics(np.zeros(10))
    with pytest.raises(ValueError, match="n_harmonics"):
        polar_harmonics(np.array(SQUARE), n_harmonics=-1)
    with pytest.raises(ValueError, match="power"):
        polar_fourier_series(np.array(SQUARE), power=2)
    with pytest.raises(ValueError, match="no area"):
        polar_harmonics(np.column_stack((np.arange(5.0), np.arange(5.0))))
    with pytest.raises(ValueError, match="d_alpha"):
        classify_shape(np.array(SQUARE), d_alpha=math.nan, centroid_inside=True)


# ------------------------------------------------------------------------------- labels

POINT_SETS = {
    "circle": [
        Ellipse((0.0, 0.0), (40.0, 40.0), 0.0).sample(400),
        Ellipse((0.0, 0.0), (40.0, 38.0), 70.0).sample(400),
    ],
    "ellipse": [
        Ellipse((0.0, 0.0), (45.0, 45.0 / q), ang).sample(400)
        for q, ang in ((1.5, 0.0), (2.0, 35.0), (3.0, 100.0), (4.0, 160.0))
    ],
    "des": [
        radial_shape(des(50, 40)),
        radial_shape(des(50, 30, phases=(0.0, 1.0, 2.0))),
        radial_shape(des(40, 40, eps=(0.03, 0.03, 0.02))),
        radial_shape(des(60, 32, eps=(0.06, 0.0, 0.04))),
    ],
    "triangle": [
        dense_polygon(TRIANGLE),
        dense_polygon([[-30, -30], [40, -30], [-30, 40]]),
        dense_polygon([[-40, -20], [40, -20], [-40, 26]]),
    ],
    "rectangle": [
        dense_polygon(SQUARE),
        dense_polygon([[50, 25], [-50, 25], [-50, -25], [50, -25]]),
        dense_polygon([[60, 15], [-60, 15], [-60, -15], [60, -15]]),
    ],
    "line": [dense_polygon([[70, 2], [-70, 2], [-70, -2], [70, -2]])],
    "other": [star(), star(6, 50, 30)],
}


@pytest.mark.parametrize(
    ("expected", "index"), [(k, i) for k, v in POINT_SETS.items() for i in range(len(v))]
)
def test_labels_of_exact_point_sets(expected: str, index: int) -> None:
    pts = POINT_SETS[expected][index]
    assert label(pts) == expected
    for deg, scale in ((27.0, 1.0), (140.0, 2.0), (300.0, 0.5)):
        assert label(rotate_scale(pts, deg, scale, (400.0, 250.0))) == expected


def test_open_line_and_crescent() -> None:
    line = np.column_stack((np.linspace(0, 80, 81), np.linspace(0, 30, 81)))
    assert classify_shape(line, d_alpha=90.0, centroid_inside=False, closed=False) == "line"
    moon = crescent()
    assert classify_shape(moon, d_alpha=20.0, centroid_inside=False) == "other"
    # even if the caller's test said inside, the contour does not wind around its centroid
    assert classify_shape(moon, d_alpha=20.0, centroid_inside=True) == "other"


def test_des_needs_small_d_alpha_and_centroid_inside() -> None:
    pts = radial_shape(des(50, 40))
    assert classify_shape(pts, d_alpha=10.0, centroid_inside=True) == "des"
    assert classify_shape(pts, d_alpha=45.0, centroid_inside=True) == "other"
    assert classify_shape(pts, d_alpha=45.0, centroid_inside=True, des_threshold_deg=50) == "des"
    assert classify_shape(pts, d_alpha=10.0, centroid_inside=False) == "other"


RENDERED = {
    "circle": [
        Ellipse((0.3, -0.4), (30.0, 30.0), 0.0).sample(2000),
        Ellipse((0.3, -0.4), (12.0, 12.0), 0.0).sample(2000),
    ],
    "ellipse": [
        Ellipse((0.3, -0.4), (45.0, 30.0), 17.0).sample(2000),
        Ellipse((0.3, -0.4), (64.0, 16.0), 128.0).sample(2000),
        Ellipse((0.3, -0.4), (32.0, 8.0), 50.0).sample(2000),
    ],
    "des": [
        rotate_scale(radial_shape(des(40, 31)), 20.0, 1.0),
        rotate_scale(radial_shape(des(50, 25, eps=(0.05, 0.0, 0.04))), 60.0, 1.0),
    ],
    "rectangle": [
        rotate_scale(np.array(SQUARE), 20.0, 1.2),
        rotate_scale(np.array([[64, 16], [-64, 16], [-64, -16], [64, -16]]), 35.0, 1),
    ],
    "triangle": [
        rotate_scale(np.array(TRIANGLE), 10.0, 1.0),
        rotate_scale(np.array([[-30, -30], [40, -30], [-30, 40]]), 10.0, 1.0),
    ],
    "line": [rotate_scale(np.array([[70, 2], [-70, 2], [-70, -2], [70, -2]]), 30.0, 1.0)],
    "other": [rotate_scale(star(5, 60, 25), 0.0, 1.0)],
}


@pytest.mark.parametrize(
    ("expected", "index"), [(k, i) for k, v in RENDERED.items() for i in range(len(v))]
)
def test_labels_of_rendered_contours(expected: str, index: int) -> None:
    contour = rendered_contour(RENDERED[expected][index])
    assert label(contour) == expected


def test_labels_are_known() -> None:
    assert set(SHAPE_LABELS) == {
        "circle",
        "ellipse",
        "des",
        "triangle",
        "rectangle",
        "line",
        "other",
    }
