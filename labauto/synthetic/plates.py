"""Synthetic petri-dish plates with exact ground truth.

``generate_plate(seed)`` renders a colour image of a petri dish seen from above, as a colony
picker's camera sees it, and returns it with the ground truth of everything drawn on it:

* the dish: a disc of agar with a visible plastic rim (and a dark meniscus line where agar meets
  the wall) on a dark or light stage;
* the agar: one of several colours (:data:`AGAR_COLOURS_RGB`), a lighting gradient with
  vignetting, a low-frequency grain and sensor noise, and a slight camera blur;
* authentic colonies: deformed elliptic shapes (DES), axis ratio 1:1 to 1:1.08 before a low-order
  harmonic deformation (orders 2 to 4) of the boundary (second-moment axis ratios of the
  outlines as analysed 1.02-1.14 from the 5th to the 95th percentile, at most ~1.19, as single
  colonies classed authentic on the AGAR photographs: 1.006-1.168), a soft edge, dome
  shading with a small off-centre highlight, colours from a palette and, now and then, a
  colony of nearly the agar's colour that still has a clear contrast;
* merged colonies: pairs and triples of overlapping colonies with a pronounced waist;
* mixed colonies: a DES whose body holds a second species of another colour, as a sector or as
  speckles;
* artefacts: pen strokes and paper labels on the rim, writing on the lid over the agar, thin
  scratches, dust specks smaller than any colony and glare streaks.

Choices made where the paper is silent (all geometry in pixels, scaled with ``min(w, h) / 1024``):

* Colonies never touch each other unless they are merged: bounding circles keep a gap of at least
  ``8 px``; colonies keep at least ``36 px`` from the agar's edge, artefacts keep ``6 px`` from
  any colony, so the truth of every colony is exact.
* A merged group's members overlap by 5-28 % of the sum of their radii and the waist where they
  meet is at most 0.72 of the smaller member's radius, so the group is one connected body that is
  visibly not a DES (radii taken along the line joining the centres; the union, eroded by one
  pixel, must still be one piece). Triples are chains bent by 50-120 degrees whose first and
  third members do not touch.
* A mixed colony's second species differs from the first by at least 70 RGB levels (Euclidean)
  and covers 18-45 % (sector) or 12-30 % (speckles) of the colony.
* Artefacts that lie on the agar are thin (scratches, pen strokes: at most 4.5 px wide), tiny
  (dust: area at most 13 px) or long and thin (glare streaks: length/width of at least 5).

Coordinates follow DESIGN.md: origin at the centre of the top-left pixel, x right, y down.

This module draws the dish and the colonies; the truth records are in
:mod:`labauto.synthetic.plate_truth`, the artefacts in :mod:`labauto.synthetic.plate_artefacts`,
the drawing and placement primitives in :mod:`labauto.synthetic.plate_canvas` and the scoring in
:mod:`labauto.synthetic.plate_score` (all re-exported here as before).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from labauto.synthetic.plate_artefacts import draw_artefacts, draw_lid_label
from labauto.synthetic.plate_canvas import Placer, blend, pixel_grid, roi_box
from labauto.synthetic.plate_score import PlateScore, score_plate
from labauto.synthetic.plate_truth import ArtefactTruth, ColonyTruth, DishTruth, PlateTruth
from labauto.vision.ellipse import Ellipse

__all__ = [
    "AGAR_COLOURS_RGB",
    "ArtefactTruth",
    "ColonyTruth",
    "DishTruth",
    "PlateScore",
    "PlateTruth",
    "generate_plate",
    "score_plate",
]

#: Agar colours (RGB) the generator knows.
AGAR_COLOURS_RGB: dict[str, tuple[int, int, int]] = {
    "amber": (206, 156, 76),
    "red_blood": (150, 30, 36),
    "chocolate": (106, 64, 38),
    "clear": (118, 122, 116),
    "macconkey": (196, 82, 122),
    "chromogenic": (214, 204, 180),
}

#: Colony colours (RGB); a colony's colour is drawn among those with enough contrast to the agar.
COLONY_COLOURS_RGB: tuple[tuple[int, int, int], ...] = (
    (238, 234, 220),  # cream white
    (246, 240, 196),  # pale yellow
    (196, 198, 200),  # grey
    (232, 190, 86),  # golden
    (242, 172, 176),  # pink
    (160, 112, 66),  # brown
    (84, 86, 92),  # dark grey
    (112, 150, 222),  # blue (chromogenic)
    (118, 182, 118),  # green
    (250, 250, 246),  # white
    (200, 60, 150),  # magenta
)

_STAGES_RGB = {"dark": (26, 28, 32), "light": (200, 202, 198)}
_MIN_COLOUR_CONTRAST = 70.0
_MIN_SPECIES_CONTRAST = 60.0
_SAMPLE_ANGLES = 128


# --------------------------------------------------------------------------------------------
# Shapes


@dataclass(frozen=True)
class _Des:
    """A deformed ellipse: ``r(t) = 1 + sum c_k cos(k t + phi_k)`` scaled by the semi-axes."""

    cx: float
    cy: float
    a: float
    b: float
    angle: float  # radians
    coeffs: tuple[tuple[int, float, float], ...]  # (order k, amplitude c_k, phase phi_k)

    @property
    def bound(self) -> float:
        return self.a * (1.0 + sum(abs(c) for _, c, _ in self.coeffs))

    def radius_factor(self, t: np.ndarray) -> np.ndarray:
        r = np.ones_like(t)
        for k, c, phi in self.coeffs:
            r += c * np.cos(k * t + phi)
        return r

    def local(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised radius ``rho`` (1 on the boundary) and parameter angle ``t`` of points."""
        dx, dy = x - self.cx, y - self.cy
        c, s = math.cos(self.angle), math.sin(self.angle)
        u = (c * dx + s * dy) / self.a
        v = (-s * dx + c * dy) / self.b
        t = np.arctan2(v, u)
        return np.hypot(u, v) / self.radius_factor(t), t

    def polygon(self, n: int = _SAMPLE_ANGLES) -> np.ndarray:
        t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        r = self.radius_factor(t)
        u, v = self.a * r * np.cos(t), self.b * r * np.sin(t)
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.column_stack((self.cx + c * u - s * v, self.cy + s * u + c * v))

    def ellipse(self) -> Ellipse:
        return Ellipse.normalised(self.cx, self.cy, self.a, self.b, math.degrees(self.angle))


