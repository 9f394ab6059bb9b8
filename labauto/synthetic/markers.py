"""Render coded markers (and plain circles and rings) with exact geometry under any projection.

A marker (:mod:`labauto.vision.marker_codes`) is a union of simple polygons in its own plane:
the centre circle and one annular sector per run of ink bits. Each polygon is sampled densely
enough (chord error below 1e-4 px in the image), its vertices are mapped into the image by a
plane-to-image map, and it is drawn by exact area coverage
(:func:`labauto.synthetic.shapes.coverage`). A plane homography maps straight lines to straight
lines, so the drawn image is exact to the sampling; with lens distortion the dense sampling
keeps it exact to well under 0.01 px. The true image of the marker's centre is
``to_image(center)``, which for a tilted marker differs from the centre of the ellipse drawn
(perspective bias).

Plane-to-image maps: :func:`homography_map` (a 3x3 homography) and :func:`camera_map` (a pinhole
camera with OpenCV's distortion model looking at the plane ``z = 0`` from pose ``rvec, tvec``).
Any callable taking (n, 2) plane points to (n, 2) pixels works.

Coordinates: pixels, origin at the centre of the top-left pixel, x right, y down.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import cv2
import numpy as np

from labauto.synthetic.shapes import coverage
from labauto.vision.marker_codes import N_BITS, RING_INNER, RING_OUTER, code_bits

#: Maps (n, 2) points of a plane to (n, 2) pixel positions.
PlaneToImage = Callable[[np.ndarray], np.ndarray]


def identity_map(points: np.ndarray) -> np.ndarray:
    """The plane is the image (units are pixels)."""
    return np.asarray(points, np.float64)


def homography_map(homography: np.ndarray) -> PlaneToImage:
    """A plane-to-image map by a 3x3 homography (plane points ``(x, y, 1)``)."""
    h = np.asarray(homography, np.float64).reshape(3, 3)

    def apply(points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, np.float64).reshape(-1, 2)
        q = p @ h[:, :2].T + h[:, 2]
        return q[:, :2] / q[:, 2:3]

    return apply


def camera_map(
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray | None,
    rvec: np.ndarray,
    tvec: np.ndarray,
) -> PlaneToImage:
    """A plane-to-image map by a camera (OpenCV model) seeing the plane ``z = 0``.

    Parameters
    ----------
    camera_matrix : np.ndarray
        3x3 intrinsics.
    dist_coeffs : np.ndarray or None
        OpenCV distortion coefficients (k1, k2, p1, p2[, k3, ...]).
    rvec, tvec : np.ndarray
        Pose of the plane in the camera frame (Rodrigues vector, translation).
    """
    k = np.asarray(camera_matrix, np.float64)
    d = np.zeros(5) if dist_coeffs is None else np.asarray(dist_coeffs, np.float64).ravel()
    r = np.asarray(rvec, np.float64).reshape(3, 1)
    t = np.asarray(tvec, np.float64).reshape(3, 1)

    def apply(points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, np.float64).reshape(-1, 2)
        obj = np.column_stack((p, np.zeros(len(p))))
        img, _ = cv2.projectPoints(obj, r, t, k, d)
        return img.reshape(-1, 2)

    return apply


def _arc(center: Sequence[float], radius: float, t0: float, t1: float, n: int) -> np.ndarray:
    t = np.linspace(t0, t1, max(int(n), 2))
    return np.column_stack((center[0] + radius * np.cos(t), center[1] + radius * np.sin(t)))


def _samples_per_turn(to_image: PlaneToImage, center: Sequence[float], radius: float) -> int:
    """Vertices per full turn so that the chord error in the image is below 1e-4 px."""
    probe = _arc(center, radius, 0.0, 2.0 * np.pi, 16)
    px = to_image(probe)
    mid = to_image(np.asarray([center], np.float64))
    r_px = float(np.max(np.hypot(*(px - mid).T)))
    return int(min(max(256, np.ceil(np.pi * np.sqrt(max(r_px, 1.0) / 2e-4))), 20000))


def disc_polygon(center: Sequence[float], radius: float, n: int) -> np.ndarray:
    """A circle of the plane as an ``n``-vertex polygon."""
    return _arc(center, radius, 0.0, 2.0 * np.pi * (1.0 - 1.0 / n), n)


def marker_polygons(
    marker_id: int, center: Sequence[float], radius: float, samples_per_turn: int = 2048
) -> list[np.ndarray]:
    """The ink of marker ``marker_id`` as simple polygons in its plane.

    Parameters
    ----------
    marker_id : int
        The marker's id (:func:`labauto.vision.marker_codes.code_bits`).
    center : (x, y)
        Centre of the marker in the plane.
    radius : float
        Radius of the centre circle in plane units; the code ring spans ``RING_INNER`` to
        ``RING_OUTER`` times it.
    samples_per_turn : int
        Vertices of a full circle (arcs get their share).

    Returns
    -------
    list of np.ndarray
        The centre circle first, then one annular sector per run of ink bits.
    """
    bits = code_bits(marker_id)
    polygons = [disc_polygon(center, radius, samples_per_turn)]
    step = 2.0 * np.pi / N_BITS
    start = int(np.flatnonzero(bits == 0)[0])  # codes always have paper bits
    k = 0
    while k < N_BITS:
        i = (start + k) % N_BITS
        if not bits[i]:
            k += 1
            continue
        run = 1
        while k + run < N_BITS and bits[(start + k + run) % N_BITS]:
            run += 1
        t0, t1 = i * step, (i + run) * step
        n = samples_per_turn * run // N_BITS + 2
        outer = _arc(center, RING_OUTER * radius, t0, t1, n)
        inner = _arc(center, RING_INNER * radius, t1, t0, n)
        polygons.append(np.vstack((outer, inner)))
        k += run
    return polygons


def fill_polygons(
    image: np.ndarray, polygons: Sequence[np.ndarray], color: float | Sequence[float]
) -> None:
    """Draw filled image-space polygons into a float image in place, by exact area coverage."""
    h, w = image.shape[:2]
    col = np.asarray(color, np.float64)
    for poly in polygons:
        cov, x0, y0 = coverage(poly, w, h)
        if cov.size == 0:
            continue
        region = image[y0 : y0 + cov.shape[0], x0 : x0 + cov.shape[1]]
        weight = cov if image.ndim == 2 else cov[..., None]
        region += weight * (col - region)


def draw_marker(
    image: np.ndarray,
    marker_id: int,
    center: Sequence[float],
    radius: float,
    *,
    to_image: PlaneToImage = identity_map,
    ink: float | Sequence[float] = 20.0,
) -> tuple[float, float]:
    """Draw marker ``marker_id`` into a float image (in place).

    Parameters
    ----------
    image : np.ndarray
        HxW or HxWx3 float image (the paper is what is already there).
    marker_id : int
        Which code.
    center, radius : (x, y), float
        Centre and centre-circle radius in the plane of ``to_image`` (pixels by default).
    to_image : PlaneToImage
        Plane-to-image map, e.g. :func:`homography_map` or :func:`camera_map`.
    ink : float or BGR
        Colour of the ink.

    Returns
    -------
    (x, y)
        The true image position of the marker's centre.
    """
    n = _samples_per_turn(to_image, center, RING_OUTER * radius)
    return _fill_plane(image, marker_polygons(marker_id, center, radius, n), to_image, ink, center)


def _fill_plane(
    image: np.ndarray,
    polygons: Sequence[np.ndarray],
    to_image: PlaneToImage,
    color: float | Sequence[float],
    center: Sequence[float],
) -> tuple[float, float]:
    """Fill plane polygons through ``to_image``; return the image of the plane point ``center``."""
    fill_polygons(image, [to_image(p) for p in polygons], color)
    cx, cy = to_image(np.asarray([center], np.float64))[0]
    return float(cx), float(cy)


def draw_disc(
    image: np.ndarray,
    center: Sequence[float],
    radius: float,
    *,
    to_image: PlaneToImage = identity_map,
    color: float | Sequence[float] = 20.0,
) -> tuple[float, float]:
    """Draw a filled circle of the plane (a circle-grid dot); returns its true image centre."""
    n = _samples_per_turn(to_image, center, radius)
    return _fill_plane(image, [disc_polygon(center, radius, n)], to_image, color, center)


def draw_ring(
    image: np.ndarray,
    center: Sequence[float],
    inner: float,
    outer: float,
    *,
    to_image: PlaneToImage = identity_map,
    color: float | Sequence[float] = 20.0,
) -> tuple[float, float]:
    """Draw an annulus of the plane (a ring-grid ring) as two half-annuli; returns its centre."""
    n = _samples_per_turn(to_image, center, outer)
    halves = [
        np.vstack(
            (
                _arc(center, outer, t0, t0 + np.pi, n // 2),
                _arc(center, inner, t0 + np.pi, t0, n // 2),
            )
        )
        for t0 in (0.0, np.pi)
    ]
    return _fill_plane(image, halves, to_image, color, center)


def finish(
    image: np.ndarray,
    *,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Blur (Gaussian), add noise and round a float render to ``uint8``."""
    out = np.asarray(image, np.float64)
    if blur_sigma > 0:
        out = cv2.GaussianBlur(out, (0, 0), blur_sigma)
    if noise_sigma > 0:
        if rng is None:
            raise ValueError("noise_sigma > 0 needs an rng")
        out = out + rng.normal(0.0, noise_sigma, out.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)
