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
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

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


@dataclass(frozen=True)
class DishTruth:
    """The dish: ``center`` (x, y) and ``radius`` of the agar disc, ``rim_width`` of the wall."""

    center: tuple[float, float]
    radius: float
    rim_width: float

    def to_dict(self) -> dict[str, Any]:
        """Return ``{"center": [x, y], "radius": r, "rim_width": w}``."""
        return {
            "center": [self.center[0], self.center[1]],
            "radius": self.radius,
            "rim_width": self.rim_width,
        }


@dataclass(frozen=True)
class ColonyTruth:
    """One colony (or merged group) as drawn.

    Attributes
    ----------
    id : int
        Index in :attr:`PlateTruth.colonies`.
    kind : str
        ``"authentic"``, ``"merged"`` or ``"mixed"``.
    center : tuple of float
        Area centroid ``(x, y)`` of the drawn body (pixels where the body covers more than half).
    count : int
        Number of colonies in the body: 1 for authentic and mixed, 2 or 3 for merged.
    ellipses : list of Ellipse
        The undeformed ellipse of every member (one for authentic and mixed).
    contour : ndarray, shape (n, 2)
        Outline polygon ``(x, y)`` of the body (exact for DES, traced for merged groups).
    area_px : int
        Pixels covered by more than half.
    colours_rgb : list of tuple
        The species colours (two for a mixed colony).
    mix_style : str
        ``"sector"`` or ``"speckles"`` for mixed colonies, ``""`` otherwise.
    near_agar : bool
        True if the colony has nearly the agar's colour.
    """

    id: int
    kind: str
    center: tuple[float, float]
    count: int
    ellipses: list[Ellipse]
    contour: np.ndarray
    area_px: int
    colours_rgb: list[tuple[int, int, int]]
    mix_style: str = ""
    near_agar: bool = False

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form (contour as a list of ``[x, y]``)."""
        return {
            "id": self.id,
            "kind": self.kind,
            "center": [self.center[0], self.center[1]],
            "count": self.count,
            "ellipses": [e.to_dict() for e in self.ellipses],
            "contour": np.round(self.contour, 2).tolist(),
            "area_px": self.area_px,
            "colours_rgb": [list(c) for c in self.colours_rgb],
            "mix_style": self.mix_style,
            "near_agar": self.near_agar,
        }


@dataclass(frozen=True)
class ArtefactTruth:
    """One artefact: ``kind`` is dust, scratch, pen, label or glare; ``points`` its polyline,
    polygon or centre; ``on_agar`` is True when it lies inside the agar disc (not on the rim)."""

    kind: str
    points: np.ndarray
    on_agar: bool

    def __post_init__(self) -> None:
        # stored rounded to 0.01 px, as in the JSON, so a round trip is exact
        pts = np.round(np.asarray(self.points, dtype=float).reshape(-1, 2), 2)
        object.__setattr__(self, "points", pts)

    @property
    def center(self) -> tuple[float, float]:
        """Mean of the artefact's points."""
        m = self.points.reshape(-1, 2).mean(axis=0)
        return float(m[0]), float(m[1])

    def to_dict(self) -> dict[str, Any]:
        """Return ``{"kind", "points", "on_agar", "center"}``."""
        return {
            "kind": self.kind,
            "points": self.points.tolist(),
            "on_agar": self.on_agar,
            "center": list(self.center),
        }


