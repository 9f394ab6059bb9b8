"""Ellipse fitting: direct algebraic, geometric (orthogonal distances, Ahn et al.) and robust.

The paper (section 4.2) fits markers with "an iterative ellipse fitting algorithm [Ahn et al.]
... a least squares method based on the perpendicular distance. Starting from seed values,
defined by the contour, an iterative approach fits an ellipse with sub-pixel precision", and
mentions a bootstrap that fits parts of an ellipse and combines them. This module provides:

* :func:`fit_ellipse_algebraic` - the direct least-squares fit of Fitzgibbon et al. in the
  numerically stable form of Halir and Flusser (1998), on points centred and scaled to unit RMS
  radius. Always an ellipse, one 3x3 eigenproblem, but biased toward small ellipses on noisy
  short arcs. :func:`fit_ellipses_algebraic_batch` does the same for many contours at once
  (one scatter matrix per contour by ``np.add.reduceat``, batched linear algebra).
* :func:`fit_ellipse_geometric` - minimises the sum of squared orthogonal distances (Ahn,
  Rauh and Warnecke, Pattern Recognition 34, 2001). For every point the orthogonal contact
  point on the current ellipse is found by a vectorised Newton iteration (below); then a
  Levenberg-Marquardt step on the 5 parameters ``(xc, yc, a, b, angle)`` uses the Jacobian of
  the orthogonal distances. At the contact point the distance is stationary along the ellipse,
  so its derivative is ``-n . d(x_contact)/d(parameter)`` at fixed ellipse parameter ``t``
  (``n`` the unit normal); this is Ahn's Jacobian in closed form. Seeded by the algebraic fit it
  converges in 3-6 iterations. :func:`fit_ellipses_geometric_batch` runs the same iteration for
  many contours at once (per-contour damping and stopping, one Newton loop over all points,
  batched 5x5 solves).
* :func:`fit_ellipse_robust` - RANSAC (batched 5-point conics, MSAC scoring with the Sampson
  distance) or the paper's bootstrap (algebraic fits of random combinations of contiguous
  arcs), then the geometric fit on the inliers with the inlier set re-chosen by true
  orthogonal distance until it is stable.

Orthogonal contact point: in the ellipse's own frame, for a point ``(x, y)`` in the first
quadrant the contact point is ``(a^2 x / (s + a^2), b^2 y / (s + b^2))`` where ``s`` is the root
of ``F(s) = (a x / (s + a^2))^2 + (b y / (s + b^2))^2 - 1`` (Eberly). F is convex and decreasing
for ``s > -b^2``; Newton started left of the root, at ``max(b y - b^2, a x - a^2)``, converges
monotonically and cannot overshoot, so the iteration is safe for every point without bracketing.
Other quadrants follow by symmetry.

Coordinates (DESIGN.md): pixels, x right, y down; :class:`~labauto.vision.ellipse.Ellipse`
angles in degrees from +x toward +y, normalised so ``a >= b`` and angle in [0, 180).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from labauto.vision.ellipse import Ellipse

_OK, _TOO_FEW, _DEGENERATE, _NOT_ELLIPSE = 0, 1, 2, 3
_ROBUST_METHODS = ("ransac", "bootstrap")
_MAX_NEWTON = 60  # contact-point Newton steps at most (2-4 are typical)


@dataclass(frozen=True)
class EllipseFit:
    """Result of an ellipse fit.

    Attributes
    ----------
    ellipse : Ellipse
        The fitted ellipse (``a >= b``, angle in [0, 180)).
    rms : float
        Root mean square orthogonal distance of the fitted (inlier) points, px.
    iterations : int
        Levenberg-Marquardt iterations of the geometric fit (0 for a purely algebraic result).
    converged : bool
        The parameter step fell below the tolerance before ``max_iter``.
    n_inliers : int
        Number of points the final fit used (all points for the geometric fit).
    inliers : np.ndarray or None
        Boolean mask over the input points of the robust fit; None for the geometric fit.
    """

    ellipse: Ellipse
    rms: float
    iterations: int
    converged: bool
    n_inliers: int
    inliers: np.ndarray | None = field(default=None, repr=False, compare=False)


# ----------------------------------------------------------------------------- algebraic


def fit_ellipse_algebraic(points: np.ndarray) -> Ellipse:
    """Direct least-squares ellipse fit (Fitzgibbon; Halir-Flusser's stable form).

    Parameters
    ----------
    points : np.ndarray
        (n, 2) float array of points ``(x, y)``, n >= 5 (OpenCV's (n, 1, 2) also accepted).

    Returns
    -------
    Ellipse

    Raises
    ------
    ValueError
        If there are fewer than 5 points, non-finite values, the points are collinear or
        otherwise degenerate (too few distinct points), or no ellipse fits them.
    """
    pts = _as_points(points)
    mean = pts.mean(axis=0)
    centred = pts - mean
    scale = math.sqrt(float(np.einsum("ij,ij->", centred, centred)) / (2.0 * len(pts))) or 1.0
    x, y = centred[:, 0] / scale, centred[:, 1] / scale
    design = np.column_stack((x * x, x * y, y * y, x, y, np.ones_like(x)))
    scatter = (design.T @ design / len(pts))[None]
    params, status = _solve_scatter(scatter, mean[None], np.array([scale]))
    _raise_for_status(int(status[0]), len(pts))
    return Ellipse.normalised(*params[0])


def fit_ellipses_algebraic_batch(points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Direct algebraic ellipse fits of many contours at once.

    Parameters
    ----------
    points : np.ndarray
        (N, 2) float, all contours' points concatenated.
    offsets : np.ndarray
        (K + 1,) int, contour k is ``points[offsets[k]:offsets[k + 1]]`` with ``offsets[0] == 0``
        and ``offsets[-1] == N`` (the convention of ``shape_angle.shape_angles``).

    Returns
    -------
    np.ndarray
        (K, 5) float rows ``(cx, cy, a, b, angle_deg)`` with ``a >= b`` and angle in [0, 180);
        a row is NaN where the contour has fewer than 5 points, is degenerate or fits no
        ellipse. ``Ellipse.normalised(*row)`` turns a row into an :class:`Ellipse`.

    Raises
    ------
    ValueError
        If the arrays have the wrong shape, non-finite points or invalid offsets.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must be an (N, 2) array of (x, y), got shape {pts.shape}")
    if not np.isfinite(pts).all():
        raise ValueError("points contains NaN or infinite coordinates")
    off = np.asarray(offsets)
    if off.ndim != 1 or len(off) < 1 or not np.issubdtype(off.dtype, np.integer):
        raise ValueError(f"offsets must be a 1-d integer array of K + 1 indices, got {offsets!r}")
    if off[0] != 0 or off[-1] != len(pts) or np.any(np.diff(off) < 0):
        raise ValueError(
            f"offsets must rise from 0 to len(points) = {len(pts)}, "
            f"got first {off[0]}, last {off[-1]}"
        )
    params, status = _algebraic_batch(pts, off)
    params[status != _OK] = np.nan
    return params


def _algebraic_batch(points: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Halir-Flusser for K contours: (K, 5) parameters and (K,) status codes."""
    counts = np.diff(offsets)
    k = len(counts)
    params = np.full((k, 5), np.nan)
    status = np.full(k, _TOO_FEW)
    use = counts >= 5
    if not use.any():
        return params, status
    if not use.all():  # drop short contours, keep the rest contiguous
        keep = np.repeat(use, counts)
        sub_params, sub_status = _algebraic_batch(
            points[keep], np.concatenate(([0], np.cumsum(counts[use])))
        )
        params[use], status[use] = sub_params, sub_status
        return params, status

    starts = offsets[:-1]
    owner = np.repeat(np.arange(k), counts)
    x, y = points[:, 0], points[:, 1]
    mean = np.column_stack((np.add.reduceat(x, starts), np.add.reduceat(y, starts)))
    mean /= counts[:, None]
    x, y = x - mean[owner, 0], y - mean[owner, 1]
    scale = np.sqrt(np.add.reduceat(x * x + y * y, starts) / (2.0 * counts))
    scale = np.where(scale > 0, scale, 1.0)
    inv = (1.0 / scale)[owner]
    x *= inv
    y *= inv
    # The scatter of the design rows (x^2, xy, y^2, x, y, 1) holds only 14 distinct moments
    # x^i y^j (1 <= i + j <= 4) besides the count: sum each once per contour.
    xx, xy, yy = x * x, x * y, y * y
    monomials = {
        (1, 0): x, (0, 1): y, (2, 0): xx, (1, 1): xy, (0, 2): yy,
        (3, 0): xx * x, (2, 1): xx * y, (1, 2): x * yy, (0, 3): yy * y,
        (4, 0): xx * xx, (3, 1): xx * xy, (2, 2): xx * yy, (1, 3): xy * yy, (0, 4): yy * yy,
    }  # fmt: skip
    moments = {key: np.add.reduceat(m, starts) / counts for key, m in monomials.items()}
    moments[0, 0] = np.ones(k)
    exponents = ((2, 0), (1, 1), (0, 2), (1, 0), (0, 1), (0, 0))
    scatter = np.empty((k, 6, 6))
    for i, (ei, fi) in enumerate(exponents):
        for j, (ej, fj) in enumerate(exponents[i:], start=i):
            scatter[:, i, j] = scatter[:, j, i] = moments[ei + ej, fi + fj]
    return _solve_scatter(scatter, mean, scale)


def _solve_scatter(
    scatter: np.ndarray, mean: np.ndarray, scale: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Halir-Flusser on (K, 6, 6) mean scatter matrices of centred, scaled points.

    Returns (K, 5) ``cx, cy, a, b, deg`` in the original coordinates and (K,) status codes.
    """
    s1, s2, s3 = scatter[:, :3, :3], scatter[:, :3, 3:], scatter[:, 3:, 3:]
    # Collinear points (or fewer than 3 distinct ones) make S3 = sum [x y 1]^T [x y 1] singular.
    s3_eig = np.linalg.eigvalsh(s3)
    degenerate = s3_eig[:, 0] <= 1e-10 * s3_eig[:, -1]
    s3 = np.where(degenerate[:, None, None], np.eye(3), s3)
    t = -np.linalg.solve(s3, np.swapaxes(s2, 1, 2))  # (K, 3, 3)
    m = s1 + s2 @ t
    # C1^-1 M with C1 = [[0, 0, 2], [0, -1, 0], [2, 0, 0]]
    m = np.stack((m[:, 2] / 2.0, -m[:, 1], m[:, 0] / 2.0), axis=1)
    if not np.isfinite(m).all():
        bad = ~np.isfinite(m).all(axis=(1, 2))
        degenerate |= bad
        m[bad] = np.eye(3)
    _, vecs = np.linalg.eig(m)
    vecs = vecs.real
    cond = 4.0 * vecs[:, 0, :] * vecs[:, 2, :] - vecs[:, 1, :] ** 2  # (K, 3) per eigenvector
    best = np.argmax(cond, axis=1)
    a1 = vecs[np.arange(len(best)), :, best]
    ok_cond = cond[np.arange(len(best)), best] > 0
    a2 = (t @ a1[:, :, None])[:, :, 0]
    conic = np.concatenate((a1, a2), axis=1)

    geo, valid = _conic_to_params(conic)
    geo[:, 0] = mean[:, 0] + scale * geo[:, 0]
    geo[:, 1] = mean[:, 1] + scale * geo[:, 1]
    geo[:, 2] *= scale
    geo[:, 3] *= scale
    status = np.where(degenerate, _DEGENERATE, np.where(ok_cond & valid, _OK, _NOT_ELLIPSE))
    return geo, status


def _conic_to_params(conic: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, 6) conics ``A x^2 + B xy + C y^2 + D x + E y + F`` -> (K, 5) ``cx, cy, a, b, deg``."""
    conic = conic * np.where(conic[:, 0] + conic[:, 2] < 0, -1.0, 1.0)[:, None]
    a_, b_, c_, d_, e_, f_ = conic.T
    den = b_ * b_ - 4.0 * a_ * c_
    with np.errstate(divide="ignore", invalid="ignore"):
        x0 = (2.0 * c_ * d_ - b_ * e_) / den
        y0 = (2.0 * a_ * e_ - b_ * d_) / den
        f0 = f_ + 0.5 * (d_ * x0 + e_ * y0)  # conic value at the centre
        half_sum = 0.5 * (a_ + c_)
        root = np.hypot(0.5 * (a_ - c_), 0.5 * b_)
        lam_small, lam_big = half_sum - root, half_sum + root
        major = np.sqrt(-f0 / lam_small)
        minor = np.sqrt(-f0 / lam_big)
    angle = (np.degrees(0.5 * np.arctan2(b_, a_ - c_)) + 90.0) % 180.0
    valid = (den < 0) & (lam_small > 0) & (f0 < 0) & np.isfinite(major) & np.isfinite(minor)
    return np.column_stack((x0, y0, major, minor, angle)), valid


def _raise_for_status(status: int, n: int) -> None:
    if status == _TOO_FEW:
        raise ValueError(f"an ellipse fit needs at least 5 points, got {n}")
    if status == _DEGENERATE:
        raise ValueError(
            f"the {n} points are degenerate (collinear or fewer than 5 distinct); "
            "no ellipse can be fitted"
        )
    if status == _NOT_ELLIPSE:
        raise ValueError(f"no ellipse fits the {n} points (the best conic is not an ellipse)")


def _as_points(points: np.ndarray, name: str = "points") -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 3 and pts.shape[1] == 1 and pts.shape[2] == 2:
        pts = pts[:, 0, :]
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{name} must be an (n, 2) array of (x, y), got shape {pts.shape}")
    if len(pts) < 5:
        raise ValueError(f"an ellipse fit needs at least 5 points, got {len(pts)}")
    if not np.isfinite(pts).all():
        raise ValueError(f"{name} contains NaN or infinite coordinates")
    return pts


# ----------------------------------------------------------------------------- geometric


def fit_ellipse_geometric(
    points: np.ndarray,
    initial: Ellipse | None = None,
    *,
    max_iter: int = 50,
    tol: float = 1e-9,
) -> EllipseFit:
    """Orthogonal-distance (geometric) ellipse fit after Ahn et al. (2001).

    Parameters
    ----------
    points : np.ndarray
        (n, 2) float array of points ``(x, y)``, n >= 5.
    initial : Ellipse, optional
        Starting ellipse; by default :func:`fit_ellipse_algebraic`.
    max_iter : int
        Largest number of Levenberg-Marquardt iterations.
    tol : float
        Convergence (MINPACK's xtol and ftol in one number): the parameter step (centre and
        axes in px, angle times a) is below ``tol * max(a, 1)``, or an undamped Gauss-Newton
        step lowers the sum of squared distances by less than ``tol`` relative. Exact points
        converge quadratically to ~1e-12 px; noisy ones stop within ~1e-5 px of the optimum.

    Returns
    -------
    EllipseFit
        ``rms`` is the RMS orthogonal distance over all points.

    Raises
    ------
    ValueError
        As :func:`fit_ellipse_algebraic`, or for a bad ``initial``/``max_iter``/``tol``.
    """
    pts = _as_points(points)
    if initial is None:
        initial = fit_ellipse_algebraic(pts)
    elif not isinstance(initial, Ellipse):
        raise ValueError(f"initial must be an Ellipse or None, got {type(initial).__name__}")
    _check_iteration_args(max_iter, tol)
    if not (initial.axes[1] > 0 and all(map(math.isfinite, (*initial.center, *initial.axes)))):
        raise ValueError(f"initial ellipse must have finite centre and axes > 0, got {initial}")
    start = np.array([[*initial.center, *initial.axes, initial.angle]])
    params, rms, iterations, converged = _levenberg_marquardt(
        pts, np.array([0, len(pts)]), start, int(max_iter), tol
    )
    return EllipseFit(
        Ellipse.normalised(*params[0]),
        float(rms[0]),
        int(iterations[0]),
        bool(converged[0]),
        len(pts),
    )


def fit_ellipses_geometric_batch(
    points: np.ndarray,
    offsets: np.ndarray,
    initial: np.ndarray | None = None,
    *,
    max_iter: int = 50,
    tol: float = 1e-9,
) -> list[EllipseFit | None]:
    """Geometric fits of many contours at once (one vectorised Levenberg-Marquardt).

    Every iteration finds the contact points of all contours' points in one Newton loop and
    solves all 5x5 normal equations in one batched call, so 40 contours cost about as much
    as 3-4 single fits. Each contour keeps its own damping and stops on its own, and only the
    points of contours still iterating are evaluated.

    Parameters
    ----------
    points : np.ndarray
        (N, 2) float, all contours' points concatenated.
    offsets : np.ndarray
        (K + 1,) int, contour k is ``points[offsets[k]:offsets[k + 1]]`` (as
        :func:`fit_ellipses_algebraic_batch`).
    initial : np.ndarray, optional
        (K, 5) rows ``(cx, cy, a, b, angle_deg)``; by default the batched algebraic fits.
    max_iter, tol : int, float
        As :func:`fit_ellipse_geometric`.

    Returns
    -------
    list of EllipseFit or None
        One entry per contour; None where the contour has fewer than 5 points, is degenerate
        or its initial row is not a finite ellipse.
    """
    pts = np.asarray(points, dtype=np.float64)
    seeds = fit_ellipses_algebraic_batch(pts, offsets) if initial is None else None
    off = np.asarray(offsets)
    if initial is not None:
        seeds = np.array(initial, dtype=np.float64)
        if seeds.shape != (len(off) - 1, 5):
            raise ValueError(f"initial must have shape ({len(off) - 1}, 5), got {seeds.shape}")
        fit_ellipses_algebraic_batch(pts, off)  # validates points and offsets
    _check_iteration_args(max_iter, tol)
    assert seeds is not None
    counts = np.diff(off)
    ok = np.isfinite(seeds).all(axis=1) & (counts >= 5) & (seeds[:, 3] > 0) & (seeds[:, 2] > 0)
    results: list[EllipseFit | None] = [None] * len(counts)
    if not ok.any():
        return results
    keep = np.repeat(ok, counts)
    sub_offsets = np.concatenate(([0], np.cumsum(counts[ok])))
    params, rms, iterations, converged = _levenberg_marquardt(
        pts[keep], sub_offsets, seeds[ok], int(max_iter), tol
    )
    for j, k in enumerate(np.flatnonzero(ok)):
        results[k] = EllipseFit(
            Ellipse.normalised(*params[j]),
            float(rms[j]),
            int(iterations[j]),
            bool(converged[j]),
            int(counts[k]),
        )
    return results


def _check_iteration_args(max_iter: int, tol: float) -> None:
    if int(max_iter) != max_iter or max_iter < 0:
        raise ValueError(f"max_iter must be an integer >= 0, got {max_iter!r}")
    if not (tol > 0 and math.isfinite(tol)):
        raise ValueError(f"tol must be a finite number > 0, got {tol!r}")


def _levenberg_marquardt(
    pts: np.ndarray, offsets: np.ndarray, start: np.ndarray, max_iter: int, tol: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Minimise each contour's squared orthogonal distances, all contours at once.

    ``start`` is (K, 5) ``cx, cy, a, b, angle_deg``. Per contour: Gauss-Newton steps while
    they lower the cost; when one does not, Marquardt damping ``lam * diag(J^T J)`` is switched
    on and raised tenfold until a step succeeds, and lowered after every success. The contact
    roots of the last accepted parameters seed the next evaluation (2 Newton steps typical).
    Only the points of contours still iterating are evaluated: the working set shrinks as
    contours converge.

    Returns (K, 5) parameters (angle in degrees), (K,) rms, iterations and converged flags.
    """
    k = len(start)
    counts = np.diff(offsets)
    p = start.astype(np.float64).copy()
    p[:, 4] = np.radians(p[:, 4])
    lam = np.zeros(k)
    iterations = np.zeros(k, dtype=int)
    converged = np.zeros(k, dtype=bool)
    active = np.ones(k, dtype=bool) if max_iter > 0 else np.zeros(k, dtype=bool)
    # the working set: contours ``ids`` and their points, contour by contour
    ids = np.arange(k)
    w_counts = counts
    w_starts = offsets[:-1]
    local = np.repeat(ids, counts)
    x = np.ascontiguousarray(pts[:, 0])
    y = np.ascontiguousarray(pts[:, 1])
    dist, jac, roots = _residuals(x, y, p, local)
    cost = np.add.reduceat(dist * dist, w_starts)
    rows, cols = np.triu_indices(5)
    diagonal = np.arange(5)
    while active.any():
        keep = active[ids]
        if not keep.all():  # drop the points of contours that stopped
            on_points = np.repeat(keep, w_counts)
            x, y, dist, roots = x[on_points], y[on_points], dist[on_points], roots[on_points]
            jac = jac[:, on_points]
            ids, w_counts = ids[keep], w_counts[keep]
            w_starts = np.concatenate(([0], np.cumsum(w_counts)[:-1]))
            local = np.repeat(np.arange(len(ids)), w_counts)
        iterations[ids] += 1
        # per-contour normal equations: J^T J (upper triangle) and J^T d, row by row (small
        # temporaries stay in cache)
        hess = np.empty((len(ids), 5, 5))
        for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
            hess[:, r, c] = hess[:, c, r] = np.add.reduceat(jac[r] * jac[c], w_starts)
        grad = np.add.reduceat(jac * dist, w_starts, axis=1).T
        diag = hess[:, diagonal, diagonal]
        w_lam = lam[ids]
        # a tiny ridge keeps the angle column solvable for a circle (where it is zero)
        hess[:, diagonal, diagonal] += w_lam[:, None] * diag + 1e-12 * diag.sum(
            axis=1, keepdims=True
        )
        step = -np.linalg.solve(hess, grad[:, :, None])[:, :, 0]
        w_p = p[ids]
        size = np.maximum(np.maximum(w_p[:, 2], w_p[:, 3]), 1.0)
        step_px = np.sqrt((step[:, :4] ** 2).sum(axis=1) + (size * step[:, 4]) ** 2)
        trial = w_p + step
        valid = np.isfinite(trial).all(axis=1) & (trial[:, 2] > 0) & (trial[:, 3] > 0)
        trial[~valid] = w_p[~valid]
        dist_t, jac_t, roots_t = _residuals(x, y, trial, local, roots)
        cost_t = np.where(valid, np.add.reduceat(dist_t * dist_t, w_starts), np.inf)

        w_cost = cost[ids]
        small_step = step_px <= tol * size
        accept = cost_t <= w_cost
        small_gain = accept & (w_lam == 0.0) & (w_cost - cost_t <= tol * w_cost)
        p[ids[accept]] = trial[accept]
        cost[ids[accept]] = cost_t[accept]
        if accept.all():
            dist, jac, roots = dist_t, jac_t, roots_t
        elif accept.any():
            moved = np.repeat(accept, w_counts)
            dist = np.where(moved, dist_t, dist)
            jac = np.where(moved, jac_t, jac)
            roots = np.where(moved, roots_t, roots)
        w_lam = np.where(accept, np.where(w_lam <= 1e-6, 0.0, w_lam / 10.0), w_lam)
        reject = ~accept & ~small_step
        w_lam = np.where(reject, np.where(w_lam == 0.0, 1e-3, w_lam * 10.0), w_lam)
        lam[ids] = w_lam
        done = (accept & (small_step | small_gain)) | (~accept & small_step)
        converged[ids] |= done
        active[ids] = ~done & (w_lam <= 1e12) & (iterations[ids] < max_iter)
    p[:, 4] = np.degrees(p[:, 4])
    rms = np.sqrt(cost / counts)
    return p, rms, iterations, converged


def _residuals(
    x: np.ndarray,
    y: np.ndarray,
    params: np.ndarray,
    local: np.ndarray,
    roots: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_distances_and_jacobian` for K contours: point i belongs to contour ``local[i]``.

    ``params`` is (K, 5) ``xc, yc, a, b, angle_rad``; the angle's sine and cosine are taken
    once per contour. Returns the (n,) distances, the (5, n) Jacobian (one row per parameter,
    so the normal equations reduce along contiguous rows) and the contact roots.
    """
    xc, yc, a, b, alpha = params.T
    c, s = np.cos(alpha)[local], np.sin(alpha)[local]
    a, b = a[local], b[local]
    dx, dy = x - xc[local], y - yc[local]
    u = c * dx + s * dy  # point in the ellipse frame
    v = c * dy - s * dx
    fu, fv, roots = _contact(u, v, a, b, roots)
    nu, nv = fu / (a * a), fv / (b * b)  # outward normal (unnormalised) in the ellipse frame
    norm = np.sqrt(nu * nu + nv * nv)  # (np.hypot is several times slower)
    nu /= norm
    nv /= norm
    dist = nu * (u - fu) + nv * (v - fv)
    jac = np.empty((5, len(x)))
    jac[0] = s * nv - c * nu  # -n_world . e_x
    jac[1] = -(s * nu + c * nv)
    jac[2] = -nu * fu / a
    jac[3] = -nv * fv / b
    jac[4] = nu * fv - nv * fu
    return dist, jac, roots


def _distances_and_jacobian(
    pts: np.ndarray, p: np.ndarray, roots: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed orthogonal distances (outside > 0), their (n, 5) Jacobian and the contact roots.

    ``p`` is (n, 5) ``xc, yc, a, b, angle_rad`` per point (or (5,) for all points).
    """
    xc, yc, a, b, alpha = np.asarray(p).T
    c, s = np.cos(alpha), np.sin(alpha)
    dx, dy = pts[:, 0] - xc, pts[:, 1] - yc
    u = c * dx + s * dy  # point in the ellipse frame
    v = c * dy - s * dx
    fu, fv, roots = _contact(u, v, a, b, roots)
    nu, nv = fu / (a * a), fv / (b * b)  # outward normal (unnormalised) in the ellipse frame
    norm = np.hypot(nu, nv)
    nu, nv = nu / norm, nv / norm
    dist = nu * (u - fu) + nv * (v - fv)
    jac = np.empty((len(pts), 5))
    jac[:, 0] = s * nv - c * nu  # -n_world . e_x
    jac[:, 1] = -(s * nu + c * nv)
    jac[:, 2] = -nu * fu / a
    jac[:, 3] = -nv * fv / b
    jac[:, 4] = nu * fv - nv * fu
    return dist, jac, roots


def contact_points(
    u: np.ndarray, v: np.ndarray, a: float, b: float
) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal contact points on the axis-aligned ellipse ``u^2/a^2 + v^2/b^2 = 1``.

    Parameters
    ----------
    u, v : np.ndarray
        Point coordinates in the ellipse's frame (centre at 0, first axis along u).
    a, b : float
        Semi-axes along u and v, > 0 (any order).

    Returns
    -------
    tuple of np.ndarray
        The contact points ``(u_c, v_c)``: the nearest points on the ellipse.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if not (a > 0 and b > 0):
        raise ValueError(f"semi-axes must be > 0, got a={a!r}, b={b!r}")
    cu, cv, _ = _contact(u, v, float(a), float(b), None)
    return cu, cv


def _contact(
    u: np.ndarray, v: np.ndarray, a: np.ndarray, b: np.ndarray, guess: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact points and roots ``s`` (module docstring) for per-point semi-axes a, b.

    ``guess`` seeds ``s`` (it is symmetric in the two axes, so it survives an axis swap).
    """
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), u.shape)
    b = np.broadcast_to(np.asarray(b, dtype=np.float64), u.shape)
    swap = a < b  # work with the longer axis along x
    x = np.abs(np.where(swap, v, u))
    y = np.abs(np.where(swap, u, v))
    a, b = np.maximum(a, b), np.minimum(a, b)
    a2, b2 = a * a, b * b
    # On the major axis inside the evolute (y = 0, a x <= a^2 - b^2; the centre included) the
    # root is s = -b^2, a pole of F: solved in closed form below, iterated as a dummy point.
    inner = (y == 0) & (a * x <= a2 - b2)
    any_inner = bool(inner.any())
    if any_inner:
        x_inner = x[inner]
        x = np.where(inner, a, x)
    ax, by = a * x, b * y
    safe = np.maximum(by - b2, ax - a2)  # F(safe) >= 0: left of the root, and > -b^2
    if guess is None:  # first order: p = c + s grad(Q)/2 at the contact c
        qx, qy = x / a2, y / b2
        guess = 0.5 * (x * qx + y * qy - 1.0) / (qx * qx + qy * qy)
    # One Newton step from the guess lands left of the root from either side (F is convex);
    # the safe start replaces it if better. From there Newton is monotone and cannot overshoot.
    # Every point iterates until its own step is below 1e-9 (s + b^2): Newton converges
    # quadratically there, so the error left is far below that. The points still moving go on
    # alone (most stop after 2-4 steps).
    s = np.maximum(guess, safe)
    s = np.maximum(s + _newton_step(s, ax, by, a2, b2), safe)
    idx = None  # all points
    cur = [s, ax, by, a2, b2]
    for _ in range(_MAX_NEWTON):
        step = _newton_step(*cur)
        cur[0] = cur[0] + step
        busy = np.abs(step) > 1e-9 * (np.abs(cur[0]) + cur[4])
        n_busy = int(np.count_nonzero(busy))
        if n_busy == 0:
            break
        if n_busy <= len(busy) // 2:  # carry on with the busy points alone
            s = _scatter(s, idx, cur[0])
            idx = np.flatnonzero(busy) if idx is None else idx[busy]
            cur = [v[busy] for v in cur]
    s = _scatter(s, idx, cur[0])
    cu = a2 * x / (s + a2)
    cv = b2 * y / (s + b2)
    if any_inner:
        ai, bi = a[inner], b[inner]
        with np.errstate(divide="ignore", invalid="ignore"):
            cu_in = np.where(ai > bi, ai * ai * x_inner / (ai * ai - bi * bi), 0.0)
        cu[inner] = cu_in
        cv[inner] = bi * np.sqrt(np.clip(1.0 - (cu_in / ai) ** 2, 0.0, 1.0))
        s[inner] = -bi * bi
    cu, cv = np.where(swap, cv, cu), np.where(swap, cu, cv)
    return np.copysign(cu, u), np.copysign(cv, v), s


def _scatter(s: np.ndarray, idx: np.ndarray | None, values: np.ndarray) -> np.ndarray:
    """``s`` with ``values`` written at ``idx`` (``values`` itself when ``idx`` is None: all)."""
    if idx is None:
        return values
    s[idx] = values
    return s


def _newton_step(
    s: np.ndarray, ax: np.ndarray, by: np.ndarray, a2: np.ndarray, b2: np.ndarray
) -> np.ndarray:
    """Newton step ``-F(s) / F'(s)`` for the contact root (module docstring)."""
    pa, pb = s + a2, s + b2
    ra, rb = ax / pa, by / pb
    ra2, rb2 = ra * ra, rb * rb
    return (ra2 + rb2 - 1.0) / (2.0 * (ra2 / pa + rb2 / pb))


# ----------------------------------------------------------------------------- robust


def fit_ellipse_robust(
    points: np.ndarray,
    *,
    method: str = "ransac",
    rng: np.random.Generator | int | None = None,
    inlier_px: float = 1.0,
    max_trials: int = 300,
    n_arcs: int = 12,
    arcs_per_trial: int = 3,
    min_inlier_fraction: float = 0.2,
    max_refits: int = 5,
) -> EllipseFit:
    """Robust ellipse fit for contours with outliers or gaps.

    Parameters
    ----------
    points : np.ndarray
        (n, 2) float points ``(x, y)``, n >= 5; for ``"bootstrap"`` in contour order.
    method : str
        ``"ransac"``: hypotheses are exact conics through 5 random points (batched SVD).
        ``"bootstrap"`` (the paper's "parts of an ellipse"): the contour is cut into ``n_arcs``
        contiguous arcs and each hypothesis is the algebraic fit of ``arcs_per_trial`` random
        arcs; good when outliers come in runs (a merged neighbour, a bump) rather than scattered.
    rng : numpy Generator, int or None
        Random source; None means a fixed seed (0) so results are reproducible.
    inlier_px : float
        A point is an inlier when its orthogonal distance is at most this (px); about 2.5 times
        the noise sigma.
    max_trials : int
        Number of hypotheses.
    n_arcs, arcs_per_trial : int
        Bootstrap arc count and arcs combined per hypothesis.
    min_inlier_fraction : float
        Fail when fewer than this fraction of the points (and fewer than 5) are inliers.
    max_refits : int
        Geometric refits with re-chosen inliers (stops early when the inlier set is stable).

    Returns
    -------
    EllipseFit
        ``n_inliers`` and ``inliers`` describe the final inlier set; ``rms`` is over the inliers.

    Raises
    ------
    ValueError
        For bad arguments, fewer than 5 points, degenerate points, or when no hypothesis has
        enough inliers.

    Notes
    -----
    Hypotheses are scored MSAC-style, ``sum(min(d^2, inlier_px^2))`` with ``d`` the Sampson
    distance (first-order orthogonal distance), which ranks them like the inlier count but
    prefers the tighter of two equally supported ellipses. The best one is refined by the
    algebraic then the geometric fit on its inliers; inliers are then re-chosen with the exact
    orthogonal distance and the geometric fit repeated until the set no longer changes.
    """
    pts = _as_points(points)
    if method not in _ROBUST_METHODS:
        raise ValueError(f"method must be one of {_ROBUST_METHODS}, got {method!r}")
    if not (inlier_px > 0 and math.isfinite(inlier_px)):
        raise ValueError(f"inlier_px must be a finite number > 0, got {inlier_px!r}")
    for name, value, low in (
        ("max_trials", max_trials, 1),
        ("n_arcs", n_arcs, 2),
        ("arcs_per_trial", arcs_per_trial, 1),
        ("max_refits", max_refits, 1),
    ):
        if int(value) != value or value < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    if method == "bootstrap" and arcs_per_trial > n_arcs:
        raise ValueError(f"arcs_per_trial ({arcs_per_trial}) must not exceed n_arcs ({n_arcs})")
    if not 0 <= min_inlier_fraction <= 1:
        raise ValueError(f"min_inlier_fraction must be in [0, 1], got {min_inlier_fraction!r}")
    generator = np.random.default_rng(0 if rng is None else rng)

    # Work on centred, scaled points so conic coefficients are well conditioned.
    mean = pts.mean(axis=0)
    scale = float(np.sqrt(((pts - mean) ** 2).sum(axis=1).mean() / 2.0)) or 1.0
    norm_pts = (pts - mean) / scale
    if method == "ransac":
        conics = _five_point_conics(norm_pts, generator, int(max_trials))
    else:
        conics = _bootstrap_conics(
            norm_pts, generator, int(max_trials), int(n_arcs), int(arcs_per_trial)
        )
    if len(conics) == 0:
        raise ValueError("no ellipse hypothesis could be formed from the points (degenerate set)")
    threshold = inlier_px / scale
    sampson = _sampson_distances(conics, norm_pts)  # (K, n)
    score = np.minimum(sampson**2, threshold**2).sum(axis=1)
    best = int(np.argmin(score))
    inliers = sampson[best] <= threshold
    min_inliers = max(5, math.ceil(min_inlier_fraction * len(pts)))
    if inliers.sum() < min_inliers:
        raise ValueError(
            f"no ellipse found: the best hypothesis has {int(inliers.sum())} inliers within "
            f"{inlier_px} px, fewer than {min_inliers}"
        )

    try:
        current = fit_ellipse_algebraic(pts[inliers])
    except ValueError:
        current = Ellipse.normalised(*_conic_to_params(conics[best : best + 1])[0][0])
        current = Ellipse.normalised(
            mean[0] + scale * current.center[0],
            mean[1] + scale * current.center[1],
            scale * current.axes[0],
            scale * current.axes[1],
            current.angle,
        )
    total_iterations, fit = 0, None
    for _ in range(int(max_refits)):
        fit = fit_ellipse_geometric(pts[inliers], current)
        total_iterations += fit.iterations
        current = fit.ellipse
        new_inliers = np.abs(orthogonal_distances(pts, current)) <= inlier_px
        if new_inliers.sum() < min_inliers or np.array_equal(new_inliers, inliers):
            break
        inliers = new_inliers
    assert fit is not None
    return EllipseFit(
        fit.ellipse, fit.rms, total_iterations, fit.converged, int(inliers.sum()), inliers
    )


def orthogonal_distances(points: np.ndarray, ellipse: Ellipse) -> np.ndarray:
    """Signed orthogonal distances (px, outside > 0) of ``points`` from ``ellipse``.

    Parameters
    ----------
    points : np.ndarray
        (n, 2) float points ``(x, y)``.
    ellipse : Ellipse
        The ellipse.

    Returns
    -------
    np.ndarray
        (n,) distances.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    p = np.array([*ellipse.center, *ellipse.axes, math.radians(ellipse.angle)])
    return _distances_and_jacobian(pts, p)[0]


def _five_point_conics(pts: np.ndarray, rng: np.random.Generator, trials: int) -> np.ndarray:
    """(K, 6) ellipse conics through 5 random distinct points each (non-ellipses dropped)."""
    n = len(pts)
    if n <= 64:
        idx = np.argsort(rng.random((trials, n)), axis=1)[:, :5]
    else:
        idx = _distinct_indices(rng, trials, n)
    x, y = pts[idx, 0], pts[idx, 1]  # (K, 5)
    design = np.stack((x * x, x * y, y * y, x, y, np.ones_like(x)), axis=2)  # (K, 5, 6)
    _, sing, vh = np.linalg.svd(design)
    conics = vh[:, -1, :]
    # a 5-point sample with a 2-d null space (4 collinear points...) has no unique conic
    unique = sing[:, -1] > 1e-9 * sing[:, 0]
    is_ellipse = conics[:, 1] ** 2 - 4.0 * conics[:, 0] * conics[:, 2] < 0
    return conics[unique & is_ellipse]


def _distinct_indices(rng: np.random.Generator, trials: int, n: int) -> np.ndarray:
    """(trials, 5) random indices in [0, n), distinct within each row."""
    idx = rng.integers(0, n, size=(trials, 5))
    for _ in range(10):
        srt = np.sort(idx, axis=1)
        dup = (np.diff(srt, axis=1) == 0).any(axis=1)
        if not dup.any():
            break
        idx[dup] = rng.integers(0, n, size=(int(dup.sum()), 5))
    return idx


def _bootstrap_conics(
    pts: np.ndarray, rng: np.random.Generator, trials: int, n_arcs: int, per_trial: int
) -> np.ndarray:
    """(K, 6) conics of algebraic fits to random combinations of contiguous arcs."""
    bounds = np.linspace(0, len(pts), n_arcs + 1).round().astype(int)
    choice = np.argsort(rng.random((trials, n_arcs)), axis=1)[:, :per_trial]
    choice = np.unique(np.sort(choice, axis=1), axis=0)  # no duplicate hypotheses
    chunks, offsets = [], [0]
    for row in choice:
        sel = np.concatenate([np.arange(bounds[i], bounds[i + 1]) for i in row])
        chunks.append(pts[sel])
        offsets.append(offsets[-1] + len(sel))
    params = fit_ellipses_algebraic_batch(np.concatenate(chunks), np.array(offsets))
    params = params[np.isfinite(params).all(axis=1)]
    return _params_to_conics(params)


def _params_to_conics(params: np.ndarray) -> np.ndarray:
    """(K, 5) ``cx, cy, a, b, deg`` -> (K, 6) conic coefficients (scaled to unit norm)."""
    cx, cy, a, b, deg = params.T
    t = np.radians(deg)
    c, s = np.cos(t), np.sin(t)
    ia, ib = 1.0 / (a * a), 1.0 / (b * b)
    qa = c * c * ia + s * s * ib
    qb = 2.0 * c * s * (ia - ib)
    qc = s * s * ia + c * c * ib
    qd = -2.0 * qa * cx - qb * cy
    qe = -qb * cx - 2.0 * qc * cy
    qf = qa * cx * cx + qb * cx * cy + qc * cy * cy - 1.0
    conics = np.column_stack((qa, qb, qc, qd, qe, qf))
    return conics / np.linalg.norm(conics, axis=1, keepdims=True)


def _sampson_distances(conics: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(K, n) Sampson distances |Q(p)| / |grad Q(p)| of n points to K conics."""
    x, y = pts[:, 0], pts[:, 1]
    a, b, c, d, e, f = (conics[:, i : i + 1] for i in range(6))
    value = a * x * x + b * x * y + c * y * y + d * x + e * y + f
    gx = 2.0 * a * x + b * y + d
    gy = b * x + 2.0 * c * y + e
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = np.abs(value) / np.hypot(gx, gy)
    return np.nan_to_num(dist, nan=np.inf)