def _random_des(rng: np.random.Generator, cx: float, cy: float, a: float) -> _Des:
    ratio = rng.uniform(1.0, 1.08)
    coeffs = tuple(
        (k, float(rng.uniform(0.0, amp)), float(rng.uniform(0.0, 2.0 * np.pi)))
        for k, amp in ((2, 0.05), (3, 0.04), (4, 0.025))
    )
    return _Des(cx, cy, a, a / ratio, float(rng.uniform(0.0, np.pi)), coeffs)


# --------------------------------------------------------------------------------------------
# Drawing colonies (float32 RGB canvas, values 0..255; primitives in plate_canvas)


def _draw_des(
    canvas: np.ndarray,
    cover: np.ndarray,
    des: _Des,
    colour_of: Any,
    rng: np.random.Generator,
    opacity: float = 1.0,
) -> None:
    """Draw a colony with soft edge, dome shading and a highlight; mark ``cover`` (alpha > .5).

    ``colour_of(x, y, rho, t)`` returns the body colour (RGB, per pixel or one colour).
    ``opacity`` below 1 draws a translucent colony: the agar shows through it, so its shading
    and highlight depart from the agar by that share too, as its colour does.
    """
    x0, y0, x1, y1 = roi_box(des.cx, des.cy, des.bound + 2.0, cover.shape)
    xs, ys = pixel_grid(x0, y0, x1, y1)
    rho, t = des.local(xs, ys)
    scale = math.sqrt(des.a * des.b) * des.radius_factor(t)
    edge_dist = (1.0 - rho) * scale  # ~ signed distance to the boundary in px (inside > 0)
    alpha = np.clip(edge_dist / 1.6 + 0.5, 0.0, 1.0).astype(np.float32)
    depth = np.sqrt(np.clip(1.0 - rho * rho, 0.0, 1.0))
    shade = (0.86 + 0.16 * depth)[..., None]
    cover_share = (0.88 + 0.12 * depth) * opacity
    hx, hy = rng.uniform(-0.35, 0.35, 2) * des.a
    sigma = 0.3 * des.b
    glint = 18.0 * np.exp(-((xs - des.cx - hx) ** 2 + (ys - des.cy - hy) ** 2) / (2 * sigma**2))
    body = np.asarray(colour_of(xs, ys, rho, t), dtype=np.float32)
    colour = np.clip(body * shade + glint[..., None], 0.0, 255.0)
    blend(canvas[..., :], alpha * cover_share, colour, x0, y0)
    cover[y0:y1, x0:x1] |= alpha > 0.5


