"""The compiled edge linker against independent references written here.

Thinning: every pixel of a class decided in every pass (numpy); tracing: ``cv2.findContours``;
chains: a plain-Python version of the rotation and first-visit rule; sub-pixel: the numpy
float32 formula of Devernay's parabola.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.synthetic.shapes import make_scene
from labauto.vision import kernels
from labauto.vision.contours import ends_adjacent
from labauto.vision.edges import (
    _work_map,
    canny_edges,
    edge_contours,
    gradient_at,
    link_edges,
    refine_subpixel,
    thin_edges,
    traces_to_chains,
)
from labauto.vision.gradient import color_gradient


def _thin_reference(edges: np.ndarray, max_iter: int = 2) -> np.ndarray:
    """The package's plain path (every pixel of a class decided in every pass, numpy)."""
    with kernels.using("plain"):
        return thin_edges(edges, max_iter)


def _chains_reference(
    traces: list[np.ndarray], width: int, min_length: int = 1, max_length: int | None = None
) -> list[list[tuple[int, int]]]:
    seen: set[int] = set()
    chains = []
    for trace in traces:
        pts = [(int(x), int(y)) for x, y in trace.reshape(-1, 2)]
        lin = [y * width + x for x, y in pts]
        n = len(pts)
        new = len({v for v in lin if v not in seen})
        rotation = 0
        if n > 2 and new < 0.75 * n:
            rotation = next((i for i in range(n) if lin[i - 1] == lin[(i + 1) % n]), 0)
        chain = []
        for j in range(n):
            k = (j + rotation) % n
            if lin[k] not in seen:
                seen.add(lin[k])
                chain.append(pts[k])
        if len(chain) >= min_length and (max_length is None or len(chain) <= max_length):
            chains.append(chain)
    return chains


def _link_reference(
    edges: np.ndarray, min_length: int = 1, max_length: int | None = None
) -> list[list[tuple[int, int]]]:
    thin = _thin_reference(edges)
    traces, hierarchy = cv2.findContours(
        thin, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE, offset=(-1, -1)
    )
    if not traces:
        return []
    outer = [t for t, h in zip(traces, hierarchy[0], strict=True) if h[3] < 0]
    return _chains_reference(outer, edges.shape[1], min_length, max_length)


def _as_list(points: np.ndarray, offsets: np.ndarray) -> list[list[tuple[int, int]]]:
    return [
        [(int(x), int(y)) for x, y in points[offsets[k] : offsets[k + 1]]]
        for k in range(offsets.shape[0] - 1)
    ]


def _random_map(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    edges = np.zeros((h, w), np.uint8)
    for _ in range(int(rng.integers(1, 10))):  # rings (also nested), arcs, strokes
        centre = tuple(int(v) for v in rng.integers(-3, (w + 3, h + 3)))
        axes = tuple(int(v) for v in rng.integers(1, 20, size=2))
        start = float(rng.uniform(0, 360))
        span = float(rng.choice([360.0, rng.uniform(20, 300)]))
        thickness = int(rng.choice([1, 1, 2]))
        angle = float(rng.uniform(0, 180))
        cv2.ellipse(edges, centre, axes, angle, start, start + span, 255, thickness)
    edges[rng.random((h, w)) < rng.uniform(0, 0.08)] = 255
    return edges


@pytest.mark.parametrize("seed", range(40))
def test_link_edges_matches_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 80, size=2))
    edges = _random_map(rng, h, w)
    min_length = int(rng.choice([1, 2, 5, 20]))
    max_length = None if seed % 3 else int(rng.integers(5, 60))
    pts, offsets = link_edges(edges, min_length, max_length)
    assert pts.dtype == np.int32 and offsets.dtype == np.int64
    assert _as_list(pts, offsets) == _link_reference(edges, min_length, max_length)
    assert not _work_map(edges.shape).any()  # the kernel leaves its work map clean


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("max_iter", [0, 1, 3])
def test_thin_edges_matches_reference(seed: int, max_iter: int) -> None:
    rng = np.random.default_rng(100 + seed)
    h, w = (int(v) for v in rng.integers(1, 60, size=2))
    edges = _random_map(rng, h, w)
    np.testing.assert_array_equal(thin_edges(edges, max_iter), _thin_reference(edges, max_iter))


