"""thin_edges: the incremental passes (only pixels next to a removal are decided again) give
the same map as deciding every edge pixel in every pass."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.vision import kernels
from labauto.vision.edges import thin_edges


def _thin_reference(edges: np.ndarray, max_iter: int = 2) -> np.ndarray:
    """The package's plain path (every pixel of a class decided in every pass, numpy)."""
    with kernels.using("plain"):
        return thin_edges(edges, max_iter)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("max_iter", [1, 2, 3])
def test_thin_edges_matches_full_passes(seed: int, max_iter: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = rng.integers(20, 70, size=2)
    edges = np.zeros((h, w), np.uint8)
    for _ in range(8):  # thick strokes and blobs leave much to thin over several passes
        centre = tuple(int(v) for v in rng.integers(0, (w, h)))
        axes = tuple(int(v) for v in rng.integers(2, 15, size=2))
        cv2.ellipse(edges, centre, axes, float(rng.uniform(0, 180)), 0, 360, 255, 2)
    edges[rng.random((h, w)) < 0.05] = 255
    np.testing.assert_array_equal(thin_edges(edges, max_iter), _thin_reference(edges, max_iter))