def _draw_ring_edge(canvas: np.ndarray, des: _Des, darker: float, width_px: float) -> None:
    """Darken a colony's edge by ``darker`` grey levels over a band ``width_px`` wide.

    The band is a Gaussian profile across the boundary, centred just inside it: the thin dark
    rim of a translucent colony whose inside is nearly the agar's colour (AGAR plate 510).
    """
    x0, y0, x1, y1 = roi_box(des.cx, des.cy, des.bound + 2.0 + width_px, canvas.shape[:2])
    xs, ys = pixel_grid(x0, y0, x1, y1)
    rho, t = des.local(xs, ys)
    edge_dist = (1.0 - rho) * math.sqrt(des.a * des.b) * des.radius_factor(t)
    band = np.exp(-(((edge_dist - 0.5 * width_px) / (0.5 * width_px)) ** 2)).astype(np.float32)
    canvas[y0:y1, x0:x1] -= darker * band[..., None]


# --------------------------------------------------------------------------------------------
# Colours


def _pick_colour(rng: np.random.Generator, agar: np.ndarray, near_agar: bool) -> np.ndarray:
    if near_agar:
        sign = 1.0 if agar.mean() < 150 else -1.0
        tint = rng.uniform(-8.0, 8.0, 3)
        return np.clip(agar + sign * rng.uniform(40.0, 50.0) + tint, 0, 255)
    choices = [
        np.array(c, float)
        for c in COLONY_COLOURS_RGB
        if np.linalg.norm(np.array(c, float) - agar) >= _MIN_COLOUR_CONTRAST
    ]
    return choices[int(rng.integers(len(choices)))] + rng.uniform(-6.0, 6.0, 3)


def _pick_second_species(
    rng: np.random.Generator, agar: np.ndarray, first: np.ndarray
) -> np.ndarray:
    choices = [
        np.array(c, float)
        for c in COLONY_COLOURS_RGB
        if np.linalg.norm(np.array(c, float) - agar) >= _MIN_COLOUR_CONTRAST
        and np.linalg.norm(np.array(c, float) - first) >= _MIN_SPECIES_CONTRAST + 10
    ]
    return choices[int(rng.integers(len(choices)))]


# --------------------------------------------------------------------------------------------
# The generator


