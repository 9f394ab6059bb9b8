"""The Table 1 descriptors and the exact polar series (eq. 4) in plain numpy: the reference.

The definitions and the choices made are documented in :mod:`labauto.vision.descriptors` and
:mod:`labauto.vision.harmonics`; this module writes them out with numpy, one contour after the
other, vectorised over its vertices and edges. Its functions take and return what the compiled
kernel :mod:`labauto.vision.kernels.shape` does (without its thread count), so those modules
call either; the results agree to rounding (the kernel sums in a different order).
"""

from __future__ import annotations

import math

import numpy as np

# descriptor status (per contour)
OK, TOO_FEW_POINTS, NON_FINITE, ONE_POINT, NEGATIVE_MOMENTS = 0, 1, 2, 3, 4
# series status (per contour)
SERIES_OK, SERIES_SKIPPED, SERIES_NO_AREA, SERIES_BAD_CENTRE, SERIES_NO_WINDING = 0, 1, 2, 3, 4

#: Columns of the (K, 14) value array of :func:`measure_contours`.
VALUE_NAMES = (
    "area", "centroid_x", "centroid_y", "semi_major", "semi_minor", "perimeter", "closing",
    "convex_perimeter", "elongation", "rectangularity", "centre_x", "centre_y",
    "star_shapedness", "winding",
)  # fmt: skip

NO_AREA_COMPACTNESS = 1e-9  # below it a polygon has no area (a traced line)


def dedup(points: np.ndarray, closed: bool) -> np.ndarray:
    """Points unequal to their predecessor (if closed, without a last one equal to the first)."""
    if len(points) == 0:
        return points
    keep = np.ones(len(points), bool)
    keep[1:] = np.any(points[1:] != points[:-1], axis=1)
    out = points[keep]
    if closed and len(out) > 1 and np.all(out[0] == out[-1]):
        out = out[:-1]
    return out


