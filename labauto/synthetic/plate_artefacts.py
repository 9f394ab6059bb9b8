"""Artefacts on a synthetic plate: what a colony picker must not take for a colony.

Paper labels and pen strokes on the rim, pen writing on the lid over the agar, thin scratches,
glare streaks and dust specks smaller than any colony (:func:`draw_artefacts`), and a printed
dot-matrix label across the lid (:func:`draw_lid_label`); the choices are listed in
:mod:`labauto.synthetic.plates`. Each artefact drawn is returned as an
:class:`~labauto.synthetic.plate_truth.ArtefactTruth`.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from labauto.synthetic.plate_canvas import Placer, blend, densify, pixel_grid, roi_box, stroke_alpha
from labauto.synthetic.plate_truth import ArtefactTruth

__all__ = ["draw_artefacts", "draw_lid_label"]


def draw_lid_label(
    canvas: np.ndarray, rng: np.random.Generator, cx: float, cy: float, radius: float, k: float
) -> ArtefactTruth:
    """A printed lid label across the dish: 3 rows of dot-matrix "characters", blue-black ink.

    Each character is a 5x7 grid of dots (0.35 mm, about 3.5 px at 1024 px) of which about half
    are inked, 1.2 dot pitches apart; rows run across the middle of the dish at a random angle.
    The ink takes ~55 % of the light (a bit less of the blue), as real printed lids do.
    """
    angle = rng.uniform(0.0, np.pi)
    u = np.array([math.cos(angle), math.sin(angle)])
    v = np.array([-u[1], u[0]])
    pitch = 4.2 * k
    dot_r = 1.7 * k
    ink = np.zeros(canvas.shape[:2], np.float32)
    points = []
    length = 1.2 * radius
    for row in range(3):
        base = np.array([cx, cy]) - u * length / 2 + v * (row - 1) * 10 * pitch
        for char in range(int(length / (6 * pitch))):
            bits = rng.uniform(size=(7, 5)) < 0.5
            for gy, gx in zip(*np.nonzero(bits), strict=True):
                p = base + u * (char * 6 + gx) * pitch + v * gy * pitch
                cv2.circle(ink, (round(p[0] * 4), round(p[1] * 4)), round(dot_r * 4), 1.0, -1,
                           cv2.LINE_AA, 2)  # fmt: skip
                points.append(p)
    ink = np.clip(ink, 0, 1)[..., None] * np.array([0.58, 0.55, 0.45], np.float32)
    canvas *= 1.0 - ink
    pts = np.array(points, float)
    hull = cv2.convexHull(pts.astype(np.float32)).reshape(-1, 2).astype(float)
    return ArtefactTruth("lid-label", hull, True)


def draw_artefacts(
    canvas: np.ndarray,
    rng: np.random.Generator,
    placer: Placer,
    cx: float,
    cy: float,
    radius: float,
    rim: float,
    agar_rgb: np.ndarray,
    k: float,
) -> list[ArtefactTruth]:
    """Draw the rim's labels and pen strokes, pen on the lid, scratches, glare and dust.

    Parameters
    ----------
    canvas : ndarray
        HxWx3 float32 RGB canvas (0..255), drawn on in place.
    rng : numpy.random.Generator
        The plate's generator (the order of draws fixes the plate for a seed).
    placer : Placer
        The colonies placed so far: artefacts on the agar keep clear of them.
    cx, cy, radius, rim : float
        The agar disc and the width of the wall, pixels.
    agar_rgb : ndarray
        The agar's colour (RGB).
    k : float
        Pixel scale of the plate (``min(w, h) / 1024``).

    Returns
    -------
    list of ArtefactTruth
        Every artefact drawn, in the order drawn.
    """
    shape = canvas.shape[:2]
    arts: list[ArtefactTruth] = []
    gap = 6.0 * k

    def inside_agar(pts: np.ndarray, pad: float) -> bool:
        return bool(np.all(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) < radius - pad))

    def on_circle(r: float, th: float) -> np.ndarray:
        return np.array([cx + r * math.cos(th), cy + r * math.sin(th)])

    # Labels on the rim: a paper rectangle tangent to the wall with some "text" strokes.
    for _ in range(int(rng.integers(0, 2)) + 1):
        th = rng.uniform(0, 2 * np.pi)
        c = on_circle(radius + rim * 0.5 + 8 * k, th)
        tang = np.array([-math.sin(th), math.cos(th)])
        norm = np.array([math.cos(th), math.sin(th)])
        hw, hh = rng.uniform(45, 70) * k, 22 * k
        poly = np.array(
            [c + sx * hw * tang + sy * hh * norm for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        )
        alpha, x0, y0 = stroke_alpha(shape, poly, 1, closed=True)
        fill = np.zeros(alpha.shape, np.uint8)
        cv2.fillPoly(fill, [np.round(poly - [x0, y0]).astype(np.int32)], 255)
        blend(
            canvas,
            np.maximum(alpha, fill / 255.0).astype(np.float32),
            np.array([244.0, 242.0, 230.0]),
            x0,
            y0,
        )
        for line in range(2):
            off = (line - 0.5) * hh * 0.8
            p0 = c - 0.8 * hw * tang + off * norm
            p1 = c + rng.uniform(0.0, 0.8) * hw * tang + off * norm
            pts = densify(np.array([p0, p1]), 6.0)
            pts += rng.normal(0, 1.2 * k, pts.shape)
            a, x0, y0 = stroke_alpha(shape, pts, max(int(2 * k), 1))
            blend(canvas, a, np.array([40.0, 40.0, 60.0]), x0, y0)
        arts.append(ArtefactTruth("label", poly, False))

    # Pen strokes on the rim and on the lid over the agar (scribbled digits/lines).
    ink = np.array([30.0, 40.0, 100.0]) if rng.uniform() < 0.5 else np.array([28.0, 28.0, 30.0])
    for i in range(int(rng.integers(2, 5))):
        on_rim = i < 2
        thick = int(rng.integers(3, 5))
        for _ in range(60):
            if on_rim:
                th = rng.uniform(0, 2 * np.pi)
                start = on_circle(radius + rng.uniform(-8, rim) * k, th)
            else:
                rr = (radius - 60 * k) * math.sqrt(rng.uniform())
                start = on_circle(rr, rng.uniform(0, 2 * np.pi))
            n_seg = int(rng.integers(1, 4))
            pts = [start]
            heading = rng.uniform(0, 2 * np.pi)
            for _s in range(n_seg):
                length = rng.uniform(25, 70) * k
                pts.append(pts[-1] + length * np.array([math.cos(heading), math.sin(heading)]))
                heading += rng.choice([-1, 1]) * rng.uniform(np.radians(35), np.radians(150))
            poly = densify(np.array(pts), 2.0)
            d = np.hypot(poly[:, 0] - cx, poly[:, 1] - cy)
            if on_rim and not (np.all(d > radius - 16 * k) and np.all(d < radius + rim + 30 * k)):
                continue
            if not on_rim and not (
                inside_agar(poly, 20 * k) and placer.clear_of_colonies(poly, thick / 2, gap)
            ):
                continue
            alpha, x0, y0 = stroke_alpha(shape, poly, thick)
            blend(canvas, alpha * 0.9, ink, x0, y0)
            arts.append(ArtefactTruth("pen", poly, not on_rim))
            break

    # Scratches: long thin lines in the agar, a little lighter or darker than the agar.
    for _ in range(int(rng.integers(1, 4))):
        for _try in range(80):
            rr = (radius - 40 * k) * math.sqrt(rng.uniform())
            c = on_circle(rr, rng.uniform(0, 2 * np.pi))
            heading = rng.uniform(0, np.pi)
            length = rng.uniform(60, 260) * k
            d = np.array([math.cos(heading), math.sin(heading)])
            bend = np.array([-d[1], d[0]]) * rng.uniform(-8, 8) * k
            pts = np.array([c - d * length / 2, c + bend, c + d * length / 2])
            poly = densify(pts, 2.0)
            if not inside_agar(poly, 12 * k) or not placer.clear_of_colonies(poly, 1.0, gap):
                continue
            alpha, x0, y0 = stroke_alpha(shape, poly, 1)
            tone = agar_rgb * (1.25 if rng.uniform() < 0.6 else 0.75)
            blend(canvas, alpha * 0.85, np.clip(tone, 0, 255), x0, y0)
            arts.append(ArtefactTruth("scratch", poly, True))
            break

    # Glare: long soft near-white streaks over the agar and an arc along the wall.
    for _ in range(int(rng.integers(1, 3))):
        for _try in range(80):
            length = rng.uniform(60, 150) * k
            half_w = length / rng.uniform(20, 30)
            rr = (radius - 50 * k) * math.sqrt(rng.uniform())
            c = on_circle(rr, rng.uniform(0, 2 * np.pi))
            heading = rng.uniform(0, np.pi)
            d = np.array([math.cos(heading), math.sin(heading)])
            pts = densify(np.array([c - d * length / 2, c + d * length / 2]), 2.0)
            if not inside_agar(pts, 20 * k) or not placer.clear_of_colonies(pts, half_w * 2, gap):
                continue
            x0, y0, x1, y1 = roi_box(c[0], c[1], length / 2 + 3 * half_w, shape)
            xs, ys = pixel_grid(x0, y0, x1, y1)
            along = (xs - c[0]) * d[0] + (ys - c[1]) * d[1]
            across = -(xs - c[0]) * d[1] + (ys - c[1]) * d[0]
            a = np.exp(-0.5 * (across / half_w) ** 2) * np.clip(
                (length / 2 - np.abs(along)) / (2 * half_w), 0, 1
            )
            blend(canvas, (0.75 * a).astype(np.float32), np.array([252.0, 252.0, 252.0]), x0, y0)
            arts.append(ArtefactTruth("glare", pts, True))
            break
    th0 = rng.uniform(0, 2 * np.pi)
    arc = np.array([on_circle(radius - 4 * k, th0 + s) for s in np.linspace(0, 0.5, 40)])
    alpha, x0, y0 = stroke_alpha(shape, arc, max(int(4 * k), 2))
    blend(canvas, alpha * 0.6, np.array([250.0, 250.0, 250.0]), x0, y0)
    arts.append(ArtefactTruth("glare", arc, False))

    # Dust: tiny dark specks anywhere on the agar, away from colonies.
    for _ in range(int(rng.integers(8, 20))):
        for _try in range(40):
            rr = (radius - 14 * k) * math.sqrt(rng.uniform())
            c = on_circle(rr, rng.uniform(0, 2 * np.pi))
            r_d = rng.uniform(0.8, 2.0)
            if not placer.clear_of_colonies(c[None, :], r_d, gap):
                continue
            x0, y0, x1, y1 = roi_box(c[0], c[1], r_d + 2, shape)
            xs, ys = pixel_grid(x0, y0, x1, y1)
            a = np.clip(r_d - np.hypot(xs - c[0], ys - c[1]) + 0.5, 0, 1).astype(np.float32)
            blend(canvas, 0.85 * a, np.array([35.0, 32.0, 30.0]), x0, y0)
            arts.append(ArtefactTruth("dust", c[None, :], True))
            break
    return arts