def generate_plate(
    seed: int,
    *,
    width: int = 1280,
    height: int = 1024,
    agar: str | None = "amber",
    stage: str | None = None,
    n_authentic: int = 20,
    n_merged: int = 6,
    n_mixed: int = 4,
    artefacts: bool = True,
    noise_sigma: float = 2.5,
    colony_scale: float = 1.0,
    faint_fraction: float = 0.0,
    faint_contrast: float = 0.25,
    ring_edge: float = 0.0,
    n_meniscus: int = 0,
    lid_label: bool = False,
) -> tuple[np.ndarray, PlateTruth]:
    """Render a synthetic petri dish and its ground truth.

    Parameters
    ----------
    seed : int
        Seed of the random generator; the same arguments always give the same plate.
    width, height : int
        Image size in pixels (at least 256 each).
    agar : str or None
        A key of :data:`AGAR_COLOURS_RGB`, or None to draw one from the seed.
    stage : {"dark", "light"} or None
        Surround of the dish; None draws one from the seed ("dark" for clear agar).
    n_authentic, n_merged, n_mixed : int
        Colonies to place of each kind. Merged groups are pairs (about 2/3) and triples. If the
        dish is too full, fewer are placed; the truth lists what was drawn.
    artefacts : bool
        Draw dust, scratches, pen marks, labels and glare.
    noise_sigma : float
        Standard deviation of the sensor noise in grey levels.
    colony_scale : float
        Colony sizes relative to the default 9-24 px radius (at 1024 px); with a large
        ``n_authentic`` this makes a crowded plate (e.g. 0.3 and 1000 colonies).
    faint_fraction : float
        Share of the authentic colonies drawn faint and translucent: ``faint_contrast`` of their
        colour's difference from the agar, and of their dome shading and highlight (the agar
        shows through all of it).
    faint_contrast : float
        Share (0-1] of a faint colony's colour difference from the agar that is drawn: 0.25 gives
        10-25 grey levels of contrast, 0.08 the 3-8 levels of large translucent colonies on pale
        agar (the AGAR photographs).
    ring_edge : float
        Grey levels by which a faint colony's edge is drawn darker (a band of ~0.4 mm): with a
        small ``faint_contrast``, the ring colonies of the AGAR photographs, whose inside is
        nearly the agar's colour (0 draws none).
    n_meniscus : int
        Authentic colonies drawn touching the meniscus (their centre half a radius inside the
        agar's edge, cut by it).
    lid_label : bool
        A printed label across the lid: rows of dark dot-matrix characters over the agar and
        over colonies (the artefact ``"lid-label"``; colonies under it stay in the truth).

    Returns
    -------
    image : ndarray, shape (height, width, 3), uint8
        BGR image (OpenCV order).
    truth : PlateTruth
        Everything that was drawn, in pixel coordinates.

    Raises
    ------
    ValueError
        If a size, a count or the agar/stage name is not valid.
    """
    if width < 256 or height < 256:
        raise ValueError(f"plate size must be at least 256x256, got width={width} height={height}")
    for name, n in (("n_authentic", n_authentic), ("n_merged", n_merged), ("n_mixed", n_mixed)):
        if n < 0:
            raise ValueError(f"{name} must be >= 0, got {n}")
    if not colony_scale > 0 or not 0 <= faint_fraction <= 1 or n_meniscus < 0:
        raise ValueError(
            f"colony_scale must be > 0, faint_fraction in [0, 1] and n_meniscus >= 0, got "
            f"{colony_scale}, {faint_fraction}, {n_meniscus}"
        )
    if not ring_edge >= 0:
        raise ValueError(f"ring_edge must be >= 0, got {ring_edge}")
    if not 0 < faint_contrast <= 1:
        raise ValueError(f"faint_contrast must be in (0, 1], got {faint_contrast}")
    rng = np.random.default_rng(seed)
    if agar is None:
        agar = sorted(AGAR_COLOURS_RGB)[int(rng.integers(len(AGAR_COLOURS_RGB)))]
    if agar not in AGAR_COLOURS_RGB:
        raise ValueError(f"agar must be one of {sorted(AGAR_COLOURS_RGB)}, got {agar!r}")
    if stage is None:
        stage = "dark" if agar == "clear" or rng.uniform() < 0.6 else "light"
    if stage not in _STAGES_RGB:
        raise ValueError(f"stage must be one of {sorted(_STAGES_RGB)}, got {stage!r}")

    k = min(width, height) / 1024.0
    agar_rgb = np.array(AGAR_COLOURS_RGB[agar], float) + rng.uniform(-6.0, 6.0, 3)
    canvas = np.empty((height, width, 3), np.float32)
    canvas[:] = _STAGES_RGB[stage]

    # Dish ------------------------------------------------------------------------------------
    radius = float(rng.uniform(0.425, 0.455) * min(width, height))
    rim = float(rng.uniform(12.0, 18.0) * k)
    slack_x = width / 2 - radius - rim - 6 * k
    slack_y = height / 2 - radius - rim - 6 * k
    cx = width / 2 - 0.5 + float(rng.uniform(-1, 1) * max(min(slack_x, 40 * k), 0))
    cy = height / 2 - 0.5 + float(rng.uniform(-1, 1) * max(min(slack_y, 30 * k), 0))
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    dist = np.hypot(xs - cx, ys - cy)
    white = np.array([236.0, 238.0, 240.0])
    wall = 0.55 * agar_rgb + 0.45 * white if stage == "dark" else 0.7 * white + 0.3 * agar_rgb
    blend(canvas, np.clip(radius + rim - dist + 0.5, 0, 1), wall, 0, 0)
    blend(canvas, np.clip(radius - dist + 0.5, 0, 1), agar_rgb, 0, 0)
    meniscus = np.clip(1.6 - np.abs(dist - radius), 0, 1) * 0.6
    blend(canvas, meniscus, 0.45 * agar_rgb, 0, 0)
    outer = np.clip(1.2 - np.abs(dist - radius - rim), 0, 1) * 0.5
    blend(canvas, outer, white, 0, 0)

    # Grain of the agar (low-frequency noise)
    grain = cv2.resize(
        rng.normal(0.0, 1.0, (height // 16 + 2, width // 16 + 2)).astype(np.float32),
        (width, height),
        interpolation=cv2.INTER_CUBIC,
    )
    canvas += (3.0 * grain * (dist < radius))[..., None]

    cover = np.zeros((height, width), bool)
    margin = 36.0 * k
    placer = Placer(rng, cx, cy, radius - margin, 8.0 * k)
    colonies: list[ColonyTruth] = []
    size_lo, size_hi = 9.0 * k * colony_scale, 24.0 * k * colony_scale
    if colony_scale != 1.0:
        placer.gap = 8.0 * k * min(colony_scale, 1.0)

    # Merged groups first (they need the most room) -------------------------------------------
    merged_members: list[list[_Des]] = []
    for i in range(n_merged):
        members = _merged_group(rng, 3 if i % 3 == 2 else 2, size_lo, size_hi)
        pts = np.concatenate([m.polygon(64) for m in members])
        gx, gy = pts.mean(axis=0)
        r_b = float(np.max(np.hypot(pts[:, 0] - gx, pts[:, 1] - gy))) + 2.0
        pos = placer.sample(r_b)
        if pos is None:
            continue
        placer.add(*pos, r_b)
        merged_members.append(
            [
                _Des(m.cx - gx + pos[0], m.cy - gy + pos[1], m.a, m.b, m.angle, m.coeffs)
                for m in members
            ]
        )

    # Single colonies ---------------------------------------------------------------------------
    singles: list[tuple[str, _Des]] = []
    for kind, n in (("mixed", n_mixed), ("authentic", n_authentic)):
        for _ in range(n):
            lo = max(size_lo, 13.0 * k * colony_scale) if kind == "mixed" else size_lo
            des = _random_des(rng, 0.0, 0.0, float(rng.uniform(lo, size_hi)))
            pos = placer.sample(des.bound + 1.5)
            if pos is None:
                continue
            placer.add(*pos, des.bound + 1.5)
            singles.append((kind, _Des(pos[0], pos[1], des.a, des.b, des.angle, des.coeffs)))

    # Draw colonies ---------------------------------------------------------------------------
    for members in merged_members:
        body_cover = np.zeros_like(cover)
        colour = _pick_colour(rng, agar_rgb, near_agar=False)
        same = rng.uniform() < 0.7
        colours = []
        for m in members:
            c = colour if same else _pick_colour(rng, agar_rgb, near_agar=False)
            colours.append(c)
            _draw_des(canvas, body_cover, m, lambda *_, c=c: c, rng)
        cover |= body_cover
        colonies.append(_truth_from_mask(len(colonies), "merged", body_cover, members, colours))

    for _ in range(n_meniscus):  # touching the meniscus: centre half a radius inside the edge
        des = _random_des(rng, 0.0, 0.0, float(rng.uniform(size_lo, size_hi)))
        for _try in range(200):
            th = rng.uniform(0.0, 2.0 * np.pi)
            rr = radius - 0.5 * min(des.a, des.b)
            x, y = cx + rr * math.cos(th), cy + rr * math.sin(th)
            gap_ok = all(
                math.hypot(x - px, y - py) >= des.bound + pr + placer.gap
                for px, py, pr in placer.discs
            )
            if gap_ok:
                placer.add(x, y, des.bound + 1.5)
                singles.append(("authentic", _Des(x, y, des.a, des.b, des.angle, des.coeffs)))
                break

    for kind, des in singles:
        near = kind == "authentic" and rng.uniform() < 0.2
        colour = _pick_colour(rng, agar_rgb, near_agar=near)
        faint = kind == "authentic" and faint_fraction > 0 and rng.uniform() < faint_fraction
        near |= faint
        style = ""
        if kind == "mixed":
            second = _pick_second_species(rng, agar_rgb, colour)
            style, colour_of = _mixed_colour(rng, des, colour, second)
            colours = [colour, second]
        else:
            colour_of = lambda *_, c=colour: c  # noqa: E731
            colours = [colour]
        opacity = faint_contrast if faint else 1.0  # faint: translucent, the agar shows through
        if faint:
            colours = [agar_rgb + faint_contrast * (colour - agar_rgb)]
        body_cover = np.zeros_like(cover)
        _draw_des(canvas, body_cover, des, colour_of, rng, opacity)
        if faint and ring_edge > 0:
            _draw_ring_edge(canvas, des, ring_edge, 4.0 * k)
        body_cover &= dist < radius  # a colony at the meniscus is cut by the agar's edge
        cover |= body_cover
        truth = _truth_from_mask(len(colonies), kind, body_cover, [des], colours, style, near)
        colonies.append(truth)

    # Artefacts -------------------------------------------------------------------------------
    arts: list[ArtefactTruth] = []
    if artefacts:
        arts = draw_artefacts(canvas, rng, placer, cx, cy, radius, rim, agar_rgb, k)

    if lid_label:
        arts.append(draw_lid_label(canvas, rng, cx, cy, radius, k))

    # Lighting, blur, noise -------------------------------------------------------------------
    phi = rng.uniform(0, 2 * np.pi)
    g_lin, vign = rng.uniform(0.04, 0.10), rng.uniform(0.03, 0.08)
    ramp = ((xs - cx) * math.cos(phi) + (ys - cy) * math.sin(phi)) / radius
    gain = (1.0 + g_lin * ramp) * (1.0 - vign * (dist / radius) ** 2)
    canvas *= gain[..., None]
    canvas = cv2.GaussianBlur(canvas, (0, 0), 0.6)
    canvas += rng.normal(0.0, noise_sigma, canvas.shape).astype(np.float32)
    image = cv2.cvtColor(np.clip(canvas + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_RGB2BGR)

    truth = PlateTruth(
        seed=int(seed),
        width=width,
        height=height,
        agar=agar,
        stage=stage,
        dish=DishTruth((float(cx), float(cy)), radius, rim),
        colonies=colonies,
        artefacts=arts,
    )
    return image, truth


def _radius_towards(des: _Des, heading: float) -> float:
    """Distance from the centre of ``des`` to its boundary in direction ``heading``."""
    pts = des.polygon(256) - [des.cx, des.cy]
    ang = np.arctan2(pts[:, 1], pts[:, 0])
    i = int(np.argmin(np.abs(np.angle(np.exp(1j * (ang - heading))))))
    return float(np.hypot(*pts[i]))


def _merged_group(rng: np.random.Generator, n: int, size_lo: float, size_hi: float) -> list[_Des]:
    """Members of a merged group around the origin with a pronounced waist between each pair.

    Each new member sits along ``heading`` from the previous one at ``u`` (0.72-0.95) times the
    sum of their radii in that direction; the waist, estimated with discs of those radii, is at
    most 0.72 of the smaller one. The group is kept only if its members' union, eroded by one
    pixel, is still one piece (a solid bridge, not a touch).
    """
    while True:
        base = float(rng.uniform(size_lo + 2.0, size_hi))
        members = [_random_des(rng, 0.0, 0.0, base)]
        heading = rng.uniform(0, 2 * np.pi)
        ok = True
        for j in range(1, n):
            if j == 2:
                heading += rng.choice([-1, 1]) * rng.uniform(np.radians(50), np.radians(120))
            m = _random_des(rng, 0.0, 0.0, base * float(rng.uniform(0.7, 1.0)))
            prev = members[-1]
            r1, r2 = _radius_towards(prev, heading), _radius_towards(m, heading + np.pi)
            d = rng.uniform(0.72, 0.95) * (r1 + r2)
            # half-width of the waist where two discs of radii r1, r2 at distance d meet
            x = (d * d + r1 * r1 - r2 * r2) / (2 * d)
            waist = math.sqrt(max(r1 * r1 - x * x, 0.0))
            if waist > 0.72 * min(r1, r2):
                ok = False
                break
            cx, cy = prev.cx + d * math.cos(heading), prev.cy + d * math.sin(heading)
            members.append(_Des(cx, cy, m.a, m.b, m.angle, m.coeffs))
        if ok and n == 3:
            # the first and third member must not touch (a bent chain, not a clump)
            a0, a2 = members[0], members[2]
            ang = math.atan2(a2.cy - a0.cy, a2.cx - a0.cx)
            reach = _radius_towards(a0, ang) + _radius_towards(a2, ang + np.pi)
            ok = math.hypot(a0.cx - a2.cx, a0.cy - a2.cy) >= 1.05 * reach
        if ok and _one_piece(members):
            return members


def _one_piece(members: list[_Des]) -> bool:
    """True if the members' union, eroded by one pixel, is connected."""
    polys = [m.polygon(96) for m in members]
    lo = np.min([p.min(axis=0) for p in polys], axis=0) - 4
    hi = np.max([p.max(axis=0) for p in polys], axis=0) + 4
    mask = np.zeros((int(hi[1] - lo[1]) + 1, int(hi[0] - lo[0]) + 1), np.uint8)
    for p in polys:
        cv2.fillPoly(mask, [np.round(p - lo).astype(np.int32)], 1)
    mask = cv2.erode(mask, np.ones((3, 3), np.uint8))
    return cv2.connectedComponents(mask)[0] == 2


def _mixed_colour(
    rng: np.random.Generator, des: _Des, first: np.ndarray, second: np.ndarray
) -> tuple[str, Any]:
    """Colour function of a mixed colony: a sector or speckles of the second species."""
    if rng.uniform() < 0.5:
        width = rng.uniform(0.18, 0.45) * 2 * np.pi
        start = rng.uniform(0, 2 * np.pi)

        def sector(xs: np.ndarray, ys: np.ndarray, rho: np.ndarray, t: np.ndarray) -> np.ndarray:
            ang = np.mod(np.arctan2(ys - des.cy, xs - des.cx) - start, 2 * np.pi)
            w = np.clip(np.minimum(ang, width - ang) / 1.0 * rho * des.b + 0.5, 0, 1)
            w = np.where(ang < width, w, 0.0)[..., None]
            return (1 - w) * first + w * second

        return "sector", sector

    n_spots = int(rng.integers(6, 14))
    frac = rng.uniform(0.12, 0.30)
    spot_r = des.b * math.sqrt(frac / n_spots)
    rr = 0.75 * np.sqrt(rng.uniform(0, 1, n_spots))
    th = rng.uniform(0, 2 * np.pi, n_spots)
    sx = des.cx + rr * des.b * np.cos(th)
    sy = des.cy + rr * des.b * np.sin(th)
    spot_r = max(spot_r, 2.0)

    def speckles(xs: np.ndarray, ys: np.ndarray, rho: np.ndarray, t: np.ndarray) -> np.ndarray:
        w = np.zeros_like(xs)
        for x, y in zip(sx, sy, strict=True):
            w = np.maximum(w, np.clip(spot_r - np.hypot(xs - x, ys - y) + 0.5, 0, 1))
        w = w[..., None]
        return (1 - w) * first + w * second

    return "speckles", speckles


def _truth_from_mask(
    idx: int,
    kind: str,
    body: np.ndarray,
    members: list[_Des],
    colours: list[np.ndarray],
    style: str = "",
    near_agar: bool = False,
) -> ColonyTruth:
    ys, xs = np.nonzero(body)
    center = (float(xs.mean()), float(ys.mean()))
    if len(members) == 1:
        contour = members[0].polygon()
    else:
        x0, y0 = int(xs.min()), int(ys.min())
        sub = body[y0 : ys.max() + 1, x0 : xs.max() + 1].astype(np.uint8)
        cs, _ = cv2.findContours(sub, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        contour = max(cs, key=cv2.contourArea).reshape(-1, 2).astype(float) + np.array([x0, y0])
    return ColonyTruth(
        id=idx,
        kind=kind,
        center=center,
        count=len(members),
        ellipses=[m.ellipse() for m in members],
        contour=contour,
        area_px=int(xs.size),
        colours_rgb=[tuple(round(float(v)) for v in np.clip(c, 0, 255)) for c in colours],
        mix_style=style,
        near_agar=near_agar,
    )