@dataclass(frozen=True)
class PlateTruth:
    """Ground truth of a generated plate."""

    seed: int
    width: int
    height: int
    agar: str
    stage: str
    dish: DishTruth
    colonies: list[ColonyTruth] = field(default_factory=list)
    artefacts: list[ArtefactTruth] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        """Number of colonies per kind and the total number of colonies (merged count summed)."""
        out = {k: sum(c.kind == k for c in self.colonies) for k in ("authentic", "merged", "mixed")}
        out["colonies_total"] = sum(c.count for c in self.colonies)
        return out

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON form of the whole truth."""
        return {
            "seed": self.seed,
            "width": self.width,
            "height": self.height,
            "agar": self.agar,
            "stage": self.stage,
            "dish": self.dish.to_dict(),
            "colonies": [c.to_dict() for c in self.colonies],
            "artefacts": [a.to_dict() for a in self.artefacts],
            "counts": self.counts(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PlateTruth:
        """Rebuild a truth from :meth:`to_dict` output (e.g. a sample plate's JSON)."""
        dish = DishTruth(
            tuple(data["dish"]["center"]), data["dish"]["radius"], data["dish"]["rim_width"]
        )
        colonies = [
            ColonyTruth(
                id=c["id"],
                kind=c["kind"],
                center=tuple(c["center"]),
                count=c["count"],
                ellipses=[
                    Ellipse(tuple(e["center"]), tuple(e["axes"]), e["angle"]) for e in c["ellipses"]
                ],
                contour=np.asarray(c["contour"], dtype=float),
                area_px=c["area_px"],
                colours_rgb=[tuple(x) for x in c["colours_rgb"]],
                mix_style=c["mix_style"],
                near_agar=c["near_agar"],
            )
            for c in data["colonies"]
        ]
        artefacts = [
            ArtefactTruth(a["kind"], np.asarray(a["points"], dtype=float), a["on_agar"])
            for a in data["artefacts"]
        ]
        return cls(
            data["seed"],
            data["width"],
            data["height"],
            data["agar"],
            data["stage"],
            dish,
            colonies,
            artefacts,
        )


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
# Rendering helpers (float32 RGB canvas, values 0..255)


def _blend(canvas: np.ndarray, alpha: np.ndarray, colour: np.ndarray, x0: int, y0: int) -> None:
    """Alpha-blend ``colour`` (broadcastable to the ROI) into the canvas at ``(x0, y0)``."""
    h, w = alpha.shape
    roi = canvas[y0 : y0 + h, x0 : x0 + w]
    a = alpha[..., None]
    roi *= 1.0 - a
    roi += a * colour


def _roi(cx: float, cy: float, r: float, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    h, w = shape
    x0, y0 = max(int(cx - r) - 2, 0), max(int(cy - r) - 2, 0)
    x1, y1 = min(int(cx + r) + 3, w), min(int(cy + r) + 3, h)
    return x0, y0, x1, y1


def _grid(x0: int, y0: int, x1: int, y1: int) -> tuple[np.ndarray, np.ndarray]:
    ys, xs = np.mgrid[y0:y1, x0:x1]
    return xs.astype(np.float32), ys.astype(np.float32)


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
    x0, y0, x1, y1 = _roi(des.cx, des.cy, des.bound + 2.0, cover.shape)
    xs, ys = _grid(x0, y0, x1, y1)
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
    _blend(canvas[..., :], alpha * cover_share, colour, x0, y0)
    cover[y0:y1, x0:x1] |= alpha > 0.5


def _draw_ring_edge(canvas: np.ndarray, des: _Des, darker: float, width_px: float) -> None:
    """Darken a colony's edge by ``darker`` grey levels over a band ``width_px`` wide.

    The band is a Gaussian profile across the boundary, centred just inside it: the thin dark
    rim of a translucent colony whose inside is nearly the agar's colour (AGAR plate 510).
    """
    x0, y0, x1, y1 = _roi(des.cx, des.cy, des.bound + 2.0 + width_px, canvas.shape[:2])
    xs, ys = _grid(x0, y0, x1, y1)
    rho, t = des.local(xs, ys)
    edge_dist = (1.0 - rho) * math.sqrt(des.a * des.b) * des.radius_factor(t)
    band = np.exp(-(((edge_dist - 0.5 * width_px) / (0.5 * width_px)) ** 2)).astype(np.float32)
    canvas[y0:y1, x0:x1] -= darker * band[..., None]


def _stroke_alpha(
    shape: tuple[int, int], pts: np.ndarray, thickness: int, closed: bool = False
) -> tuple[np.ndarray, int, int]:
    """Antialiased polyline alpha in a tight ROI: returns (alpha, x0, y0)."""
    pad = thickness + 3
    x0 = max(int(pts[:, 0].min()) - pad, 0)
    y0 = max(int(pts[:, 1].min()) - pad, 0)
    x1 = min(int(pts[:, 0].max()) + pad, shape[1])
    y1 = min(int(pts[:, 1].max()) + pad, shape[0])
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    shift = 4
    p = np.round((pts - [x0, y0]) * (1 << shift)).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(mask, [p], closed, 255, thickness, cv2.LINE_AA, shift)
    return mask.astype(np.float32) / 255.0, x0, y0


# --------------------------------------------------------------------------------------------
# Placement


class _Placer:
    """Rejection sampling of non-overlapping discs inside the usable part of the agar."""

    def __init__(self, rng: np.random.Generator, cx: float, cy: float, r_use: float, gap: float):
        self.rng, self.cx, self.cy, self.r_use, self.gap = rng, cx, cy, r_use, gap
        self.discs: list[tuple[float, float, float]] = []

    def free(self, x: float, y: float, r: float, gap: float | None = None) -> bool:
        g = self.gap if gap is None else gap
        if math.hypot(x - self.cx, y - self.cy) + r > self.r_use:
            return False
        return all(math.hypot(x - px, y - py) >= r + pr + g for px, py, pr in self.discs)

    def sample(self, r: float, tries: int = 400) -> tuple[float, float] | None:
        for _ in range(tries):
            rr = (self.r_use - r) * math.sqrt(self.rng.uniform())
            th = self.rng.uniform(0.0, 2.0 * np.pi)
            x, y = self.cx + rr * math.cos(th), self.cy + rr * math.sin(th)
            if self.free(x, y, r):
                return x, y
        return None

    def add(self, x: float, y: float, r: float) -> None:
        self.discs.append((x, y, r))

    def clear_of_colonies(self, pts: np.ndarray, half_width: float, gap: float) -> bool:
        for px, py, pr in self.discs:
            if np.min(np.hypot(pts[:, 0] - px, pts[:, 1] - py)) < pr + half_width + gap:
                return False
        return True


def _densify(pts: np.ndarray, step: float = 2.0) -> np.ndarray:
    out = [pts[:1]]
    for p, q in itertools.pairwise(pts):
        n = max(int(np.hypot(*(q - p)) / step), 1)
        out.append(p + (q - p) * np.linspace(0, 1, n + 1)[1:, None])
    return np.concatenate(out)


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
    _blend(canvas, np.clip(radius + rim - dist + 0.5, 0, 1), wall, 0, 0)
    _blend(canvas, np.clip(radius - dist + 0.5, 0, 1), agar_rgb, 0, 0)
    meniscus = np.clip(1.6 - np.abs(dist - radius), 0, 1) * 0.6
    _blend(canvas, meniscus, 0.45 * agar_rgb, 0, 0)
    outer = np.clip(1.2 - np.abs(dist - radius - rim), 0, 1) * 0.5
    _blend(canvas, outer, white, 0, 0)

    # Grain of the agar (low-frequency noise)
    grain = cv2.resize(
        rng.normal(0.0, 1.0, (height // 16 + 2, width // 16 + 2)).astype(np.float32),
        (width, height),
        interpolation=cv2.INTER_CUBIC,
    )
    canvas += (3.0 * grain * (dist < radius))[..., None]

    cover = np.zeros((height, width), bool)
    margin = 36.0 * k
    placer = _Placer(rng, cx, cy, radius - margin, 8.0 * k)
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
        arts = _draw_artefacts(canvas, rng, placer, cx, cy, radius, rim, agar_rgb, k)

    if lid_label:
        arts.append(_draw_lid_label(canvas, rng, cx, cy, radius, k))

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


def _draw_lid_label(
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


def _draw_artefacts(
    canvas: np.ndarray,
    rng: np.random.Generator,
    placer: _Placer,
    cx: float,
    cy: float,
    radius: float,
    rim: float,
    agar_rgb: np.ndarray,
    k: float,
) -> list[ArtefactTruth]:
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
        alpha, x0, y0 = _stroke_alpha(shape, poly, 1, closed=True)
        fill = np.zeros(alpha.shape, np.uint8)
        cv2.fillPoly(fill, [np.round(poly - [x0, y0]).astype(np.int32)], 255)
        _blend(
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
            pts = _densify(np.array([p0, p1]), 6.0)
            pts += rng.normal(0, 1.2 * k, pts.shape)
            a, x0, y0 = _stroke_alpha(shape, pts, max(int(2 * k), 1))
            _blend(canvas, a, np.array([40.0, 40.0, 60.0]), x0, y0)
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
            poly = _densify(np.array(pts), 2.0)
            d = np.hypot(poly[:, 0] - cx, poly[:, 1] - cy)
            if on_rim and not (np.all(d > radius - 16 * k) and np.all(d < radius + rim + 30 * k)):
                continue
            if not on_rim and not (
                inside_agar(poly, 20 * k) and placer.clear_of_colonies(poly, thick / 2, gap)
            ):
                continue
            alpha, x0, y0 = _stroke_alpha(shape, poly, thick)
            _blend(canvas, alpha * 0.9, ink, x0, y0)
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
            poly = _densify(pts, 2.0)
            if not inside_agar(poly, 12 * k) or not placer.clear_of_colonies(poly, 1.0, gap):
                continue
            alpha, x0, y0 = _stroke_alpha(shape, poly, 1)
            tone = agar_rgb * (1.25 if rng.uniform() < 0.6 else 0.75)
            _blend(canvas, alpha * 0.85, np.clip(tone, 0, 255), x0, y0)
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
            pts = _densify(np.array([c - d * length / 2, c + d * length / 2]), 2.0)
            if not inside_agar(pts, 20 * k) or not placer.clear_of_colonies(pts, half_w * 2, gap):
                continue
            x0, y0, x1, y1 = _roi(c[0], c[1], length / 2 + 3 * half_w, shape)
            xs, ys = _grid(x0, y0, x1, y1)
            along = (xs - c[0]) * d[0] + (ys - c[1]) * d[1]
            across = -(xs - c[0]) * d[1] + (ys - c[1]) * d[0]
            a = np.exp(-0.5 * (across / half_w) ** 2) * np.clip(
                (length / 2 - np.abs(along)) / (2 * half_w), 0, 1
            )
            _blend(canvas, (0.75 * a).astype(np.float32), np.array([252.0, 252.0, 252.0]), x0, y0)
            arts.append(ArtefactTruth("glare", pts, True))
            break
    th0 = rng.uniform(0, 2 * np.pi)
    arc = np.array([on_circle(radius - 4 * k, th0 + s) for s in np.linspace(0, 0.5, 40)])
    alpha, x0, y0 = _stroke_alpha(shape, arc, max(int(4 * k), 2))
    _blend(canvas, alpha * 0.6, np.array([250.0, 250.0, 250.0]), x0, y0)
    arts.append(ArtefactTruth("glare", arc, False))

    # Dust: tiny dark specks anywhere on the agar, away from colonies.
    for _ in range(int(rng.integers(8, 20))):
        for _try in range(40):
            rr = (radius - 14 * k) * math.sqrt(rng.uniform())
            c = on_circle(rr, rng.uniform(0, 2 * np.pi))
            r_d = rng.uniform(0.8, 2.0)
            if not placer.clear_of_colonies(c[None, :], r_d, gap):
                continue
            x0, y0, x1, y1 = _roi(c[0], c[1], r_d + 2, shape)
            xs, ys = _grid(x0, y0, x1, y1)
            a = np.clip(r_d - np.hypot(xs - c[0], ys - c[1]) + 0.5, 0, 1).astype(np.float32)
            _blend(canvas, 0.85 * a, np.array([35.0, 32.0, 30.0]), x0, y0)
            arts.append(ArtefactTruth("dust", c[None, :], True))
            break
    return arts


# --------------------------------------------------------------------------------------------
# Scoring an analysis against the truth


@dataclass(frozen=True)
class PlateScore:
    """How well a list of reported colonies matches a plate's truth.

    Attributes
    ----------
    n_truth : int
        Colonies (bodies) in the truth.
    found : int
        Truth colonies matched by a reported colony.
    correct : int
        Matched colonies whose class equals the truth's kind.
    count_correct, n_merged_found : int
        Merged bodies found as merged whose estimated count equals the truth count, and merged
        bodies found as merged.
    false_positives : int
        Reported colonies that match no truth colony.
    artefacts_reported : int
        False positives that lie on an artefact.
    confusion : dict
        ``{(truth kind, reported class): n}``, with ``"missed"`` as the reported class.
    """

    n_truth: int
    found: int
    correct: int
    count_correct: int
    n_merged_found: int
    false_positives: int
    artefacts_reported: int
    confusion: dict[tuple[str, str], int]


def score_plate(truth: PlateTruth, colonies: list[Any], scale: float = 1.0) -> PlateScore:
    """Match reported colonies to the truth and count what was found and classified right.

    A reported colony (anything with ``centroid``, ``klass`` and ``estimated_count``) matches
    the truth colony whose outline contains its centroid, or, failing that, the nearest truth
    centre within half the truth's equivalent radius; each truth colony is matched at most once.
    ``scale``: the colonies were reported on the plate resampled by this factor (as
    ``cv2.resize(image, None, fx=scale, fy=scale)``); their centroids are mapped back first.
    """
    polys = [c.contour.astype(np.float32).reshape(-1, 1, 2) for c in truth.colonies]
    used: set[int] = set()
    found = correct = count_ok = merged_found = fp = art = 0
    confusion: dict[tuple[str, str], int] = {}
    for col in colonies:
        # pixel centres: x in the resampled image is at (x + 0.5) / scale - 0.5 in the plate's
        x = (float(col.centroid[0]) + 0.5) / scale - 0.5
        y = (float(col.centroid[1]) + 0.5) / scale - 0.5
        match = None
        for i, (tc, poly) in enumerate(zip(truth.colonies, polys, strict=True)):
            if i in used:
                continue
            if cv2.pointPolygonTest(poly, (x, y), False) >= 0 or math.hypot(
                x - tc.center[0], y - tc.center[1]
            ) <= 0.5 * math.sqrt(tc.area_px / math.pi):
                match = i
                break
        if match is None:
            fp += 1
            for a in truth.artefacts:
                pts = a.points.reshape(-1, 2)
                if np.min(np.hypot(pts[:, 0] - x, pts[:, 1] - y)) < 25.0 or (
                    a.kind in ("label", "lid-label")
                    and cv2.pointPolygonTest(
                        pts.astype(np.float32).reshape(-1, 1, 2), (x, y), False
                    )
                    >= 0
                ):
                    art += 1
                    break
            continue
        used.add(match)
        tc = truth.colonies[match]
        found += 1
        key = (tc.kind, col.klass)
        confusion[key] = confusion.get(key, 0) + 1
        if col.klass == tc.kind:
            correct += 1
            if tc.kind == "merged":
                merged_found += 1
                count_ok += int(col.estimated_count == tc.count)
    for i, tc in enumerate(truth.colonies):
        if i not in used:
            confusion[(tc.kind, "missed")] = confusion.get((tc.kind, "missed"), 0) + 1
    return PlateScore(
        len(truth.colonies), found, correct, count_ok, merged_found, fp, art, confusion
    )