@pytest.mark.parametrize("width", [1, 63, 64, 65, 127, 128, 130, 200])
@pytest.mark.parametrize("density", [0.05, 0.5, 1.0])
def test_link_and_thin_across_64_pixel_blocks(width: int, density: float) -> None:
    """The kernel reads the edge map 64 pixels at a time: widths around that block size (a
    partial block at the end of a row), empty, sparse and full blocks, edges on the border."""
    rng = np.random.default_rng(width)
    edges = ((rng.random((9, width)) < density) * 255).astype(np.uint8)
    edges[4] = 255  # a full row: every block of it set
    pts, offsets = link_edges(edges)
    assert _as_list(pts, offsets) == _link_reference(edges)
    for max_iter in (1, 2, 3):
        np.testing.assert_array_equal(thin_edges(edges, max_iter), _thin_reference(edges, max_iter))
    assert not _work_map(edges.shape).any()


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("max_iter", [2, 3, 5])
def test_thin_edges_dense_maps_many_passes(seed: int, max_iter: int) -> None:
    """Dense maps keep removing pixels in every pass, so a pixel kept earlier must be decided
    again after a neighbour (of any class, in this pass or the last) was removed."""
    rng = np.random.default_rng(500 + seed)
    h, w = (int(v) for v in rng.integers(2, 100, size=2))
    edges = ((rng.random((h, w)) < rng.uniform(0.3, 0.7)) * 255).astype(np.uint8)
    np.testing.assert_array_equal(thin_edges(edges, max_iter), _thin_reference(edges, max_iter))


def test_link_edges_on_a_scene_matches_reference() -> None:
    """A full 1280x1024 scene through the colour Canny edges, as detect links it."""
    gx, gy = color_gradient(make_scene(np.random.default_rng(3))[0], 0.7)
    edges = canny_edges(gx, gy, 40.0, 100.0)
    pts, offsets = link_edges(edges, 20)
    assert _as_list(pts, offsets) == _link_reference(edges, 20)
    points, _, grads, _ = edge_contours(edges, gx, gy, 20)
    np.testing.assert_array_equal(points, _refine_reference(pts, gx, gy))
    np.testing.assert_array_equal(
        grads, np.column_stack((gx[pts[:, 1], pts[:, 0]], gy[pts[:, 1], pts[:, 0]]))
    )


@pytest.mark.parametrize(
    "edges",
    [
        np.zeros((7, 9), np.uint8),  # nothing
        np.pad(np.full((1, 1), 255, np.uint8), 2),  # one pixel
        np.full((6, 8), 255, np.uint8),  # a solid block touching every border
        np.pad(np.zeros((4, 6), np.uint8), 1, constant_values=255),  # a frame on the border
        np.full((1, 17), 255, np.uint8),  # one row
        np.full((13, 1), 7, np.uint8),  # one column, any nonzero value
        np.eye(9, dtype=np.uint8),  # a diagonal from corner to corner
    ],
    ids=["empty", "pixel", "block", "frame", "row", "column", "diagonal"],
)
def test_link_edges_edge_cases(edges: np.ndarray) -> None:
    pts, offsets = link_edges(edges)
    assert _as_list(pts, offsets) == _link_reference(edges)
    assert offsets[0] == 0 and offsets[-1] == pts.shape[0]


def test_link_edges_accepts_bool_maps() -> None:
    edges = np.zeros((20, 30), bool)
    edges[5, 3:25] = True
    pts, offsets = link_edges(edges)
    assert offsets.tolist() == [0, 22]
    assert {tuple(pts[0]), tuple(pts[-1])} == {(3, 5), (24, 5)}


