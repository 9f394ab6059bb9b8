"""Test scenes of the paper's marker experiment: coded markers among rectangles and artefacts.

Section 4.2: "40 different and elliptical distorted markers among more than 130 objects (40
markers, 40 rectangles and artefacts)". :func:`marker_scene` renders that on paper-coloured
ground: each marker on its own tilted plane (tilt up to ``max_tilt_deg``, seen by a pinhole
camera of focal ``focal_px``, so it is perspectively distorted, not just an ellipse), rectangles,
and artefacts (plain dots, which are DES but have no code, triangles, stars, lines, crescents),
then uneven light (a smooth gain field), a Gaussian blur and noise. The truth of each marker is
its id and the exact image of its centre (not the centre of its ellipse).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.synthetic import shapes
from labauto.synthetic.grey_look import GreyLook
from labauto.synthetic.markers import draw_marker, fill_polygons, homography_map
from labauto.vision.marker_codes import QUIET_RADIUS, n_codes

#: Draws a marker of some id under a homography into a float image; returns its true centre.
Painter = Callable[[np.ndarray, int, np.ndarray, float], tuple[float, float]]


@dataclass(frozen=True)
class SceneMarker:
    """A marker drawn into a scene: id, true image centre, centre radius (px, before tilt)."""

    id: int
    center: tuple[float, float]
    radius_px: float
    tilt_deg: float
    homography: np.ndarray


def tilted_plane(
    center_px: tuple[float, float],
    scale_px: float,
    tilt_deg: float,
    tilt_axis_deg: float,
    spin_deg: float,
    focal_px: float = 1500.0,
    principal: tuple[float, float] = (640.0, 512.0),
) -> np.ndarray:
    """Homography of a plane seen by a pinhole camera, one plane unit ``scale_px`` px at its centre.

    The plane's origin projects to ``center_px``; the plane is turned ``spin_deg`` about its
    normal, then tilted ``tilt_deg`` about an in-plane axis at ``tilt_axis_deg``, the tilt being
    the angle between the plane's normal and the line of sight (not the optical axis).
    """
    k = np.array([[focal_px, 0, principal[0]], [0, focal_px, principal[1]], [0, 0, 1.0]])
    depth = 1000.0
    ray = np.linalg.solve(k, [center_px[0], center_px[1], 1.0])
    t = ray / ray[2] * depth
    axis = np.deg2rad(tilt_axis_deg)
    tilt, _ = cv2.Rodrigues(np.array([np.cos(axis), np.sin(axis), 0.0]) * np.deg2rad(tilt_deg))
    spin, _ = cv2.Rodrigues(np.array([0.0, 0.0, np.deg2rad(spin_deg)]))
    r = _facing(t) @ tilt @ spin
    unit = depth / focal_px * scale_px  # plane units per px at that depth, times the scale
    h = k @ np.column_stack((r[:, 0] * unit, r[:, 1] * unit, t))
    return h / h[2, 2]


def _facing(direction: np.ndarray) -> np.ndarray:
    """A rotation taking the camera's +z onto ``direction`` (the line of sight)."""
    d = direction / np.linalg.norm(direction)
    axis = np.cross([0.0, 0.0, 1.0], d)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.eye(3)
    rot, _ = cv2.Rodrigues(axis / s * np.arctan2(s, d[2]))
    return rot


def _free(boxes: list[tuple[float, float, float]], x: float, y: float, r: float) -> bool:
    return all((x - bx) ** 2 + (y - by) ** 2 > (r + br) ** 2 for bx, by, br in boxes)


def _artefact(rng: np.random.Generator, x: float, y: float, size: float) -> shapes.Shape:
    kind = rng.integers(5)
    angle = float(rng.uniform(0, 180))
    if kind == 0:
        return shapes.ellipse((x, y), (size * 0.5, size * 0.5), 0.0)  # a plain dot: DES, no code
    if kind == 1:
        return shapes.triangle((x, y), size * 0.6, angle)
    if kind == 2:
        return shapes.star((x, y), size * 0.6, size * 0.3, 5, angle)
    if kind == 3:
        d = np.array([np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))]) * size * 0.8
        return shapes.line((x - d[0], y - d[1]), (x + d[0], y + d[1]), float(rng.uniform(2, 5)))
    return shapes.crescent((x, y), size * 0.6, size * 0.45, size * 0.25, angle)


