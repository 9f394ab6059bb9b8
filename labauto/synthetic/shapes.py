"""Synthetic shapes with exact geometry, rendered anti-aliased at sub-pixel positions.

Every shape is one simple polygon (curved shapes are sampled densely enough that the chord error
is below 1e-4 px), so its area, centroid, boundary and normals are known exactly. Rendering
computes the area coverage of each pixel: exact along x (analytic overlap of the inside intervals
with the pixel) and supersampled along y (``supersample`` scan lines per pixel row, midpoint rule),
so edge positions are unbiased to well under 0.01 px.

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down; angles in
degrees from +x toward +y (the sense of ``cv2.ellipse``). Colours are grey levels (float) or BGR
triples on a 0-255 scale.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from labauto.vision.ellipse import Ellipse

Color = float | tuple[float, float, float]


@dataclass(frozen=True)
class Shape:
    """A filled shape bounded by one simple polygon.

    Attributes
    ----------
    kind : str
        ``"ellipse"``, ``"polygon"``, ``"star"``, ``"line"``, ``"crescent"`` or ``"des"``.
    vertices : np.ndarray
        (n, 2) float vertices ``(x, y)`` of the boundary polygon (not repeated at the end).
    params : dict
        The exact parameters the shape was built from (JSON-friendly).
    """

    kind: str
    vertices: np.ndarray = field(repr=False)
    params: dict

    @property
    def area(self) -> float:
        """Exact (polygon) area in square pixels."""
        x, y = self.vertices[:, 0], self.vertices[:, 1]
        return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) / 2.0)

    @property
    def centroid(self) -> tuple[float, float]:
        """Exact area centroid ``(x, y)`` of the filled polygon."""
        x, y = self.vertices[:, 0], self.vertices[:, 1]
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        cross = x * yn - xn * y
        a6 = 3.0 * cross.sum()
        return float(((x + xn) * cross).sum() / a6), float(((y + yn) * cross).sum() / a6)

    @property
    def ellipse(self) -> Ellipse | None:
        """The exact ellipse for ``kind == "ellipse"``, else None."""
        if self.kind != "ellipse":
            return None
        p = self.params
        return Ellipse.normalised(*p["center"], *p["axes"], p["angle"])

    def boundary_samples(self, spacing: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
        """Points uniformly spaced in arc length on the boundary, with their unit outward normals.

        Parameters
        ----------
        spacing : float
            Arc-length step in pixels.

        Returns
        -------
        points, normals : np.ndarray
            (m, 2) each. The normal of a point is the normal of the polygon edge it lies on.
        """
        v = self.vertices
        edges = np.roll(v, -1, axis=0) - v
        lengths = np.hypot(edges[:, 0], edges[:, 1])
        total = lengths.sum()
        s = np.arange(0.0, total, spacing) + spacing / 2.0
        cum = np.concatenate(([0.0], np.cumsum(lengths)))
        k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(v) - 1)
        t = (s - cum[k]) / lengths[k]
        points = v[k] + t[:, None] * edges[k]
        tangent = edges[k] / lengths[k][:, None]
        sign = 1.0 if _signed_area(v) > 0 else -1.0  # y-down: positive area = clockwise on screen
        normals = sign * np.column_stack((tangent[:, 1], -tangent[:, 0]))
        return points, normals

    def bbox(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the polygon."""
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def to_dict(self) -> dict:
        """``{"kind": ..., **params}`` (JSON-friendly)."""
        return {"kind": self.kind, **self.params}


def _signed_area(v: np.ndarray) -> float:
    x, y = v[:, 0], v[:, 1]
    return float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) / 2.0


def _n_curve_vertices(radius: float) -> int:
    # chord error r (1 - cos(pi/n)) ~ r pi^2 / (2 n^2) < 1e-4 px; normals within 0.1 degree
    return int(max(2048, np.ceil(np.pi * np.sqrt(max(radius, 1.0) / 2e-4))))