@pytest.mark.parametrize("seed", range(10))
def test_traces_to_chains_matches_reference(seed: int) -> None:
    """Traces of a segmentation (thick regions, holes): pixels shared by traces appear once."""
    rng = np.random.default_rng(200 + seed)
    h, w = (int(v) for v in rng.integers(3, 60, size=2))
    region = (rng.random((h, w)) < 0.35).astype(np.uint8)
    region = cv2.morphologyEx(region, cv2.MORPH_CLOSE, np.ones((2, 2), np.uint8))
    traces, _ = cv2.findContours(region, cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    min_length, max_length = (1, None) if seed % 2 else (4, 40)
    pts, offsets = traces_to_chains(list(traces), w, min_length, max_length)
    assert _as_list(pts, offsets) == _chains_reference(list(traces), w, min_length, max_length)


def test_traces_to_chains_small_cases() -> None:
    assert traces_to_chains([], 5)[1].tolist() == [0]
    one = np.array([[[3, 4]]], np.int32)
    pair = np.array([[[0, 0]], [[1, 0]]], np.int32)
    pts, offsets = traces_to_chains([one, pair, one], 10)  # repeated pixel: once, then no chain
    assert pts.tolist() == [[3, 4], [0, 0], [1, 0]] and offsets.tolist() == [0, 1, 3]
    pts, offsets = traces_to_chains([one, pair], 10, min_length=2)
    assert pts.tolist() == [[0, 0], [1, 0]] and offsets.tolist() == [0, 2]


def _refine_reference(points: np.ndarray, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    h, w = gx.shape
    out = points.astype(np.float64)
    for i, (x, y) in enumerate(points.tolist()):
        ax, ay = np.float32(gx[y, x]), np.float32(gy[y, x])
        sx, sy = (1, 0) if abs(ax) >= abs(ay) else (0, 1)
        if not (x >= sx and x + sx < w and y >= sy and y + sy < h):
            continue
        m0, mm, mp = (
            np.hypot(np.float32(gx[yy, xx]), np.float32(gy[yy, xx]))
            for xx, yy in ((x, y), (x - sx, y - sy), (x + sx, y + sy))
        )
        denom = mm - np.float32(2) * m0 + mp
        if denom < 0:
            offset = np.clip(np.float32(0.5) * (mm - mp) / denom, -0.5, 0.5)
            out[i] += (float(offset) * sx, float(offset) * sy)
    return out


@pytest.mark.parametrize("seed", range(5))
def test_refine_subpixel_and_gradient_match_reference(seed: int) -> None:
    rng = np.random.default_rng(300 + seed)
    h, w = (int(v) for v in rng.integers(1, 40, size=2))
    gx = rng.integers(-1020, 1021, (h, w)).astype(np.int16)
    gy = rng.integers(-1020, 1021, (h, w)).astype(np.int16)
    tie = rng.random((h, w)) < 0.2
    gy[tie] = -gx[tie]  # |gx| == |gy|: refined along x
    ys, xs = np.nonzero(rng.random((h, w)) < 0.5)
    points = np.column_stack((xs, ys)).astype(np.int64)
    expected = _refine_reference(points, gx, gy)
    np.testing.assert_array_equal(refine_subpixel(points, gx, gy), expected)
    grads = gradient_at(gx, gy, points)
    assert grads.dtype == np.float32
    np.testing.assert_array_equal(grads, np.column_stack((gx[ys, xs], gy[ys, xs])))
    assert refine_subpixel(points[:0], gx, gy).shape == (0, 2)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("subpixel", [True, False])
def test_edge_contours_is_link_refine_and_gradient(seed: int, subpixel: bool) -> None:
    rng = np.random.default_rng(400 + seed)
    h, w = (int(v) for v in rng.integers(1, 70, size=2))
    edges = _random_map(rng, h, w)
    gx = rng.integers(-300, 301, (h, w)).astype(np.int16)
    gy = rng.integers(-300, 301, (h, w)).astype(np.int16)
    points, offsets, grads, closed = edge_contours(edges, gx, gy, 3, None, subpixel)
    pix, pix_offsets = link_edges(edges, 3)
    np.testing.assert_array_equal(offsets, pix_offsets)
    expected = refine_subpixel(pix, gx, gy) if subpixel else pix.astype(np.float64)
    np.testing.assert_array_equal(points, expected)
    np.testing.assert_array_equal(grads, gradient_at(gx, gy, pix))
    np.testing.assert_array_equal(closed, ends_adjacent(pix.astype(np.float64), offsets))
    assert closed.dtype == bool and points.dtype == np.float64


@pytest.fixture
def restore_threads():
    before = kernels.threads()
    yield
    kernels.set_threads(before)


def _contours_on_threads(
    edges: np.ndarray, gx: np.ndarray, gy: np.ndarray, min_length: int, subpixel: bool
) -> list[tuple[np.ndarray, ...]]:
    results = []
    for threads in (1, 2, 3):  # 3: more threads than this machine's cores
        kernels.set_threads(threads)
        results.append(edge_contours(edges, gx, gy, min_length, None, subpixel))
    return results


@pytest.mark.parametrize("seed", range(6))
def test_edge_contours_same_on_any_number_of_threads(seed: int, restore_threads) -> None:
    """Maps large enough for the threaded path (image split in two bands, thinned apart, then
    the seam; chains sampled by several threads): identical output on 1, 2 and 3 threads, and
    the same as the separate linking, lookup and refinement."""
    rng = np.random.default_rng(600 + seed)
    h, w = int(rng.integers(256, 400)), int(rng.integers(256, 500))
    edges = _random_map(rng, h, w)
    for _ in range(int(rng.integers(20, 60))):  # longer strokes crossing the band split
        a, b = rng.integers(0, (w, h), size=(2, 2))
        cv2.line(edges, tuple(int(v) for v in a), tuple(int(v) for v in b), 255, 1)
    gx = rng.integers(-600, 601, (h, w)).astype(np.int16)
    gy = rng.integers(-600, 601, (h, w)).astype(np.int16)
    subpixel = bool(seed % 2)
    serial, *threaded = _contours_on_threads(edges, gx, gy, 3, subpixel)
    for result in threaded:
        for a, b in zip(serial, result, strict=True):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
    pix, pix_offsets = link_edges(edges, 3)
    np.testing.assert_array_equal(serial[1], pix_offsets)
    expected = refine_subpixel(pix, gx, gy) if subpixel else pix.astype(np.float64)
    np.testing.assert_array_equal(serial[0], expected)
    np.testing.assert_array_equal(serial[2], gradient_at(gx, gy, pix))
    assert not _work_map(edges.shape).any()


def test_edge_contours_on_a_scene_same_on_any_number_of_threads(restore_threads) -> None:
    gx, gy = color_gradient(make_scene(np.random.default_rng(1))[0], 0.7)
    edges = canny_edges(gx, gy, 40.0, 100.0)
    serial, *threaded = _contours_on_threads(edges, gx, gy, 20, True)
    for result in threaded:
        for a, b in zip(serial, result, strict=True):
            np.testing.assert_array_equal(a, b)


def test_bad_input_raises_value_error() -> None:
    edges = np.zeros((5, 6), np.uint8)
    g = np.zeros((5, 6), np.int16)
    with pytest.raises(ValueError, match="edges"):
        link_edges(np.zeros((2, 3, 3), np.uint8))
    with pytest.raises(ValueError, match="max_length"):
        link_edges(edges, 1, -2)
    with pytest.raises(ValueError, match="gx"):
        edge_contours(edges, g.astype(np.float32), g)
    with pytest.raises(ValueError, match="shape"):
        edge_contours(edges, g[:4], g[:4])
    with pytest.raises(ValueError, match="inside"):
        refine_subpixel(np.array([[6, 0]]), g, g)
    with pytest.raises(ValueError, match="points"):
        gradient_at(g, g, np.zeros((3, 3), np.int64))
