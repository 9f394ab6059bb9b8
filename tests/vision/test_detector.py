"""The detector pipeline on rendered images with exact ground truth."""

from __future__ import annotations

import json

import numpy as np
import pytest
from vision_helpers import largest, render_alone

from labauto.synthetic import shapes
from labauto.vision.detector import DetectionResult, DetectorParams, detect
from labauto.vision.edges import canny_edges, link_edges
from labauto.vision.gradient import color_gradient
from labauto.vision.shape_angle import points_in_polygons

NO_FIT = DetectorParams(fit_ellipses=False)


@pytest.mark.parametrize("gap", [0.05, 0.10, 0.15])
@pytest.mark.parametrize("start", [0.0, 100.0, 230.0])
def test_des_with_missing_contour_is_still_detected(gap: float, start: float) -> None:
    shape = shapes.deformed_ellipse((70.3, 65.6), (45, 32), 20, ((3, 0.05, 0.3), (4, 0.03, 1.0)))
    colours = {"background": 60.0, "color": 160.0}
    img = render_alone(shape, 141, gap_fraction=gap, gap_start_deg=start, **colours)
    full = largest(detect(render_alone(shape, 141, **colours), NO_FIT))
    obj = largest(detect(img, NO_FIT))
    # the gap really removed about that fraction of the edge
    assert obj.n_points <= (1.0 - 0.6 * gap) * full.n_points
    assert not obj.closed
    assert obj.is_des and obj.centroid_inside
    assert obj.d_alpha_median < 25.0


@pytest.mark.parametrize("angle", [0.0, 60.0, 135.0, 250.0])
@pytest.mark.parametrize(("radius", "inner", "offset"), [(30, 26, 9), (40, 36, 12), (25, 23, 8)])
@pytest.mark.parametrize("method", ["canny", "color"])
def test_crescent_is_never_des(
    angle: float, radius: float, inner: float, offset: float, method: str
) -> None:
    shape = shapes.crescent((50.4, 50.3), radius, inner, offset, angle)
    vertices = shape.vertices
    assert not points_in_polygons(
        np.array([shape.centroid]), vertices, np.array([0, len(vertices)])
    )[0], "test shape must have its centroid outside"
    img = render_alone(shape, 101)
    result = detect(img, DetectorParams(method=method, fit_ellipses=False, classify=False))
    assert result.objects
    assert not any(o.is_des for o in result.objects)


@pytest.mark.parametrize("ratio", [1.0, 1.5, 2.0, 3.0, 4.0])
@pytest.mark.parametrize("angle", [0.0, 33.0, 90.0])
@pytest.mark.parametrize("bright", [True, False])
def test_ellipses_down_to_1_to_4_are_des(ratio: float, angle: float, bright: bool) -> None:
    shape = shapes.ellipse((60.3, 60.8), (48, 48 / ratio), angle)
    fg, bg = (220.0, 50.0) if bright else (50.0, 220.0)
    obj = largest(detect(render_alone(shape, 121, background=bg, color=fg), NO_FIT))
    assert obj.is_des and obj.closed


@pytest.mark.parametrize("kind", ["line", "thin_line"])
def test_lines_are_not_des(kind: str) -> None:
    width = 4.0 if kind == "line" else 1.5
    img = render_alone(shapes.line((10.2, 20.7), (110.5, 80.1), width), 121)
    assert not any(o.is_des for o in detect(img, NO_FIT).objects)


ELLIPSES = [  # (a, b, angle): radius of curvature b^2/a >= 6 px (see the report for smaller)
    (15.0, 10.0, 0.0),
    (22.5, 14.0, 31.0),
    (30.0, 14.0, 77.0),
    (40.0, 25.0, 128.0),
    (60.0, 24.0, 12.5),
    (80.0, 55.0, 160.0),
]


@pytest.mark.parametrize(("a", "b", "angle"), ELLIPSES)
def test_ellipse_fit_through_the_whole_chain(a: float, b: float, angle: float) -> None:
    size = int(2 * a + 24)
    center = (size / 2 + 0.41, size / 2 - 0.27)
    img = render_alone(shapes.ellipse(center, (a, b), angle), size, background=60, color=190)
    obj = largest(detect(img))
    assert obj.is_des and obj.ellipse is not None
    e = obj.ellipse
    assert np.hypot(e.center[0] - center[0], e.center[1] - center[1]) < 0.05
    assert e.axes[0] == pytest.approx(a, abs=0.1)
    assert e.axes[1] == pytest.approx(b, abs=0.1)
    assert (e.angle - angle + 90) % 180 - 90 == pytest.approx(0.0, abs=0.5)


def test_colour_edge_invisible_in_grey_is_found() -> None:
    """Eq. 2: an edge that only exists in one colour channel (same grey level) is detected."""
    shape = shapes.ellipse((50.5, 50.5), (30, 22), 10)
    bg, fg = (100, 140, 160), (160, 110, 154)  # BGR -> nearly equal luminance
    img = shapes.render([shape], 101, 101, background=bg, colors=fg)
    grey = img.mean(axis=2)
    assert np.ptp(grey) < 12
    obj = largest(detect(img, NO_FIT))
    assert obj.is_des and obj.closed


