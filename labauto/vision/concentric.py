"""The image of the centre of concentric circles: perspective-bias correction of marker centres.

Under perspective the centre of a circle does not project to the centre of its image ellipse;
the gap grows with the circle's size and tilt (tenths of a pixel for a 10 px marker at 60
degrees). Our markers have three concentric circles in their plane (the centre circle and the
code ring's inner and outer edges), and concentric circles fix the image of their centre exactly,
whatever the homography (Kim, Gurdjos and Kweon, "Geometric and algebraic constraints of
projected concentric circles", PAMI 2005):

In the plane, circles of radii r1 < r2 about the origin are the conics
``Q_i = diag(1, 1, -r_i^2)``, so ``Q_2^-1 Q_1 = diag(1, 1, r1^2 / r2^2)``: a double eigenvalue
(its eigenvectors span the line at infinity) and a single one, whose eigenvector is the centre
``(0, 0, 1)``. A homography ``H`` maps conics to ``C_i ~ H^-T Q_i H^-1``, hence
``C_2^-1 C_1 ~ H (Q_2^-1 Q_1) H^-1``: the same eigenvalues, eigenvectors mapped by ``H``. The
image of the centre is the eigenvector of ``C_2^-1 C_1`` of the eigenvalue that stands apart.

With noisy ellipses the double eigenvalue splits a little; the one farthest from the other two
is the single one. The conics are built in a frame centred on the first ellipse and scaled by
its major semi-axis, which keeps the 3x3 problem well conditioned. With three circles every
pair gives the centre; :func:`projected_center` averages the pairs with the largest radius ratio
first (the best conditioned).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from labauto.vision.ellipse import Ellipse


def conic_matrix(
    ellipse: Ellipse, origin: Sequence[float] = (0.0, 0.0), scale: float = 1.0
) -> np.ndarray:
    """The 3x3 symmetric conic of ``ellipse`` in the frame ``(p - origin) / scale``.

    Points ``x = (u, v, 1)`` of the ellipse satisfy ``x^T C x = 0``; C is scaled to unit norm.
    """
    (cx, cy), (a, b) = ellipse.center, ellipse.axes
    theta = np.deg2rad(ellipse.angle)
    c, s = np.cos(theta), np.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    centre = (np.array([cx, cy]) - np.asarray(origin, np.float64)) / scale
    shape = rot @ np.diag([(scale / a) ** 2, (scale / b) ** 2]) @ rot.T
    conic = np.empty((3, 3))
    conic[:2, :2] = shape
    conic[:2, 2] = conic[2, :2] = -shape @ centre
    conic[2, 2] = centre @ shape @ centre - 1.0
    return conic / np.linalg.norm(conic)


def _pair_center(inner: np.ndarray, outer: np.ndarray) -> np.ndarray | None:
    try:
        values, vectors = np.linalg.eig(np.linalg.solve(outer, inner))
    except np.linalg.LinAlgError:
        return None
    gaps = [min(abs(values[i] - values[j]) for j in range(3) if j != i) for i in range(3)]
    v = vectors[:, int(np.argmax(gaps))]
    v = v.real if np.all(np.isfinite(v)) else None
    if v is None or abs(v[2]) < 1e-12:
        return None
    return v[:2] / v[2]


def projected_center(ellipses: Sequence[Ellipse]) -> tuple[float, float] | None:
    """Image of the common centre of concentric circles from their image ellipses.

    Parameters
    ----------
    ellipses : sequence of Ellipse
        Two or more images of concentric circles of different radii, smallest first.

    Returns
    -------
    (x, y) or None
        The projected centre, or None when the conics are degenerate.
    """
    if len(ellipses) < 2:
        raise ValueError(f"need at least 2 concentric ellipses, got {len(ellipses)}")
    first = ellipses[0]
    origin, scale = first.center, max(first.axes[0], 1e-9)
    conics = [conic_matrix(e, origin, scale) for e in ellipses]
    points = []
    for j in range(len(conics) - 1, 0, -1):  # the widest pair first
        p = _pair_center(conics[0], conics[j])
        if p is not None:
            points.append(p)
    if not points:
        return None
    mean = np.mean(points, axis=0) * scale + np.asarray(origin)
    return float(mean[0]), float(mean[1])


def conic_to_ellipse(conic: np.ndarray) -> Ellipse | None:
    """The ellipse of a 3x3 conic matrix (None when it is no real ellipse)."""
    c = (np.asarray(conic, np.float64) + np.asarray(conic, np.float64).T) / 2.0
    shape, lin, const = c[:2, :2], c[:2, 2], c[2, 2]
    try:
        centre = -np.linalg.solve(shape, lin)
    except np.linalg.LinAlgError:
        return None
    k = centre @ shape @ centre - const  # (p - c)^T S (p - c) = k
    values, vectors = np.linalg.eigh(shape / k if k != 0 else shape)
    if k == 0 or np.any(values <= 0):
        return None
    axes = 1.0 / np.sqrt(values)
    major = int(np.argmax(axes))
    angle = np.degrees(np.arctan2(vectors[1, major], vectors[0, major]))
    return Ellipse.normalised(centre[0], centre[1], axes[major], axes[1 - major], angle)