def _place(local: np.ndarray, center: Sequence[float], angle_deg: float) -> np.ndarray:
    t = np.deg2rad(angle_deg)
    c, s = np.cos(t), np.sin(t)
    x, y = local[:, 0], local[:, 1]
    return np.column_stack((center[0] + c * x - s * y, center[1] + s * x + c * y))


def _placed(
    kind: str, local: np.ndarray, center: Sequence[float], angle: float, params: dict
) -> Shape:
    """A ``kind`` shape of ``local`` vertices turned ``angle`` degrees and moved to ``center``.

    Its parameters are ``center`` (as floats) followed by ``params`` (the shape's own, in order).
    """
    return Shape(
        kind,
        _place(local, center, angle),
        {"center": [float(center[0]), float(center[1])], **params},
    )


def _polar(radius: np.ndarray, theta: np.ndarray) -> np.ndarray:
    return np.column_stack((radius * np.cos(theta), radius * np.sin(theta)))


def ellipse(center: Sequence[float], axes: Sequence[float], angle: float = 0.0) -> Shape:
    """Ellipse with semi-axes ``axes = (a, b)`` turned ``angle`` degrees."""
    a, b = float(axes[0]), float(axes[1])
    n = _n_curve_vertices(max(a, b))
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    local = np.column_stack((a * np.cos(t), b * np.sin(t)))
    return _placed("ellipse", local, center, angle, {"axes": [a, b], "angle": angle})


def regular_polygon(
    center: Sequence[float], radius: float, n_sides: int, angle: float = 0.0
) -> Shape:
    """Regular polygon with circumradius ``radius`` (a triangle for 3 sides, a square for 4)."""
    t = np.arange(n_sides) * 2.0 * np.pi / n_sides
    local = _polar(np.full(n_sides, float(radius)), t)
    params = {"radius": float(radius), "n_sides": int(n_sides), "angle": angle}
    return _placed("polygon", local, center, angle, params)


def rectangle(center: Sequence[float], width: float, height: float, angle: float = 0.0) -> Shape:
    """Rectangle ``width`` x ``height`` (full side lengths) turned ``angle`` degrees."""
    w, h = float(width) / 2.0, float(height) / 2.0
    local = np.array([[-w, -h], [w, -h], [w, h], [-w, h]])
    params = {"width": float(width), "height": float(height), "angle": angle}
    return _placed("polygon", local, center, angle, params)


def square(center: Sequence[float], side: float, angle: float = 0.0) -> Shape:
    """Square with side ``side`` turned ``angle`` degrees."""
    return rectangle(center, side, side, angle)


def triangle(center: Sequence[float], radius: float, angle: float = 0.0) -> Shape:
    """Equilateral triangle with circumradius ``radius``."""
    return regular_polygon(center, radius, 3, angle)


def star(
    center: Sequence[float],
    outer_radius: float,
    inner_radius: float,
    n_points: int = 5,
    angle: float = 0.0,
) -> Shape:
    """Star polygon with ``n_points`` tips at ``outer_radius`` and notches at ``inner_radius``."""
    k = np.arange(2 * n_points)
    r = np.where(k % 2 == 0, float(outer_radius), float(inner_radius))
    local = _polar(r, k * np.pi / n_points)
    params = {
        "outer_radius": float(outer_radius),
        "inner_radius": float(inner_radius),
        "n_points": int(n_points),
        "angle": angle,
    }
    return _placed("star", local, center, angle, params)


def line(p0: Sequence[float], p1: Sequence[float], width: float = 2.0) -> Shape:
    """Thick straight segment from ``p0`` to ``p1`` (a ``width`` wide rectangle, flat ends)."""
    p0a, p1a = np.asarray(p0, float), np.asarray(p1, float)
    d = p1a - p0a
    length = float(np.hypot(*d))
    center = (p0a + p1a) / 2.0
    angle = float(np.degrees(np.arctan2(d[1], d[0])))
    shape = rectangle(center, length, width, angle)
    params = {"p0": p0a.tolist(), "p1": p1a.tolist(), "width": float(width)}
    return Shape("line", shape.vertices, params)


