"""Ellipse fitting: direct algebraic, geometric (orthogonal distances, Ahn et al.) and robust.

The paper (section 4.2) fits markers with "an iterative ellipse fitting algorithm [Ahn et al.]
... a least squares method based on the perpendicular distance. Starting from seed values,
defined by the contour, an iterative approach fits an ellipse with sub-pixel precision", and
mentions a bootstrap that fits parts of an ellipse and combines them. This module provides:

* :func:`fit_ellipse_algebraic` - the direct least-squares fit of Fitzgibbon et al. in the
  numerically stable form of Halir and Flusser (1998), on points centred and scaled to unit RMS
  radius. Always an ellipse, one 3x3 eigenproblem, but biased toward small ellipses on noisy
  short arcs. :func:`fit_ellipses_algebraic_batch` does the same for many contours at once.
* :func:`fit_ellipse_geometric` - minimises the sum of squared orthogonal distances (Ahn,
  Rauh and Warnecke, Pattern Recognition 34, 2001). For every point the orthogonal contact
  point on the current ellipse is found by a Newton iteration (below); then a
  Levenberg-Marquardt step on the 5 parameters ``(xc, yc, a, b, angle)`` uses the Jacobian of
  the orthogonal distances. At the contact point the distance is stationary along the ellipse,
  so its derivative is ``-n . d(x_contact)/d(parameter)`` at fixed ellipse parameter ``t``
  (``n`` the unit normal); this is Ahn's Jacobian in closed form. Seeded by the algebraic fit it
  converges in 3-6 iterations. :func:`fit_ellipses_geometric_batch` runs the same iteration for
  many contours at once (each contour with its own damping and stopping);
  :func:`fit_selected_ellipses` fits the selected contours of a contour set where they lie (the
  detector's DES: no gathered copy of their points, only the ellipses built).
* :func:`fit_ellipse_robust` - RANSAC (batched 5-point conics, MSAC scoring with the Sampson
  distance) or the paper's bootstrap (algebraic fits of random combinations of contiguous
  arcs), then the geometric fit on the inliers with the inlier set re-chosen by true
  orthogonal distance until it is stable.

Algebraic fit (Halir-Flusser): with the design rows ``(x^2, xy, y^2, x, y, 1)`` of the centred,
scaled points and their mean scatter ``S = [[S1, S2], [S2^T, S3]]`` (3x3 blocks, built from the
14 moments ``x^i y^j``, ``1 <= i + j <= 4``), the linear part is eliminated,
``T = -S3^-1 S2^T``, and the quadratic part ``a1`` is the eigenvector of
``C1^-1 (S1 + S2 T)``, ``C1 = [[0, 0, 2], [0, -1, 0], [2, 0, 0]]``, with the largest
``4 a c - b^2`` (> 0 for an ellipse; unit-norm eigenvectors). The conic is ``(a1, T a1)``.
Collinear points (or fewer than 3 distinct ones) make S3 singular: smallest eigenvalue at most
1e-10 times the largest.

Geometric fit (Levenberg-Marquardt, per contour): Gauss-Newton steps on the normal equations
``(J^T J + lam diag(J^T J) + 1e-12 trace(J^T J) I) step = -J^T d`` (the tiny ridge keeps the
angle column solvable for a circle, where it is zero) while they lower the cost; when one does
not, Marquardt damping is switched on (``lam = 1e-3``) and raised tenfold until a step
succeeds, and lowered tenfold after every success (to 0 from 1e-6 or less). The fit stops when
an accepted step is small (``|step| <= tol * max(a, b, 1)``, angle scaled by that size) or an
undamped step gains less than ``tol`` relative, when a rejected step is small, when
``lam > 1e12`` or after ``max_iter`` iterations. The contact roots of the last accepted
parameters seed the next evaluation (2 Newton steps typical).

Orthogonal contact point: in the ellipse's own frame, for a point ``(x, y)`` in the first
quadrant the contact point is ``(a^2 x / (s + a^2), b^2 y / (s + b^2))`` where ``s`` is the root
of ``F(s) = (a x / (s + a^2))^2 + (b y / (s + b^2))^2 - 1`` (Eberly). F is convex and decreasing
for ``s > -b^2``; Newton started left of the root, at ``max(b y - b^2, a x - a^2)``, converges
monotonically and cannot overshoot, so the iteration is safe for every point without bracketing.
The first guess is first order (``p = c + s grad(Q)/2`` at the contact ``c``) or the root of
the previous parameters; one Newton step from it lands left of the root from either side (F is
convex) and the safe start replaces it if better. Every point iterates until its step is below
``1e-9 (|s| + b^2)`` (at most 60 steps): Newton converges quadratically there, so the error left
is far below that. (The kernel takes the step ``-F/F'`` over the common denominator
``pa^3 pb^3``, ``pa = s + a^2``, ``pb = s + b^2``: one division instead of five, the same
iterates up to rounding.) On the major axis inside the evolute (``y = 0``, ``a x <= a^2 - b^2``; the
centre included) the root is ``s = -b^2``, a pole of F, and the contact point has a closed form.
Other quadrants follow by symmetry.

The loops (moments, contact points, normal equations, the whole Levenberg-Marquardt of every
contour) are written out in numpy in :mod:`labauto.vision.ellipse_plain`, the reference; the
compiled kernel :mod:`labauto.vision.kernels.ellipse_fit` runs them in one call per batch with
the contours shared among threads, with the same results to rounding. The single-contour
functions are batches of one.

Coordinates (DESIGN.md): pixels, x right, y down; :class:`~labauto.vision.ellipse.Ellipse`
angles in degrees from +x toward +y, normalised so ``a >= b`` and angle in [0, 180).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import ModuleType

import numpy as np

from labauto.vision import ellipse_plain, kernels
from labauto.vision.ellipse import Ellipse

_OK, _TOO_FEW, _DEGENERATE, _NOT_ELLIPSE, _BAD_INITIAL = 0, 1, 2, 3, 4
_ROBUST_METHODS = ("ransac", "bootstrap")
_INT_MAX = 2**31 - 1


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
    params = np.empty((1, 5))
    status = _run(pts, np.array([0, len(pts)], dtype=np.intp), params, seed=True)[0]
    _raise_for_status(int(status[0]), len(pts))
    return Ellipse.normalised(*params[0].tolist())


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
    pts, off = _check_batch(points, offsets)
    params = np.empty((len(off) - 1, 5))
    status = _run(pts, off, params, seed=True)[0]
    params[status != _OK] = np.nan
    return params


def _check_batch(points: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validated C-contiguous float64 (N, 2) points and intp (K + 1,) offsets."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
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
    return pts, np.ascontiguousarray(off, dtype=np.intp)


def _run(
    pts: np.ndarray,
    off: np.ndarray,
    params: np.ndarray,
    *,
    seed: bool,
    max_iter: int = -1,
    tol: float = 1.0,
    index: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Run the kernel on validated input, in place on ``params``.

    Algebraic seeds into ``params`` when ``seed``, then the geometric fits from ``params`` when
    ``max_iter >= 0``, of the contours ``index`` ((K,) intp; by default all, in order). Returns
    (K,) status codes, rms, iterations and converged flags (the last three are meaningful where
    the status is ok and a geometric fit ran).
    """
    if index is None:
        index = np.arange(len(off) - 1, dtype=np.intp)
    k = len(index)
    status = np.empty(k, dtype=np.int32)
    rms = np.zeros(k)
    iterations = np.zeros(k, dtype=np.int32)
    converged = np.zeros(k, dtype=np.uint8)
    arrays = (pts, off, index, params, status, rms, iterations, converged)
    kernel = kernels.compiled("ellipse_fit")
    if kernel is None:
        ellipse_plain.fit_ellipses(*arrays, seed, min(max_iter, _INT_MAX), tol)
    else:
        kernel.fit_ellipses(*arrays, seed, min(max_iter, _INT_MAX), tol, kernels.threads())
    return status, rms, iterations, converged


