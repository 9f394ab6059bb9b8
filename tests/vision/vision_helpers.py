"""Helpers for the detector tests: analytic shape angles from exact geometry, single renders."""

from __future__ import annotations

import numpy as np

from labauto.synthetic import shapes
from labauto.vision.detector import DetectedObject, DetectionResult


def analytic_d_alpha(shape: shapes.Shape, spacing: float = 0.02) -> tuple[float, float]:
    """(median, mean) of alpha over the true boundary, sampled uniformly in arc length with its
    true normals, about the exact area centroid; degrees, polarity invariant."""
    points, normals = shape.boundary_samples(spacing)
    m = np.asarray(shape.centroid) - points
    cos = np.abs(np.sum(normals * m, axis=1)) / np.hypot(m[:, 0], m[:, 1])
    alpha = np.degrees(np.arccos(np.minimum(cos, 1.0)))
    return float(np.median(alpha)), float(np.mean(alpha))


def render_alone(
    shape: shapes.Shape, size: int, *, background: float = 40.0, color: float = 200.0, **kw
) -> np.ndarray:
    """Render one shape on a ``size`` x ``size`` grey image."""
    return shapes.render([shape], size, size, background=background, colors=color, **kw)


def largest(result: DetectionResult) -> DetectedObject:
    """The object with the most contour points."""
    assert result.objects, "no contour detected"
    return max(result.objects, key=lambda o: o.n_points)