def crescent(
    center: Sequence[float],
    radius: float,
    inner_radius: float,
    offset: float,
    angle: float = 0.0,
) -> Shape:
    """Disk of ``radius`` minus a disk of ``inner_radius`` shifted by ``offset`` along ``angle``.

    Requires ``radius - inner_radius < offset < radius + inner_radius`` (the circles cross).
    """
    r, q, d = float(radius), float(inner_radius), float(offset)
    if not (abs(r - q) < d < r + q):
        raise ValueError(
            f"crescent needs |radius - inner_radius| < offset < radius + inner_radius, got "
            f"radius={r}, inner_radius={q}, offset={d}"
        )
    # crossing points: angle phi on the outer circle, psi on the inner one (about its centre)
    phi = np.arccos((r * r + d * d - q * q) / (2.0 * r * d))
    psi = np.arccos((d * d + q * q - r * r) / (2.0 * d * q))
    n = _n_curve_vertices(r)
    outer = _polar(np.full(n, r), np.linspace(phi, 2.0 * np.pi - phi, n))
    inner_t = np.linspace(np.pi + psi, np.pi - psi, n)[1:-1]  # back inside, reverse direction
    inner = _polar(np.full(inner_t.size, q), inner_t) + np.array([d, 0.0])
    local = np.vstack((outer, inner))
    params = {"radius": r, "inner_radius": q, "offset": d, "angle": angle}
    return _placed("crescent", local, center, angle, params)


def deformed_ellipse(
    center: Sequence[float],
    axes: Sequence[float],
    angle: float = 0.0,
    harmonics: Sequence[tuple[int, float, float]] = ((3, 0.06, 0.0), (5, 0.03, 1.0)),
) -> Shape:
    """A DES: an ellipse whose radius is modulated by low-order harmonics.

    The boundary is ``r(t) = r_ellipse(t) * (1 + sum_k amp_k cos(k t + phase_k))`` for the
    polar angle t, with ``harmonics`` given as ``(k, amp_k, phase_k)`` tuples.
    """
    a, b = float(axes[0]), float(axes[1])
    n = _n_curve_vertices(max(a, b) * 2.0)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    r_ell = a * b / np.hypot(b * np.cos(t), a * np.sin(t))
    mod = np.ones_like(t)
    for k, amp, phase in harmonics:
        mod += amp * np.cos(k * t + phase)
    local = _polar(r_ell * mod, t)
    params = {
        "axes": [a, b],
        "angle": angle,
        "harmonics": [[int(k), float(amp), float(ph)] for k, amp, ph in harmonics],
    }
    return _placed("des", local, center, angle, params)


# ----------------------------------------------------------------------------------- rendering