def _fits() -> ModuleType:
    """The compiled ellipse kernel when it runs, else its plain twin (the same functions)."""
    return kernels.compiled("ellipse_fit") or ellipse_plain


def _conic_to_params(conic: np.ndarray) -> np.ndarray:
    """Conic ``(A, B, C, D, E, F)`` -> ``(cx, cy, major, minor, angle_deg)``.

    The conic is ``A x^2 + B xy + C y^2 + D x + E y + F = 0``; the row is NaN or meaningless
    when it is no real ellipse.
    """
    out = np.empty((1, 5))
    _fits().conics_to_params(
        np.ascontiguousarray(conic, dtype=np.float64).reshape(1, 6), out, np.empty(1, np.uint8)
    )
    return out[0]


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
    return np.ascontiguousarray(pts)


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
    if initial is not None and not isinstance(initial, Ellipse):
        raise ValueError(f"initial must be an Ellipse or None, got {type(initial).__name__}")
    _check_iteration_args(max_iter, tol)
    params = np.empty((1, 5))
    if initial is not None:
        if not (initial.axes[1] > 0 and all(map(math.isfinite, (*initial.center, *initial.axes)))):
            raise ValueError(f"initial ellipse must have finite centre and axes > 0, got {initial}")
        params[0] = (*initial.center, *initial.axes, initial.angle)
    status, rms, iterations, converged = _run(
        pts,
        np.array([0, len(pts)], dtype=np.intp),
        params,
        seed=initial is None,
        max_iter=int(max_iter),
        tol=float(tol),
    )
    _raise_for_status(int(status[0]), len(pts))
    return EllipseFit(
        Ellipse.normalised(*params[0].tolist()),
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
    """Geometric fits of many contours at once (one compiled call).

    The algebraic seeds and every contour's Levenberg-Marquardt run in one kernel call, the
    contours shared among threads; each contour keeps its own damping and stops on its own,
    exactly as :func:`fit_ellipse_geometric` (which is a batch of one).

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
    pts, off = _check_batch(points, offsets)
    _check_iteration_args(max_iter, tol)
    k = len(off) - 1
    if initial is None:
        params = np.empty((k, 5))
    else:
        params = np.array(initial, dtype=np.float64, order="C")
        if params.shape != (k, 5):
            raise ValueError(f"initial must have shape ({k}, 5), got {params.shape}")
    status, rms, iterations, converged = _run(
        pts, off, params, seed=initial is None, max_iter=int(max_iter), tol=float(tol)
    )
    # the kernel's rows are normalised already (``Ellipse.normalised``'s rule)
    fits = zip(
        (status == _OK).tolist(),
        params.tolist(),
        rms.tolist(),
        iterations.tolist(),
        converged.astype(bool).tolist(),
        np.diff(off).tolist(),
        strict=True,
    )
    return [
        EllipseFit(Ellipse((cx, cy), (a, b), angle), fit_rms, n_iter, conv, n) if ok else None
        for ok, (cx, cy, a, b, angle), fit_rms, n_iter, conv, n in fits
    ]


def fit_selected_ellipses(
    points: np.ndarray,
    offsets: np.ndarray,
    selected: np.ndarray,
    *,
    max_iter: int = 50,
    tol: float = 1e-9,
) -> list[Ellipse | None]:
    """Geometric ellipses of the selected contours of a contour set (the detector's batch).

    The same fits as :func:`fit_ellipses_geometric_batch` of the selected contours (algebraic
    seeds, then Levenberg-Marquardt), in one kernel call that reads the selected contours where
    they are (no gathered copy of their points) and only the ellipses as the result.

    Parameters
    ----------
    points : np.ndarray
        (N, 2) float, all contours' points concatenated.
    offsets : np.ndarray
        (K + 1,) int, contour k is ``points[offsets[k]:offsets[k + 1]]`` (as
        :func:`fit_ellipses_algebraic_batch`).
    selected : np.ndarray
        (K,) bool, the contours to fit.
    max_iter, tol : int, float
        As :func:`fit_ellipse_geometric`.

    Returns
    -------
    list of Ellipse or None
        One entry per contour: the fitted ellipse of a selected contour, None for the others
        and where :func:`fit_ellipses_geometric_batch` gives None.

    Raises
    ------
    ValueError
        As :func:`fit_ellipses_geometric_batch`, or for a ``selected`` that is no (K,) mask.
    """
    pts, off = _check_batch(points, offsets)
    _check_iteration_args(max_iter, tol)
    mask = np.asarray(selected)
    k = len(off) - 1
    if mask.shape != (k,) or mask.dtype != np.bool_:
        raise ValueError(
            f"selected must be a ({k},) boolean mask, got {mask.dtype} of shape {mask.shape}"
        )
    index = np.flatnonzero(mask)
    params = np.empty((len(index), 5))
    status, _, _, _ = _run(
        pts, off, params, seed=True, max_iter=int(max_iter), tol=float(tol), index=index
    )
    out: list[Ellipse | None] = [None] * k
    # the kernel's rows are normalised already (``Ellipse.normalised``'s rule)
    for j, ok, (cx, cy, a, b, angle) in zip(
        index.tolist(), (status == _OK).tolist(), params.tolist(), strict=True
    ):
        if ok:
            out[j] = Ellipse((cx, cy), (a, b), angle)
    return out


def _check_iteration_args(max_iter: int, tol: float) -> None:
    if int(max_iter) != max_iter or max_iter < 0:
        raise ValueError(f"max_iter must be an integer >= 0, got {max_iter!r}")
    if not (tol > 0 and math.isfinite(tol)):
        raise ValueError(f"tol must be a finite number > 0, got {tol!r}")


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
    if not (a > 0 and b > 0):
        raise ValueError(f"semi-axes must be > 0, got a={a!r}, b={b!r}")
    u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    cu, cv = np.empty(u.shape), np.empty(u.shape)
    _fits().contact_points(
        np.ascontiguousarray(u).ravel(),
        np.ascontiguousarray(v).ravel(),
        float(a),
        float(b),
        cu.reshape(-1),
        cv.reshape(-1),
    )
    return cu, cv


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
        current = Ellipse.normalised(*_conic_to_params(conics[best]).tolist())
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
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    out = np.empty(len(pts))
    _fits().orthogonal_distances(
        pts, *ellipse.center, *ellipse.axes, math.radians(ellipse.angle), out
    )
    return out


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
