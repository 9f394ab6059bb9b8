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
its major semi-axis, which keeps the 3x3 problem well conditioned. :func:`projected_centers`
solves many pairs at once (one batched eigenproblem); :func:`projected_center` averages, for
three or more circles, the pairs of the first with each other one.
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


def projected_center(ellipses: Sequence[Ellipse]) -> tuple[float, float] | None:
    """Image of the common centre of concentric circles from their image ellipses.

    Parameters
    ----------
    ellipses : sequence of Ellipse
        Two or more images of concentric circles of different radii, smallest first.

    Returns
    -------
    (x, y) or None
        The projected centre (the mean over the pairs of the first with each other one), or
        None when the conics are degenerate.
    """
    if len(ellipses) < 2:
        raise ValueError(f"need at least 2 concentric ellipses, got {len(ellipses)}")
    rows = np.array([(*e.center, *e.axes, e.angle) for e in ellipses], np.float64)
    centres = projected_centers(np.repeat(rows[:1], len(rows) - 1, axis=0), rows[1:])
    centres = centres[np.isfinite(centres).all(axis=1)]
    if len(centres) == 0:
        return None
    x, y = centres.mean(axis=0)
    return float(x), float(y)


def conic_matrices(params: np.ndarray, origin: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(K, 3, 3) unit-norm conics of ellipse rows ``(cx, cy, a, b, angle_deg)`` in the frames
    ``(p - origin_k) / scale_k`` (as :func:`conic_matrix`, for K ellipses at once)."""
    p = np.asarray(params, np.float64).reshape(-1, 5)
    theta = np.deg2rad(p[:, 4])
    c, s = np.cos(theta), np.sin(theta)
    ia, ib = (scale / p[:, 2]) ** 2, (scale / p[:, 3]) ** 2
    sxx, syy, sxy = c * c * ia + s * s * ib, s * s * ia + c * c * ib, c * s * (ia - ib)
    u, v = (p[:, 0] - origin[:, 0]) / scale, (p[:, 1] - origin[:, 1]) / scale
    conic = np.empty((len(p), 3, 3))
    conic[:, 0, 0], conic[:, 1, 1], conic[:, 0, 1], conic[:, 1, 0] = sxx, syy, sxy, sxy
    conic[:, 0, 2] = conic[:, 2, 0] = -(sxx * u + sxy * v)
    conic[:, 1, 2] = conic[:, 2, 1] = -(sxy * u + syy * v)
    conic[:, 2, 2] = sxx * u * u + 2 * sxy * u * v + syy * v * v - 1.0
    return conic / np.linalg.norm(conic, axis=(1, 2))[:, None, None]


def projected_centers(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(K, 2) images of the centres of K pairs of concentric circles (NaN where degenerate).

    Parameters
    ----------
    first, second : np.ndarray
        (K, 5) ellipse rows ``(cx, cy, a, b, angle_deg)`` of each pair's two circles (either
        order); the frame of each pair is centred on ``first`` and scaled by its major axis.
    """
    a = np.asarray(first, np.float64).reshape(-1, 5)
    b = np.asarray(second, np.float64).reshape(-1, 5)
    out = np.full((len(a), 2), np.nan)
    if len(a) == 0:
        return out
    origin, scale = a[:, :2], np.maximum(a[:, 2], 1e-9)
    c1, c2 = conic_matrices(a, origin, scale), conic_matrices(b, origin, scale)
    ok = np.abs(np.linalg.det(c2)) > 1e-15
    if not ok.any():
        return out
    values, vectors = np.linalg.eig(np.linalg.solve(c2[ok], c1[ok]))
    gaps = np.abs(values[:, :, None] - values[:, None, :])
    gaps[:, np.arange(3), np.arange(3)] = np.inf
    single = np.argmax(gaps.min(axis=2), axis=1)
    v = vectors[np.arange(len(single)), :, single].real
    good = np.abs(v[:, 2]) > 1e-12
    centre = np.where(good[:, None], v[:, :2] / np.where(good, v[:, 2], 1.0)[:, None], np.nan)
    out[ok] = centre * scale[ok, None] + origin[ok]
    return out


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