def coverage(
    vertices: np.ndarray, width: int, height: int, supersample: int = 16
) -> tuple[np.ndarray, int, int]:
    """Area coverage of each pixel by the polygon, cropped to the polygon's bounding box.

    Parameters
    ----------
    vertices : np.ndarray
        (n, 2) polygon ``(x, y)`` (even-odd rule).
    width, height : int
        Image size; the crop is clipped to it.
    supersample : int
        Scan lines per pixel row.

    Returns
    -------
    cov, x0, y0
        ``cov`` is a float array in [0, 1] for the pixels ``[y0:y0+h, x0:x0+w]``.
    """
    lo = np.floor(vertices.min(axis=0) - 1).astype(int)
    hi = np.ceil(vertices.max(axis=0) + 1).astype(int)
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), width - 1), min(int(hi[1]), height - 1)
    w, h = x1 - x0 + 1, y1 - y0 + 1
    if w <= 0 or h <= 0:
        return np.zeros((0, 0)), x0, y0
    s = int(supersample)
    v0 = vertices
    v1 = np.roll(vertices, -1, axis=0)
    ya, yb = np.minimum(v0[:, 1], v1[:, 1]), np.maximum(v0[:, 1], v1[:, 1])
    # scan line r (0-based, local) sits at y = y0 - 0.5 + (r + 0.5) / s; it meets an edge when
    # ya <= y < yb (half-open, so a vertex is counted once)
    base = y0 - 0.5
    r_start = np.ceil((ya - base) * s - 0.5).astype(np.int64)
    r_end = np.ceil((yb - base) * s - 0.5).astype(np.int64)
    r_start = np.clip(r_start, 0, h * s)
    r_end = np.clip(r_end, 0, h * s)
    count = np.maximum(r_end - r_start, 0)
    edge = np.repeat(np.arange(len(v0)), count)
    first = np.repeat(r_start - np.concatenate(([0], np.cumsum(count)[:-1])), count)
    rows = first + np.arange(edge.size)
    y = base + (rows + 0.5) / s
    p, q = v0[edge], v1[edge]
    x = p[:, 0] + (y - p[:, 1]) * (q[:, 0] - p[:, 0]) / (q[:, 1] - p[:, 1])
    order = np.lexsort((x, rows))
    rows, x = rows[order], x[order]
    # even-odd: crossings pair up within each scan line
    if rows.size % 2 or np.any(rows[0::2] != rows[1::2]):
        raise ValueError("polygon is not closed or not simple")
    line_rows, ua, ub = rows[0::2], x[0::2] - x0 + 0.5, x[1::2] - x0 + 0.5
    ua, ub = np.clip(ua, 0, w), np.clip(ub, 0, w)
    keep = ub > ua
    pix_row, ua, ub = line_rows[keep] // s, ua[keep], ub[keep]
    ja, jb = np.floor(ua).astype(np.int64), np.floor(ub).astype(np.int64)
    stride = w + 2
    flat = np.zeros(h * stride)
    diff = np.zeros(h * stride)
    same = ja == jb
    np.add.at(flat, pix_row[same] * stride + ja[same], (ub - ua)[same])
    d = ~same
    rd = pix_row[d] * stride
    np.add.at(flat, rd + ja[d], ja[d] + 1 - ua[d])
    np.add.at(flat, rd + jb[d], ub[d] - jb[d])
    np.add.at(diff, rd + ja[d] + 1, 1.0)
    np.add.at(diff, rd + jb[d], -1.0)
    cov = flat.reshape(h, stride) + np.cumsum(diff.reshape(h, stride), axis=1)
    return cov[:, :w] / s, x0, y0


def _as_color(value: Color, channels: int) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(value, dtype=float))
    if channels == 1:
        if arr.size != 1:
            raise ValueError(f"a grey image needs a scalar colour, got {value!r}")
        return arr
    if arr.size == 1:
        return np.repeat(arr, 3)
    if arr.size != 3:
        raise ValueError(f"a colour must be a scalar or a BGR triple, got {value!r}")
    return arr


def _gap_weight(
    shape: Shape, x0: int, y0: int, h: int, w: int, fraction: float, start_deg: float
) -> np.ndarray:
    """Contrast weight in [0, 1] that removes ``fraction`` of the boundary.

    By polar angle about the centroid, the weight is 0 on the boundary over ``[start, start +
    360 * fraction)`` degrees and 1 beyond a 60-degree cosine ramp on either side. Toward the
    centre it rises linearly to 1 (at the centroid), reaching the full gap at 0.9 of the shortest
    centroid-boundary distance. Linear ramps have no gradient maximum, so at moderate contrast
    (<= ~100 grey levels for shapes of >= 30 px) the fade itself leaves no Canny edge.
    """
    cx, cy = shape.centroid
    yy, xx = np.mgrid[y0 : y0 + h, x0 : x0 + w].astype(float)
    theta = np.arctan2(yy - cy, xx - cx)
    span = 2.0 * np.pi * fraction
    rel = np.mod(theta - np.deg2rad(start_deg), 2.0 * np.pi)  # the gap is [0, span)
    ramp = np.deg2rad(60.0)
    outside = np.where(rel < span, 0.0, np.minimum(rel - span, 2.0 * np.pi - rel))
    g = np.where(outside >= ramp, 0.0, 0.5 * (1.0 + np.cos(np.pi * outside / ramp)))
    pts, _ = shape.boundary_samples(0.25)
    r_min = float(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy).min())
    radial = np.clip(np.hypot(xx - cx, yy - cy) / (0.9 * r_min), 0.0, 1.0)
    return 1.0 - g * radial


