"""Contour extraction, both ways of section 3.1, on rendered shapes with exact geometry."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from vision_helpers import render_alone

from labauto.synthetic import shapes
from labauto.vision.contours import Contours, canny_contours, color_contours, ends_adjacent
from labauto.vision.edges import link_edges, refine_subpixel, thin_edges, traces_to_chains
from labauto.vision.gradient import color_gradient
from labauto.vision.segmentation import background_mean, color_deviation, segment


def _steps(points: np.ndarray) -> np.ndarray:
    return np.abs(np.diff(np.rint(points), axis=0)).max(axis=1)


@pytest.mark.parametrize("angle", [0.0, 23.0, 45.0, 151.0])
@pytest.mark.parametrize("kind", ["ellipse", "triangle", "star"])
def test_canny_contour_is_one_ordered_chain(kind: str, angle: float) -> None:
    shape = {
        "ellipse": shapes.ellipse((50.4, 49.7), (35, 20), angle),
        "triangle": shapes.triangle((50.4, 49.7), 38, angle),
        "star": shapes.star((50.4, 49.7), 40, 22, 5, angle),
    }[kind]
    contours = canny_contours(render_alone(shape, 101), subpixel=False)
    assert len(contours) == 1
    pts = contours[0]
    # consecutive pixels are 8-neighbours: the chain is ordered
    assert np.all(_steps(pts) == 1)
    # every point lies on the true boundary (within a pixel)
    boundary, _ = shape.boundary_samples(0.05)
    d = np.min(np.hypot(*(pts[:, None, :] - boundary[None, ::4, :]).transpose(2, 0, 1)), axis=1)
    assert d.max() < 1.0
    if kind == "ellipse":
        assert contours.closed[0]


def test_open_edge_is_ordered_end_to_end() -> None:
    edges = np.zeros((40, 60), np.uint8)
    # an arch: the topmost pixel is in the middle of the chain, not at an end
    t = np.linspace(0.2, np.pi - 0.2, 400)
    xy = np.unique(np.rint(np.column_stack((30 + 20 * np.cos(t), 30 - 20 * np.sin(t)))), axis=0)
    edges[xy[:, 1].astype(int), xy[:, 0].astype(int)] = 255
    pts, offsets = link_edges(edges)
    assert offsets.tolist() == [0, len(pts)]
    assert np.all(_steps(pts.astype(float)) <= 1)  # no jump: ordered from one end to the other
    ends = {tuple(pts[0]), tuple(pts[-1])}
    assert ends == {
        (int(xy[:, 0].min()), int(xy[xy[:, 0].argmin(), 1])),
        (int(xy[:, 0].max()), int(xy[xy[:, 0].argmax(), 1])),
    }
    assert not ends_adjacent(pts.astype(float), offsets)[0]


def test_staircase_chain_stays_ordered() -> None:
    """Corner pixels of 4-connected steps, met only on the way back, do not scramble the order."""
    edges = np.zeros((14, 26), np.uint8)
    x = np.arange(2, 23)
    y = np.rint(2 + (x - 2) * 0.45).astype(int)
    edges[y, x] = 255
    steps = np.flatnonzero(np.diff(y))[::2]
    edges[y[steps], x[steps] + 1] = 255  # make every other step 4-connected
    pts, offsets = link_edges(edges)
    assert offsets.tolist() == [0, len(pts)]
    assert np.all(_steps(pts.astype(float)) == 1)
    assert {tuple(pts[0]), tuple(pts[-1])} == {(2, 2), (22, int(y[-1]))}


def test_thinning_keeps_chains_connected_and_ends() -> None:
    edges = np.zeros((10, 10), np.uint8)
    for i in range(1, 7):  # a 4-connected staircase (x=i, y=i), (x=i+1, y=i)
        edges[i, i] = edges[i, i + 1] = 255
    thin = thin_edges(edges)[1:-1, 1:-1]
    assert np.count_nonzero(thin) < np.count_nonzero(edges)
    xs = np.nonzero(thin)[1]
    assert xs.min() <= 2 and xs.max() >= 6  # ends of a two-pixel-thick run shorten by <= 1 px
    assert cv2.connectedComponents(thin, connectivity=8)[0] == 2  # background + one chain


def test_traces_to_chains_keeps_each_pixel_once() -> None:
    chain = np.array([[0, 0], [1, 0], [2, 1], [3, 1]], np.int32)
    trace = np.vstack((chain[1:], chain[::-1][1:-1], chain[:1]))  # out and back, odd start
    pts, offsets = traces_to_chains([trace.reshape(-1, 1, 2)], width=10)
    assert offsets.tolist() == [0, 4]
    assert pts.tolist() in (chain.tolist(), chain[::-1].tolist())


@pytest.mark.parametrize("radius", [12.0, 25.0, 50.0])
def test_subpixel_points_lie_on_the_circle(radius: float) -> None:
    c = (radius + 10.3, radius + 9.8)
    size = int(2 * radius + 21)
    img = render_alone(shapes.ellipse(c, (radius, radius)), size)
    raw = canny_contours(img, subpixel=False)
    fine = canny_contours(img, subpixel=True)
    r_raw = np.hypot(*(raw.points - c).T) - radius
    r_fine = np.hypot(*(fine.points - c).T) - radius
    assert np.sqrt(np.mean(r_fine**2)) < 0.08
    assert np.sqrt(np.mean(r_fine**2)) < 0.5 * np.sqrt(np.mean(r_raw**2))
    assert abs(np.mean(r_fine)) < 0.05


def test_refine_subpixel_finds_the_parabola_vertex() -> None:
    gx = np.zeros((5, 5), np.int16)
    gx[2, 1:4] = [60, 100, 80]  # vertex of the parabola at x = 2 + 0.5*(60-80)/(60-200+80)
    out = refine_subpixel(np.array([[2, 2]]), gx, np.zeros_like(gx))
    assert out[0] == pytest.approx([2 + 0.5 * (60 - 80) / (60 - 200 + 80), 2.0])


@pytest.mark.parametrize("bright", [True, False])
def test_color_segmentation_contours(bright: bool) -> None:
    shape = shapes.ellipse((60.2, 50.7), (30, 18), 25)
    bg, fg = ((120, 140, 90), (120, 140, 200)) if bright else ((120, 140, 90), (120, 140, 10))
    img = shapes.render([shape], 121, 101, background=bg, colors=fg)
    assert background_mean(img).tolist() == list(bg)
    contours = color_contours(img, threshold=900.0)
    assert len(contours) == 1 and contours.closed[0]
    pts = contours[0]
    # boundary pixels of the region: inside the true edge by 0-1 px
    boundary, _ = shape.boundary_samples(0.05)
    d = np.min(np.hypot(*(pts[:, None, :] - boundary[None, ::4, :]).transpose(2, 0, 1)), axis=1)
    assert d.max() < 1.2
    # gradients point across the boundary (roughly along the radial direction)
    radial = pts - np.array(shape.centroid)
    g = contours.gradients
    cos = np.abs((g * radial).sum(1)) / (np.hypot(*g.T) * np.hypot(*radial.T))
    assert np.median(cos) > 0.8


def test_segmentation_weights_and_mask() -> None:
    img = np.full((20, 20, 3), (10, 20, 30), np.uint8)
    img[5:10, 5:10] = (10, 20, 130)
    dev = color_deviation(img, (10, 20, 30), channel_weights=(1, 1, 0.5))
    assert dev[7, 7] == pytest.approx(0.5 * 100**2)
    assert dev[0, 0] == 0
    fg, _ = segment(img, threshold=100.0, channel_weights=(1, 1, 0))
    assert not fg.any()  # the only difference is in a channel weighted 0
    mask = np.zeros((20, 20), np.uint8)
    mask[5:10, 5:10] = 1
    assert background_mean(img, mask).tolist() == [10, 20, 130]
    with pytest.raises(ValueError, match="channel_weights"):
        color_deviation(img, (1, 2, 3), channel_weights=(1, 1))


def test_both_methods_agree_on_a_colour_image() -> None:
    shape = shapes.deformed_ellipse((70.5, 60.2), (40, 28), 15)
    img = shapes.render([shape], 141, 121, background=(30, 160, 60), colors=(200, 60, 60))
    a = canny_contours(img)
    b = color_contours(img, threshold=900.0)
    assert len(a) == len(b) == 1
    assert abs(len(a[0]) - len(b[0])) < 0.1 * len(a[0])


def test_gray_gradient_equals_single_channel() -> None:
    img = render_alone(shapes.ellipse((20, 20), (10, 6), 30), 41)
    gx, gy = color_gradient(img, 0.7)
    gx3, gy3 = color_gradient(np.dstack([img, img // 2, img // 3]), 0.7)
    assert np.array_equal(gx, gx3) and np.array_equal(gy, gy3)  # strongest channel = img


def test_contours_container() -> None:
    c = Contours.from_list(
        [np.array([[0, 0], [1, 0], [1, 1], [0, 1]]), np.array([[5, 5], [9, 9], [20, 20]])],
        [np.ones((4, 2)), np.ones((3, 2))],
    )
    assert len(c) == 2 and c.lengths.tolist() == [4, 3]
    assert c.closed.tolist() == [True, False]
    assert c[1].tolist() == [[5, 5], [9, 9], [20, 20]]
    assert len(Contours.empty()) == 0
