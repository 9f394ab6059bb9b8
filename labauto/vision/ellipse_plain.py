"""The ellipse fits of :mod:`labauto.vision.ellipse_fit` in plain numpy: the reference path.

The method (Halir-Flusser's direct fit, Eberly's contact-point root, Ahn's Jacobian, the
Levenberg-Marquardt damping and stopping rules) is documented in
:mod:`labauto.vision.ellipse_fit`; this module writes it out with numpy, vectorised over the
points of a contour, one contour after the other. Its functions take and fill the same arrays
as the compiled kernel :mod:`labauto.vision.kernels.ellipse_fit` (without its thread count), so
:mod:`labauto.vision.ellipse_fit` calls either; the results agree to rounding.

Parameter rows are ``(cx, cy, a, b, angle_deg)``. Status codes: 0 ok, 1 fewer than 5 points,
2 degenerate points, 3 the best conic is not an ellipse, 4 a bad initial row.
"""

from __future__ import annotations

import math

import numpy as np

OK, TOO_FEW, DEGENERATE, NOT_ELLIPSE, BAD_INITIAL = 0, 1, 2, 3, 4
MAX_NEWTON = 60  # contact-point Newton steps at most (2-4 are typical)


# ------------------------------------------------------------------------ contact points


def contact_roots(
    u: np.ndarray, v: np.ndarray, a: float, b: float, guess: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthogonal contact points on ``u^2/a^2 + v^2/b^2 = 1`` and the roots ``s`` (Eberly).

    In the first quadrant of the frame whose first axis is the major one, the contact point is
    ``(a^2 x / (s + a^2), b^2 y / (s + b^2))`` with ``s`` the root of ``F(s) = (a x / (s +
    a^2))^2 + (b y / (s + b^2))^2 - 1``, found by Newton from the left (from the safe start
    ``max(b y - b^2, a x - a^2)``, the first-order guess or ``guess``); on the major axis inside
    the evolute the contact point has a closed form and ``s = -b^2``. Other quadrants follow by
    symmetry.
    """
    big, small = max(a, b), min(a, b)
    a2, b2 = big * big, small * small
    swap = a < b
    x, y = (np.abs(v), np.abs(u)) if swap else (np.abs(u), np.abs(v))
    inner = (y == 0) & (big * x <= a2 - b2)
    x_inner = x
    x = np.where(inner, big, x)
    ax, by = big * x, small * y

    def newton(s: np.ndarray, ax: np.ndarray = ax, by: np.ndarray = by) -> np.ndarray:
        ra, rb = ax / (s + a2), by / (s + b2)
        return (ra * ra + rb * rb - 1.0) / (2.0 * (ra * ra / (s + a2) + rb * rb / (s + b2)))

    with np.errstate(divide="ignore", invalid="ignore"):
        safe = np.maximum(by - b2, ax - a2)
        if guess is None:
            qx, qy = x / a2, y / b2
            den = qx * qx + qy * qy  # 0 only for a point next to the centre
            start = np.where(den > 0, 0.5 * (x * qx + y * qy - 1.0) / den, -np.inf)
        else:
            start = np.asarray(guess, dtype=np.float64)
        s = np.maximum(start, safe)
        s = np.maximum(s + newton(s), safe)
        active = np.ones(s.shape, bool)
        for _ in range(MAX_NEWTON):
            step = newton(s[active], ax[active], by[active])
            s[active] += step
            going = np.abs(step) > 1e-9 * (np.abs(s[active]) + b2)
            active[active] = going
            if not active.any():
                break
        cu = a2 * x / (s + a2)
        cv = b2 * y / (s + b2)
    inner_u = a2 * x_inner / (a2 - b2) if big > small else np.zeros_like(x_inner)
    inner_v = small * np.sqrt(np.clip(1.0 - (inner_u / big) ** 2, 0.0, 1.0))
    cu = np.where(inner, inner_u, cu)
    cv = np.where(inner, inner_v, cv)
    s = np.where(inner, -b2, s)
    if swap:
        cu, cv = cv, cu
    return np.copysign(cu, u), np.copysign(cv, v), s


def contact_points(
    u: np.ndarray, v: np.ndarray, a: float, b: float, cu: np.ndarray, cv: np.ndarray
) -> None:
    """Orthogonal contact points of ``(u, v)`` on ``u^2/a^2 + v^2/b^2 = 1`` into ``cu``, ``cv``."""
    if not (a > 0.0 and b > 0.0):
        raise ValueError("contact_points: semi-axes must be > 0")
    cu[:], cv[:], _ = contact_roots(np.asarray(u), np.asarray(v), a, b)


def _frame(points: np.ndarray, cx: float, cy: float, angle_rad: float) -> tuple:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    dx, dy = points[:, 0] - cx, points[:, 1] - cy
    return c * dx + s * dy, c * dy - s * dx, c, s


def orthogonal_distances(
    points: np.ndarray, cx: float, cy: float, a: float, b: float, angle_rad: float,
    out: np.ndarray,
) -> None:  # fmt: skip
    """Signed orthogonal distances (outside > 0) of ``points`` to one ellipse, into ``out``."""
    if not (a > 0.0 and b > 0.0):
        raise ValueError("orthogonal_distances: semi-axes must be > 0")
    u, v, _, _ = _frame(points, cx, cy, angle_rad)
    out[:] = _distances(u, v, a, b, None)[0]


def _distances(u: np.ndarray, v: np.ndarray, a: float, b: float, guess: np.ndarray | None):
    """Signed distances, the unit normals and contact points, and the roots."""
    cu, cv, roots = contact_roots(u, v, a, b, guess)
    nu, nv = cu / (a * a), cv / (b * b)
    norm = np.hypot(nu, nv)
    nu, nv = nu / norm, nv / norm
    return nu * (u - cu) + nv * (v - cv), nu, nv, cu, cv, roots


# ---------------------------------------------------------------------------- algebraic


def conics_to_params(conics: np.ndarray, out: np.ndarray, valid: np.ndarray) -> None:
    """Conic rows ``(A, B, C, D, E, F)`` -> rows ``(cx, cy, major, minor, angle_deg)``.

    ``valid`` (uint8) is 1 where the conic is a real ellipse; ``out`` is filled either way.
    """
    conics = np.asarray(conics, dtype=np.float64)
    sign = np.where(conics[:, 0] + conics[:, 2] < 0.0, -1.0, 1.0)
    qa, qb, qc, qd, qe, qf = (conics * sign[:, None]).T
    with np.errstate(divide="ignore", invalid="ignore"):
        den = qb * qb - 4.0 * qa * qc
        x0 = (2.0 * qc * qd - qb * qe) / den
        y0 = (2.0 * qa * qe - qb * qd) / den
        f0 = qf + 0.5 * (qd * x0 + qe * y0)
        half_sum = 0.5 * (qa + qc)
        root = np.hypot(0.5 * (qa - qc), 0.5 * qb)
        small, large = half_sum - root, half_sum + root
        major, minor = np.sqrt(-f0 / small), np.sqrt(-f0 / large)
    out[:, 0], out[:, 1], out[:, 2], out[:, 3] = x0, y0, major, minor
    out[:, 4] = np.mod(np.degrees(0.5 * np.arctan2(qb, qa - qc)) + 90.0, 180.0)
    valid[:] = (den < 0) & (small > 0) & (f0 < 0) & np.isfinite(major) & np.isfinite(minor)


def algebraic(pts: np.ndarray) -> tuple[int, np.ndarray]:
    """Halir-Flusser direct fit of one contour: (status, row)."""
    row = np.full(5, np.nan)
    if len(pts) < 5:
        return TOO_FEW, row
    mean = pts.mean(axis=0)
    centred = pts - mean
    scale = math.sqrt(float((centred**2).sum()) / (2 * len(pts))) or 1.0
    x, y = centred[:, 0] / scale, centred[:, 1] / scale
    d1 = np.column_stack((x * x, x * y, y * y))
    d2 = np.column_stack((x, y, np.ones_like(x)))
    s1, s2, s3 = d1.T @ d1, d1.T @ d2, d2.T @ d2
    low, high = np.linalg.eigvalsh(s3)[[0, -1]]
    if low <= 1e-10 * high:  # collinear points, or fewer than 3 distinct ones
        return DEGENERATE, row
    t = -np.linalg.solve(s3, s2.T)
    m = s1 + s2 @ t
    reduced = np.array([m[2] / 2, -m[1], m[0] / 2])  # C1^-1 M
    if not np.isfinite(reduced).all():
        return DEGENERATE, row
    values, vectors = np.linalg.eig(reduced)
    vectors = vectors[:, np.abs(values.imag) == 0].real
    condition = 4 * vectors[0] * vectors[2] - vectors[1] ** 2
    if vectors.shape[1] == 0 or condition.max() <= 0:
        return NOT_ELLIPSE, row
    a1 = vectors[:, np.argmax(condition)]
    valid = np.zeros(1, np.uint8)
    conics_to_params(np.concatenate((a1, t @ a1))[None], row[None], valid)
    if not valid[0]:
        return NOT_ELLIPSE, row
    row[:2] = mean + scale * row[:2]
    row[2:4] *= scale
    return OK, row


# ---------------------------------------------------------------------------- geometric


def geometric(
    pts: np.ndarray, row: np.ndarray, max_iter: int, tol: float
) -> tuple[np.ndarray, float, int, bool]:
    """Levenberg-Marquardt on ``(xc, yc, a, b, angle)`` from ``row``: (row, rms, iterations,
    converged), the normal equations solved by numpy."""
    p = np.array([*row[:4], math.radians(row[4])])

    def evaluate(p: np.ndarray, guess: np.ndarray | None) -> tuple:
        xc, yc, a, b, angle = p
        u, v, c, s = _frame(pts, xc, yc, angle)
        d, nu, nv, fu, fv, roots = _distances(u, v, a, b, guess)
        jac = np.column_stack(
            (s * nv - c * nu, -(s * nu + c * nv), -nu * fu / a, -nv * fv / b, nu * fv - nv * fu)
        )
        return d, jac, roots

    d, jac, roots = evaluate(p, None)
    cost = float(d @ d)
    lam, iterations, converged, active = 0.0, 0, False, max_iter > 0
    while active:
        iterations += 1
        hess = jac.T @ jac
        diag = np.diag(hess).copy()
        hess[np.diag_indices(5)] += lam * diag + 1e-12 * diag.sum()
        step = -np.linalg.solve(hess, jac.T @ d)
        size = max(p[2], p[3], 1.0)
        step_px = math.sqrt(float(step[:4] @ step[:4]) + (size * step[4]) ** 2)
        trial = p + step
        cost_t = math.inf
        if np.isfinite(trial).all() and trial[2] > 0 and trial[3] > 0:
            d_t, jac_t, roots_t = evaluate(trial, roots)
            cost_t = float(d_t @ d_t)
        small_step = step_px <= tol * size
        accept = cost_t <= cost
        small_gain = accept and lam == 0 and cost - cost_t <= tol * cost
        if accept:
            p, cost, d, jac, roots = trial, cost_t, d_t, jac_t, roots_t
            lam = 0.0 if lam <= 1e-6 else lam / 10
        elif not small_step:
            lam = 1e-3 if lam == 0 else lam * 10
        done = (accept and (small_step or small_gain)) or (not accept and small_step)
        converged = converged or done
        active = not done and lam <= 1e12 and iterations < max_iter
    fitted = np.array([*p[:4], math.degrees(p[4])])
    return fitted, math.sqrt(cost / len(pts)), iterations, converged


def normalise(row: np.ndarray) -> None:
    """``Ellipse.normalised`` on a row in place: ``a >= b``, angle in [0, 180)."""
    a, b = abs(row[2]), abs(row[3])
    if b > a:
        row[2], row[3], row[4] = b, a, row[4] + 90.0
    else:
        row[2], row[3] = a, b
    row[4] = row[4] % 180.0


def fit_ellipses(
    points: np.ndarray, offsets: np.ndarray, index: np.ndarray, params: np.ndarray,
    status: np.ndarray, rms: np.ndarray, iterations: np.ndarray, converged: np.ndarray,
    seed: bool, max_iter: int, tol: float,
) -> None:  # fmt: skip
    """Algebraic seeds and/or geometric fits of the contours ``index``, in place.

    The arguments are those of the compiled kernel's ``fit_ellipses`` (see
    :func:`labauto.vision.ellipse_fit._run`): row j of the outputs is contour ``index[j]``;
    ``params`` holds the initial rows unless ``seed``; ``max_iter < 0``: no geometric fit.
    """
    if len(offsets) > 1 and (offsets[0] != 0 or offsets[-1] != len(points)):
        raise ValueError("fit_ellipses: offsets must run from 0 to len(points)")
    if np.any(np.diff(offsets) < 0):
        raise ValueError("fit_ellipses: offsets must not decrease")
    if len(index) and (index.min() < 0 or index.max() >= len(offsets) - 1):
        raise ValueError("fit_ellipses: index out of range of the contours")
    for j, c in enumerate(index.tolist()):
        pts = points[offsets[c] : offsets[c + 1]]
        if seed:
            status[j], params[j] = algebraic(pts)
        elif len(pts) < 5:
            status[j] = TOO_FEW
        else:
            good = np.isfinite(params[j]).all() and params[j, 2] > 0 and params[j, 3] > 0
            status[j] = OK if good else BAD_INITIAL
        if status[j] != OK:
            continue
        if max_iter >= 0:
            params[j], rms[j], iterations[j], converged[j] = geometric(
                pts, params[j], max_iter, tol
            )
        normalise(params[j])