def render(
    shapes: Sequence[Shape],
    width: int,
    height: int,
    *,
    background: Color = 40.0,
    colors: list[Color] | Color = 200.0,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
    gap_fraction: float | Sequence[float] = 0.0,
    gap_start_deg: float | Sequence[float] = 0.0,
    supersample: int = 16,
    dtype: type = np.uint8,
) -> np.ndarray:
    """Render shapes over a uniform background, anti-aliased by exact area coverage.

    Parameters
    ----------
    shapes : sequence of Shape
        Drawn in order (later ones over earlier ones).
    width, height : int
        Image size.
    background : float or BGR triple
        Background grey level or colour; a scalar with a colour in ``colors`` gives a grey BGR.
    colors : colour or list of colours
        Fill of each shape: one colour (a scalar or a BGR tuple) for all, or a ``list`` with one
        colour per shape. A BGR triple anywhere makes the image HxWx3, else HxW.
    noise_sigma : float
        Standard deviation of additive Gaussian noise (grey levels), drawn from ``rng``.
    rng : numpy.random.Generator, optional
        Needed when ``noise_sigma > 0``.
    gap_fraction : float or sequence of float
        Fraction of each shape's boundary (by polar angle about its centroid) drawn with no
        contrast, fading in smoothly; 0 for none.
    gap_start_deg : float or sequence of float
        Polar angle (degrees, from +x toward +y) where each gap starts.
    supersample : int
        Scan lines per pixel row for the coverage.
    dtype : numpy dtype
        ``np.uint8`` (rounded and clipped) or a float type (unclipped).

    Returns
    -------
    np.ndarray
        HxW or HxWx3 image.
    """
    n = len(shapes)
    if isinstance(colors, list):
        if len(colors) != n:
            raise ValueError(f"colors has {len(colors)} entries for {n} shapes")
        color_list = colors
    else:
        color_list = [colors] * n
    channels = 3 if any(np.size(c) == 3 for c in [*color_list, background]) else 1
    gaps = np.broadcast_to(np.asarray(gap_fraction, float), (n,))
    starts = np.broadcast_to(np.asarray(gap_start_deg, float), (n,))
    img = np.empty((height, width, channels))
    img[:] = _as_color(background, channels)
    for shape, color, gap, start in zip(shapes, color_list, gaps, starts, strict=True):
        cov, x0, y0 = coverage(shape.vertices, width, height, supersample)
        if cov.size == 0:
            continue
        h, w = cov.shape
        if gap > 0:
            cov = cov * _gap_weight(shape, x0, y0, h, w, float(gap), float(start))
        region = img[y0 : y0 + h, x0 : x0 + w]
        region += cov[..., None] * (_as_color(color, channels) - region)
    if noise_sigma > 0:
        if rng is None:
            raise ValueError("noise_sigma > 0 needs an rng")
        img += rng.normal(0.0, noise_sigma, img.shape)
    if channels == 1:
        img = img[..., 0]
    if np.dtype(dtype) == np.uint8:
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return img.astype(dtype)


# ------------------------------------------------------------------------------------ scenes