def signed_area_centroid(q: np.ndarray) -> tuple[float, np.ndarray]:
    """Signed area and area centroid of the polygon ``q`` (implicitly closed), summed about the
    vertex mean; the mean when the area is zero."""
    mean = q.mean(axis=0)
    p = q - mean
    nxt = np.roll(p, -1, axis=0)
    cross = p[:, 0] * nxt[:, 1] - nxt[:, 0] * p[:, 1]
    area = 0.5 * float(cross.sum())
    if area == 0.0:
        return area, mean
    return area, mean + ((p + nxt) * cross[:, None]).sum(axis=0) / (6.0 * area)


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (Andrew's monotone chain), counter-clockwise in (x, y) axes, without
    collinear vertices; collinear points give their two ends, a single point one vertex."""
    if points.shape[0] < 1 or points.shape[1:] != (2,):
        raise ValueError("convex_hull needs (n, 2) points, n >= 1")
    order = np.lexsort((points[:, 1], points[:, 0]))
    pts = [tuple(p) for p in points[order].tolist()]

    def chain(sequence: list) -> list:
        stack: list = []
        for p in sequence:
            while (
                len(stack) >= 2
                and (
                    (stack[-1][0] - stack[-2][0]) * (p[1] - stack[-2][1])
                    - (stack[-1][1] - stack[-2][1]) * (p[0] - stack[-2][0])
                )
                <= 0.0
            ):
                stack.pop()
            stack.append(p)
        return stack

    lower, upper = chain(pts), chain(pts[::-1])
    hull = lower[:-1] + upper[:-1]
    if not hull:
        hull = pts[:1]
    if len(hull) == 2 and hull[0] == hull[1]:
        hull = hull[:1]
    return np.array(hull, dtype=np.float64).reshape(-1, 2)


def _box(hull: np.ndarray) -> tuple[float, float, float]:
    """Long and short side of the minimum-area box around the convex polygon ``hull``
    (rotating calipers: one side on each hull edge; of equal areas to 1e-12 the least
    elongated box) and the polygon's perimeter."""
    m = len(hull)
    edges = np.roll(hull, -1, axis=0) - hull
    lengths = np.hypot(edges[:, 0], edges[:, 1])
    if m < 3:  # a point (perimeter 0) or a segment (twice its length)
        return (float(lengths[0]) if m == 2 else 0.0), 0.0, float(lengths.sum())
    u = edges / lengths[:, None]
    rel = hull[None, :, :] - hull[:, None, :]  # vertex j about edge i's start
    along = rel[..., 0] * u[:, None, 0] + rel[..., 1] * u[:, None, 1]
    across = rel[..., 0] * -u[:, None, 1] + rel[..., 1] * u[:, None, 0]
    width, extent = across.max(axis=1), along.max(axis=1) - along.min(axis=1)
    area = width * extent
    long_sides, short_sides = np.maximum(width, extent), np.minimum(width, extent)
    best, side = math.inf, (0.0, 0.0)
    for i in range(m):
        a, long_side, short_side = area[i], long_sides[i], short_sides[i]
        if a < best * (1.0 - 1e-12) or (
            a <= best * (1.0 + 1e-12) and long_side * side[1] < side[0] * short_side
        ):
            best = min(a, best)
            side = (float(long_side), float(short_side))
    return side[0], side[1], float(lengths.sum())


def min_area_box(points: np.ndarray) -> tuple[float, float]:
    """(long, short) sides of the minimum-area rectangle around n >= 1 points."""
    long_side, short_side, _ = _box(convex_hull(points))
    return long_side, short_side


def _descriptors(q: np.ndarray, out: np.ndarray) -> int:
    """Descriptors of the polygon ``q`` (n >= 2 points, no repeats) into out[0:10]; status."""
    nxt = np.roll(q, -1, axis=0)
    seg = np.hypot(*(nxt - q).T)
    total = float(seg.sum())
    out[5], out[6] = total, seg[-1]  # perimeter and its closing segment (last point to first)
    signed, centroid = signed_area_centroid(q)
    area = abs(signed)
    has_area = 4.0 * math.pi * area > NO_AREA_COMPACTNESS * total * total
    if not has_area:  # a traced line: the centroid of the curve with uniform mass per length
        area = 0.0
        centroid = 0.5 * ((q + nxt) * seg[:, None]).sum(axis=0) / total
    out[0], out[1], out[2] = area, centroid[0], centroid[1]
    # second moments about the centroid: of the filled polygon, or of the curve without area
    p, r = q - centroid, nxt - centroid
    px, py, qx, qy = p[:, 0], p[:, 1], r[:, 0], r[:, 1]
    w = px * qy - qx * py if has_area else seg / total
    sxx = float((w * (px * px + px * qx + qx * qx)).sum())
    syy = float((w * (py * py + py * qy + qy * qy)).sum())
    sxy = float((w * (2.0 * px * py + px * qy + qx * py + 2.0 * qx * qy)).sum())
    if has_area:
        twice = float(w.sum())
        sxx, syy, sxy, scale = sxx / (6 * twice), syy / (6 * twice), sxy / (12 * twice), 4.0
    else:
        sxx, syy, sxy, scale = sxx / 3.0, syy / 3.0, sxy / 6.0, 3.0
    half_trace = 0.5 * (sxx + syy)
    root = math.hypot(0.5 * (sxx - syy), sxy)
    major2 = scale * (half_trace + root)
    out[3] = math.sqrt(major2) if major2 >= 0.0 else math.nan
    out[4] = math.sqrt(scale * (half_trace - root)) if half_trace - root > 0.0 else 0.0
    long_side, short_side, out[7] = _box(convex_hull(q))
    if short_side > 1e-12 * long_side:
        box_area, out[8] = long_side * short_side, long_side / short_side
    else:
        box_area, out[8] = 0.0, math.inf
    out[9] = (area / box_area if area < box_area else 1.0) if box_area > 0.0 else 0.0
    return OK if major2 >= 0.0 else NEGATIVE_MOMENTS


def _series(
    q: np.ndarray, centre: np.ndarray | None, n_r: int, n_rho: int,
    r: np.ndarray, rho: np.ndarray, out: np.ndarray,
) -> int:  # fmt: skip
    """Coefficients of ``r`` (harmonics 0..n_r) and ``r^-2`` (0..n_rho) about the centre, exact
    per edge (see :mod:`labauto.vision.harmonics`), into r, rho; centre, star-shapedness and
    winding into out[10:14]; the series status.

    Per edge at distance d from the centre, foot point in direction phi (``nu = e^{i phi}``),
    ``u = theta - phi`` from u0 to u1: with ``w = e^{i theta}`` at the vertices,
    ``D_m = (w1^m - w0^m) / (i m)`` (``D_0 = du``), ``Q_0 = K_0 = asinh tan u1 - asinh tan u0``,
    ``Q_1 = nu (du + i log(r1 / r0))``, ``Q_{m+1} = 2 nu D_m - nu^2 Q_{m-1}``; ``r`` gathers
    ``d Q_n``, ``r^-2`` gathers ``h D_n + conj(a) D_{n+2} + a D_{n-2}`` with ``h = 1 / (2
    d^2)``, ``a = nu^2 / (4 d^2)``. Edges on a line through the centre add nothing.
    """
    if centre is None:
        if len(q) == 0:
            return SERIES_NO_AREA
        signed, centre = signed_area_centroid(q)
        if signed == 0.0:
            return SERIES_NO_AREA
    elif not np.all(np.isfinite(centre)):
        return SERIES_BAD_CENTRE
    out[10], out[11] = centre
    if len(q) == 0:
        return _no_winding(r, rho, out, 0.0, 0.0)
    g = np.vstack((q, q[:1])) - centre  # the vertices about the centre, vertex 0 again
    r2 = (g * g).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_r = 1.0 / np.sqrt(r2)
        w = np.where(r2 > 0, (g[:, 0] + 1j * g[:, 1]) * inv_r, 0)
        thresh = 1e-12 * math.sqrt(float(r2.max()))
        e = g[1:] - g[:-1]
        normal = np.column_stack((e[:, 1], -e[:, 0])) / np.hypot(e[:, 0], e[:, 1])[:, None]
        d = (g[:-1] * normal).sum(axis=1)
        normal[d < 0] *= -1.0  # nu points from the centre to the edge
        d = np.abs(d)
        ok = d > thresh
        nu = normal[:, 0] + 1j * normal[:, 1]
        # cos and sin of u at both ends of every edge, the angle du it subtends
        cos_u = d[:, None] * np.column_stack((inv_r[:-1], inv_r[1:]))
        ends = np.stack((g[:-1], g[1:]), axis=1)
        sin_u = (ends[..., 1] * normal[:, None, 0] - ends[..., 0] * normal[:, None, 1]) * (
            np.column_stack((inv_r[:-1], inv_r[1:]))
        )
        (c0, c1), (s0, s1) = cos_u.T, sin_u.T
        du = np.where(ok, np.arctan2(s1 * c0 - c1 * s0, c1 * c0 + s1 * s0), 0.0)
        h = np.where(ok, 0.5 / (d * d), 0.0)
        a = np.where(ok, 0.5 * h * nu * nu, 0.0)
        if n_r >= 0:
            # K_0 = log(e1 / e0), e = (1 + sin u) / cos u, or cos u / (1 - sin u) for sin u < 0
            a0, b0 = np.where(s0 >= 0, 1 + s0, c0), np.where(s0 >= 0, c0, 1 - s0)
            a1, b1 = np.where(s1 >= 0, 1 + s1, c1), np.where(s1 >= 0, c1, 1 - s1)
            k0 = np.log((a1 * b0) / (b1 * a0))
            log_r = -np.log(inv_r)
            q_prev, q_cur = k0.astype(np.complex128), nu * (du + 1j * (log_r[1:] - log_r[:-1]))
            coefficients = [np.sum(np.where(ok, d * q_prev, 0)), np.sum(np.where(ok, d * q_cur, 0))]

        def power_change(m: int) -> np.ndarray:
            """D_m of every edge (D_0 = du; D_-m = conj(D_m) for unit w)."""
            if m == 0:
                return du.astype(np.complex128)
            change = (w[1:] ** abs(m) - w[:-1] ** abs(m)) / (1j * abs(m))
            return np.where(ok, change if m > 0 else np.conj(change), 0)

        big_m = max(n_r - 1, n_rho + 2)
        changes = {m: power_change(m) for m in range(-2, big_m + 1)}
        for m in range(1, n_r):
            q_prev, q_cur = q_cur, 2.0 * nu * changes[m] - nu * nu * q_prev
            coefficients.append(np.sum(np.where(ok, d * q_cur, 0)))
    net, total = float(du.sum()), float(np.abs(du).sum())
    winding = float(np.rint(net / (2.0 * math.pi)))
    out[12] = abs(net) / total if total > 0.0 else 0.0
    out[13] = winding
    if winding == 0.0:
        return _no_winding(r, rho, out, out[12], winding)
    norm = 1.0 / (math.pi * winding)
    if n_r >= 0:
        r[:] = np.array(coefficients[: n_r + 1]) * norm
        r[0] = r[0].real
    for k in range(n_rho + 1):
        terms = h * changes[k] + np.conj(a) * changes[k + 2] + a * changes[k - 2]
        rho[k] = terms.sum() * norm
    if n_rho >= 0:
        rho[0] = rho[0].real
    return SERIES_OK


def _no_winding(r: np.ndarray, rho: np.ndarray, out: np.ndarray, star: float, winding: float):
    out[12], out[13] = star, winding
    r[:] = np.nan
    rho[:] = np.nan
    return SERIES_NO_WINDING


def measure_contours(
    points: np.ndarray, offsets: np.ndarray, min_points: int, want_series: np.ndarray,
    centres: np.ndarray, given_centres: bool, max_elongation: float, n_r: int, n_rho: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Descriptors (and polar series) of K concatenated contours: status, series status,
    values (K, 14) (columns ``VALUE_NAMES``), r (K, n_r + 1), rho (K, n_rho + 1) complex; as
    the compiled kernel's ``measure_contours``."""
    k_total = len(offsets) - 1
    if k_total < 0 or offsets[0] != 0 or offsets[-1] != len(points):
        raise ValueError("measure_contours needs (N, 2) points, offsets from 0 to N and K rows")
    if np.any(np.diff(offsets) < 0):
        raise ValueError("measure_contours: offsets must not decrease")
    n_r, n_rho = max(n_r, -1), max(n_rho, -1)
    status = np.empty(k_total, np.int8)
    series = np.full(k_total, SERIES_SKIPPED, np.int8)
    values = np.full((k_total, len(VALUE_NAMES)), np.nan)
    r = np.full((k_total, n_r + 1), np.nan, np.complex128)
    rho = np.full((k_total, n_rho + 1), np.nan, np.complex128)
    for k in range(k_total):
        raw = points[offsets[k] : offsets[k + 1]]
        if len(raw) < min_points:
            status[k] = TOO_FEW_POINTS
            continue
        if not np.all(np.isfinite(raw)):
            status[k] = NON_FINITE
            continue
        q = dedup(raw, closed=True)
        status[k] = ONE_POINT if len(q) < 2 else _descriptors(q, values[k])
        if status[k] != OK:
            values[k] = np.nan
        line = math.isfinite(max_elongation) and values[k, 8] >= max_elongation
        if want_series[k] and max(n_r, n_rho) >= 0 and not line:
            centre = centres[k] if given_centres else None
            series[k] = _series(q, centre, n_r, n_rho, r[k], rho[k], values[k])
    return status, series, values, r, rho


def drop_repeated(
    points: np.ndarray, offsets: np.ndarray, closed: bool
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`dedup` of K concatenated contours: (points (M, 2), offsets (K + 1,))."""
    if offsets[0] != 0 or offsets[-1] != len(points):
        raise ValueError("drop_repeated needs (N, 2) points and offsets from 0 to N")
    kept = [dedup(points[offsets[k] : offsets[k + 1]], closed) for k in range(len(offsets) - 1)]
    counts = np.array([len(c) for c in kept], np.int64)
    out = np.concatenate(kept) if kept else np.empty((0, 2))
    return out.reshape(-1, 2), np.concatenate(([0], np.cumsum(counts))).astype(np.int64)


def area_centroids(points: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Absolute area and area centroid (the vertex mean without area) of K polygons."""
    if offsets[0] != 0 or offsets[-1] != len(points):
        raise ValueError("area_centroids needs (N, 2) points and offsets from 0 to N")
    if np.any(np.diff(offsets) < 1):
        raise ValueError("area_centroids: every polygon needs a vertex")
    k_total = len(offsets) - 1
    area, centroid = np.empty(k_total), np.empty((k_total, 2))
    for k in range(k_total):
        signed, centroid[k] = signed_area_centroid(points[offsets[k] : offsets[k + 1]])
        area[k] = abs(signed)
    return area, centroid
