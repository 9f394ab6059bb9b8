"""Drawing and placement primitives of the plate generator (float32 RGB canvas, 0..255).

Alpha blending into a region of the canvas, the pixel grid of a region, antialiased polylines,
polylines densified to an even step, and rejection sampling of non-overlapping discs on the agar
(:class:`Placer`): shared by the colonies (:mod:`labauto.synthetic.plates`) and the artefacts
(:mod:`labauto.synthetic.plate_artefacts`).
"""

from __future__ import annotations

import itertools
import math

import cv2
import numpy as np

__all__ = ["Placer", "blend", "densify", "pixel_grid", "roi_box", "stroke_alpha"]


def blend(canvas: np.ndarray, alpha: np.ndarray, colour: np.ndarray, x0: int, y0: int) -> None:
    """Alpha-blend ``colour`` (broadcastable to the ROI) into the canvas at ``(x0, y0)``."""
    h, w = alpha.shape
    roi = canvas[y0 : y0 + h, x0 : x0 + w]
    a = alpha[..., None]
    roi *= 1.0 - a
    roi += a * colour


def roi_box(cx: float, cy: float, r: float, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` of the disc ``(cx, cy, r)`` with 2 px to spare, clipped to ``shape``."""
    h, w = shape
    x0, y0 = max(int(cx - r) - 2, 0), max(int(cy - r) - 2, 0)
    x1, y1 = min(int(cx + r) + 3, w), min(int(cy + r) + 3, h)
    return x0, y0, x1, y1


def pixel_grid(x0: int, y0: int, x1: int, y1: int) -> tuple[np.ndarray, np.ndarray]:
    """The x and y coordinates (float32) of every pixel of ``[x0, x1) x [y0, y1)``."""
    ys, xs = np.mgrid[y0:y1, x0:x1]
    return xs.astype(np.float32), ys.astype(np.float32)


def stroke_alpha(
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


class Placer:
    """Rejection sampling of non-overlapping discs inside the usable part of the agar."""

    def __init__(self, rng: np.random.Generator, cx: float, cy: float, r_use: float, gap: float):
        self.rng, self.cx, self.cy, self.r_use, self.gap = rng, cx, cy, r_use, gap
        self.discs: list[tuple[float, float, float]] = []

    def free(self, x: float, y: float, r: float, gap: float | None = None) -> bool:
        """Whether a disc ``(x, y, r)`` lies on the usable agar, ``gap`` clear of every disc."""
        g = self.gap if gap is None else gap
        if math.hypot(x - self.cx, y - self.cy) + r > self.r_use:
            return False
        return all(math.hypot(x - px, y - py) >= r + pr + g for px, py, pr in self.discs)

    def sample(self, r: float, tries: int = 400) -> tuple[float, float] | None:
        """A free centre for a disc of radius ``r`` (uniform on the agar), or None."""
        for _ in range(tries):
            rr = (self.r_use - r) * math.sqrt(self.rng.uniform())
            th = self.rng.uniform(0.0, 2.0 * np.pi)
            x, y = self.cx + rr * math.cos(th), self.cy + rr * math.sin(th)
            if self.free(x, y, r):
                return x, y
        return None

    def add(self, x: float, y: float, r: float) -> None:
        """Take the disc ``(x, y, r)``."""
        self.discs.append((x, y, r))

    def clear_of_colonies(self, pts: np.ndarray, half_width: float, gap: float) -> bool:
        """Whether a stroke through ``pts``, ``half_width`` wide, keeps ``gap`` from every disc."""
        for px, py, pr in self.discs:
            if np.min(np.hypot(pts[:, 0] - px, pts[:, 1] - py)) < pr + half_width + gap:
                return False
        return True


def densify(pts: np.ndarray, step: float = 2.0) -> np.ndarray:
    """The polyline ``pts`` with points inserted about every ``step`` px along each segment."""
    out = [pts[:1]]
    for p, q in itertools.pairwise(pts):
        n = max(int(np.hypot(*(q - p)) / step), 1)
        out.append(p + (q - p) * np.linspace(0, 1, n + 1)[1:, None])
    return np.concatenate(out)