def make_scene(
    rng: np.random.Generator,
    width: int = 1280,
    height: int = 1024,
    n_ellipses: int = 40,
    n_other: int = 90,
    noise: float = 4.0,
    min_contrast: float = 60.0,
) -> tuple[np.ndarray, list[dict]]:
    """A colour test scene: ellipses among rectangles, lines and blobs, on a coloured background.

    Shapes do not overlap (each keeps a margin of 6 px). Ellipses have semi-axes 8-30 px and
    axis ratios 1:1 to 1:3; the others are rectangles (with squares), thick lines, stars,
    triangles and crescents ("blobs"). Each shape is brighter or darker than the background by at
    least ``min_contrast`` grey levels in some channel.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of all randomness (the scene is a pure function of its state).
    width, height : int
        Image size.
    n_ellipses, n_other : int
        Numbers of elliptic and of other objects.
    noise : float
        Gaussian noise sigma (grey levels).
    min_contrast : float
        Smallest per-channel contrast of a shape against the background.

    Returns
    -------
    image, truth
        The uint8 BGR image and one dict per shape: ``{"kind", ...exact params...}``; ellipses
        also carry ``"ellipse": Ellipse.to_dict()``.
    """
    background = rng.uniform(70, 180, 3)
    placed: list[tuple[float, float, float]] = []
    shapes: list[Shape] = []

    def free_spot(radius: float) -> tuple[float, float] | None:
        for _ in range(200):
            cx = rng.uniform(radius + 4, width - radius - 4)
            cy = rng.uniform(radius + 4, height - radius - 4)
            if all(np.hypot(cx - px, cy - py) > radius + pr + 6 for px, py, pr in placed):
                placed.append((cx, cy, radius))
                return cx, cy
        return None

    kinds = ["ellipse"] * n_ellipses + list(
        rng.choice(["rectangle", "line", "star", "triangle", "crescent"], size=n_other)
    )
    for kind in kinds:
        angle = float(rng.uniform(0, 180))
        if kind == "ellipse":
            a = rng.uniform(8, 30)
            b = a / rng.uniform(1.0, 3.0)
            spot = free_spot(a)
            if spot:
                shapes.append(ellipse(spot, (a, max(b, 5.0)), angle))
        elif kind == "rectangle":
            w, h = rng.uniform(12, 60), rng.uniform(12, 60)
            spot = free_spot(np.hypot(w, h) / 2)
            if spot:
                shapes.append(rectangle(spot, w, h, angle))
        elif kind == "line":
            length, thick = rng.uniform(30, 120), rng.uniform(2, 5)
            spot = free_spot(length / 2)
            if spot:
                d = np.array([np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))]) * length / 2
                shapes.append(line(np.array(spot) - d, np.array(spot) + d, thick))
        elif kind == "star":
            r = rng.uniform(12, 30)
            spot = free_spot(r)
            if spot:
                n_pts = int(rng.integers(4, 8))
                shapes.append(star(spot, r, r * rng.uniform(0.35, 0.6), n_pts, angle))
        elif kind == "triangle":
            r = rng.uniform(10, 30)
            spot = free_spot(r)
            if spot:
                shapes.append(triangle(spot, r, angle))
        else:
            r = rng.uniform(12, 30)
            spot = free_spot(r)
            if spot:
                shapes.append(crescent(spot, r, r * 0.8, r * 0.55, angle))
    colors = []
    for _ in shapes:
        sign = rng.choice([-1.0, 1.0], size=3)
        delta = sign * rng.uniform(0, 90, 3)
        k = int(rng.integers(3))
        delta[k] = sign[k] * rng.uniform(min_contrast, 110)
        colors.append(tuple(np.clip(background + delta, 0, 255)))
    image = render(
        shapes,
        width,
        height,
        background=tuple(background),
        colors=colors,
        noise_sigma=noise,
        rng=rng,
        supersample=4,
    )
    truth = []
    for shape in shapes:
        d = shape.to_dict()
        if shape.kind == "ellipse":
            d["ellipse"] = shape.ellipse.to_dict()
        truth.append(d)
    return image, truth