def marker_scene(
    rng: np.random.Generator,
    width: int = 1280,
    height: int = 1024,
    *,
    n_markers: int = 40,
    n_rectangles: int = 40,
    n_artefacts: int = 50,
    radius_px: tuple[float, float] = (10.0, 14.0),
    max_tilt_deg: float = 60.0,
    paper: float = 210.0,
    ink: float = 30.0,
    blur_sigma: float = 1.0,
    noise_sigma: float = 2.0,
    light_gain: tuple[float, float] = (0.7, 1.0),
    painter: Painter | None = None,
) -> tuple[np.ndarray, list[SceneMarker]]:
    """Render one scene; returns the uint8 grey image and the markers' truth.

    Markers get distinct random ids; rectangles and artefacts are placed where no marker's quiet
    zone is. ``light_gain`` spans the smooth illumination field (a tilted plane plus a bump).
    ``painter(image, id, homography, ink)`` draws another kind of marker in the same place (the
    plane's unit is one centre radius, the marker spanning +-3.6 units) and returns its true
    centre, e.g. an ArUco marker for a benchmark; by default our coded marker is drawn.
    """
    look = GreyLook(paper, ink, blur_sigma, noise_sigma)
    img = look.canvas((width, height))
    placed: list[tuple[float, float, float]] = []
    truth: list[SceneMarker] = []
    ids = rng.choice(n_codes(), size=n_markers, replace=False)
    for marker_id in ids:
        r = float(rng.uniform(*radius_px))
        reach = QUIET_RADIUS * r * 1.25 + 4
        for _ in range(500):
            x, y = rng.uniform(reach, width - reach), rng.uniform(reach, height - reach)
            if _free(placed, x, y, reach):
                break
        else:
            raise ValueError("scene too crowded for the markers")
        tilt = float(rng.uniform(0.0, max_tilt_deg))
        hom = tilted_plane((x, y), r, tilt, rng.uniform(0, 180), rng.uniform(0, 360))
        if painter is None:
            center = draw_marker(
                img, int(marker_id), (0.0, 0.0), 1.0, to_image=homography_map(hom), ink=ink
            )
        else:
            center = painter(img, int(marker_id), hom, ink)
        placed.append((x, y, reach))
        truth.append(SceneMarker(int(marker_id), center, r, tilt, hom))
    others: list[shapes.Shape] = []
    for n in range(n_rectangles + n_artefacts):
        size = float(rng.uniform(14, 40))
        for _ in range(500):
            x, y = rng.uniform(size, width - size), rng.uniform(size, height - size)
            if _free(placed, x, y, size * 0.9 + 3):
                break
        else:
            continue
        placed.append((x, y, size * 0.9 + 3))
        if n < n_rectangles:
            w, h = size * float(rng.uniform(0.8, 1.5)), size * float(rng.uniform(0.4, 1.0))
            others.append(shapes.rectangle((x, y), w, h, float(rng.uniform(0, 180))))
        else:
            others.append(_artefact(rng, x, y, size))
    for shape in others:
        fill_polygons(img, [shape.vertices], ink)
    img *= _light(rng, width, height, light_gain)
    return look.develop(img, rng), truth


def _light(
    rng: np.random.Generator, width: int, height: int, gain: tuple[float, float]
) -> np.ndarray:
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    angle = rng.uniform(0, 2 * np.pi)
    ramp = (np.cos(angle) * xx / width + np.sin(angle) * yy / height) + 1.0
    bx, by = rng.uniform(0, width), rng.uniform(0, height)
    bump = np.exp(-((xx - bx) ** 2 + (yy - by) ** 2) / (2 * (0.4 * width) ** 2))
    field = ramp + bump
    field = (field - field.min()) / max(float(np.ptp(field)), 1e-9)
    return gain[0] + (gain[1] - gain[0]) * field