def test_result_json_shape() -> None:
    scene = [shapes.ellipse((40.3, 40.2), (20, 14), 30), shapes.line((80, 10), (150, 70), 3)]
    img = shapes.render(scene, 160, 90, background=(20, 60, 90), colors=(200, 200, 200))
    result = detect(img)
    assert isinstance(result, DetectionResult)
    d = result.to_dict()
    assert json.loads(json.dumps(d)) == d
    assert set(d) == {"width", "height", "method", "timing_ms", "objects"}
    assert (d["width"], d["height"], d["method"]) == (160, 90, "canny")
    keys = {
        "id",
        "centroid",
        "n_points",
        "closed",
        "d_alpha_median",
        "d_alpha_mean",
        "centroid_inside",
        "is_des",
        "shape",
        "ellipse",
    }
    assert all(set(o) == keys for o in d["objects"])
    des = [o for o in d["objects"] if o["is_des"]]
    assert len(des) == 1 and des[0]["centroid"] == pytest.approx([40.3, 40.2], abs=0.1)
    if des[0]["ellipse"] is not None:
        assert set(des[0]["ellipse"]) == {"center", "axes", "angle"}
    assert all(o["ellipse"] is None for o in d["objects"] if not o["is_des"])


@pytest.mark.parametrize("dtype", ["gray", "gray_float", "unit_float", "hxwx1", "uint16_small"])
def test_accepted_image_forms_give_the_same_contour(dtype: str) -> None:
    base = render_alone(shapes.ellipse((30.4, 30.1), (18, 12), 20), 61)
    img = {
        "gray": base,
        "gray_float": base.astype(np.float64),
        "unit_float": base.astype(np.float32) / 255.0,
        "hxwx1": base[..., None],
        "uint16_small": base.astype(np.uint16),
    }[dtype]
    ref = largest(detect(base, NO_FIT))
    obj = largest(detect(img, NO_FIT))
    assert obj.n_points == ref.n_points
    assert obj.d_alpha_median == pytest.approx(ref.d_alpha_median, abs=1e-6)


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((0, 10), np.uint8), "empty"),
        (np.zeros(100, np.uint8), "dimension"),
        (np.zeros((10, 10, 2), np.uint8), "channels"),
        (np.zeros((10, 10, 3, 2), np.uint8), "dimension"),
        (np.zeros((10, 10), np.complex64), "dtype"),
        (np.zeros((10, 10), bool), "dtype"),
        (np.full((10, 10), 1000, np.uint16), "0..255"),
        (np.full((10, 10), np.nan), "NaN"),
        ([[1, 2], [3, 4]], "numpy array"),
    ],
)
def test_bad_images_raise_value_error(image: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        detect(image)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("method", "sobel"),
        ("statistic", "mode"),
        ("blur_sigma", -1.0),
        ("canny_low", 200.0),
        ("min_contour_length", 1),
        ("des_threshold_deg", 120.0),
        ("channel_weights", (1.0, 1.0)),
    ],
)
def test_bad_params_name_the_field(field: str, value: object) -> None:
    params = DetectorParams(**{field: value})
    with pytest.raises(ValueError, match=field):
        detect(np.zeros((20, 20), np.uint8), params)


def test_mean_statistic_and_length_filter() -> None:
    scene = [shapes.ellipse((30.2, 30.4), (20, 15), 0), shapes.ellipse((90.2, 30.4), (5, 4), 0)]
    img = shapes.render(scene, 120, 60, background=30, colors=220)
    both = detect(img, NO_FIT)
    assert len(both.objects) == 2
    big_only = detect(img, DetectorParams(min_contour_length=40, fit_ellipses=False))
    assert len(big_only.objects) == 1
    strict = detect(img, DetectorParams(statistic="mean", des_threshold_deg=0.01))
    assert not any(o.is_des for o in strict.objects)


def test_empty_image_gives_no_objects() -> None:
    result = detect(np.full((50, 60, 3), 128, np.uint8))
    assert result.objects == [] and (result.width, result.height) == (60, 50)


def test_scene_is_deterministic_and_mostly_found() -> None:
    img1, truth1 = shapes.make_scene(np.random.default_rng(5), 400, 300, 8, 10)
    img2, truth2 = shapes.make_scene(np.random.default_rng(5), 400, 300, 8, 10)
    assert np.array_equal(img1, img2) and truth1 == truth2
    result = detect(img1, NO_FIT)
    des = [o for o in result.objects if o.is_des]
    ellipses = [t for t in truth1 if t["kind"] == "ellipse"]
    found = sum(
        any(np.hypot(*(np.array(o.centroid) - t["center"])) < 1.0 for o in des) for t in ellipses
    )
    assert found == len(ellipses)


def test_link_edges_on_empty_map() -> None:
    gx, gy = color_gradient(np.zeros((20, 20), np.uint8), 0.7)
    pts, offsets = link_edges(canny_edges(gx, gy, 10, 20))
    assert pts.shape == (0, 2) and offsets.tolist() == [0]
