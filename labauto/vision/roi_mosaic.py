"""Search windows packed into one mosaic image, so a detector runs once for all of them.

A tracker that searches each marker only in a small window around its predicted position would
call the detector once per window: with 35 markers the per-call overhead (array set-up,
bookkeeping, Python) would cost more than the pixels. Instead the windows are copied side by
side into one small image (a *mosaic*) and the detector runs on it once; what it finds is mapped
back to frame coordinates by each window's integer offset (exact: no resampling).

Each window is padded by ``gap`` pixels replicated from its own border (``BORDER_REPLICATE``),
so a uniform background continues smoothly into the padding and the seams make no edges; only
an object cut by its window's border makes an edge there, and such a partial object is
discarded by :func:`owner_of` (its centre would not be well inside its window anyway).

Windows are placed on shelves (rows) in the order given, left to right, a new shelf when the
next window would pass ``max_width``. Overlapping windows are first merged into their bounding
rectangle (:func:`merge_overlapping`), so two markers close together are searched once, in one
piece, and neither is cut at the other's window border.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["Mosaic", "build_mosaic", "clip_rect", "merge_overlapping"]

#: A window ``(x0, y0, x1, y1)`` in integer frame pixels, half-open: columns x0..x1-1.
Rect = tuple[int, int, int, int]


def clip_rect(rect: Rect, width: int, height: int) -> Rect | None:
    """``rect`` clipped to a ``width`` x ``height`` frame, ``None`` if nothing is left."""
    x0, y0, x1, y1 = rect
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, width), min(y1, height)
    if x1 <= x0 or y1 <= y0:
        return None
    return (x0, y0, x1, y1)


def merge_overlapping(rects: list[Rect]) -> list[Rect]:
    """Merge overlapping (or touching) rectangles into their bounding boxes until none overlap."""
    boxes = [list(r) for r in rects]
    alive = [True] * len(rects)
    changed = True
    while changed:
        changed = False
        for i in range(len(boxes)):
            if not alive[i]:
                continue
            for j in range(i + 1, len(boxes)):
                if not alive[j]:
                    continue
                a, b = boxes[i], boxes[j]
                if a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]:
                    boxes[i] = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])]
                    alive[j] = False
                    changed = True
    return [tuple(boxes[i]) for i in range(len(boxes)) if alive[i]]  # type: ignore[misc]


@dataclass(frozen=True)
class Mosaic:
    """A mosaic of windows and where each window sits in it.

    Attributes
    ----------
    image : ndarray
        The mosaic (same dtype and channels as the frame).
    rects : list of Rect
        The frame window of each tile.
    offsets : ndarray
        (n, 2) integer offset of each tile: frame point p lies at p + offset in the mosaic.
    tiles : ndarray
        (n, 4) each tile's window in mosaic pixels ``(x0, y0, x1, y1)`` (padding excluded).
    """

    image: np.ndarray
    rects: list[Rect]
    offsets: np.ndarray
    tiles: np.ndarray

    def owners(self, points: np.ndarray) -> np.ndarray:
        """(n,) index of the tile whose window holds each mosaic point, -1 for the padding."""
        p = np.asarray(points, np.float64).reshape(-1, 1, 2)
        t = self.tiles[None, :, :]
        inside = (
            (p[..., 0] >= t[..., 0] - 0.5)
            & (p[..., 0] <= t[..., 2] - 0.5)
            & (p[..., 1] >= t[..., 1] - 0.5)
            & (p[..., 1] <= t[..., 3] - 0.5)
        )
        return np.where(inside.any(axis=1), inside.argmax(axis=1), -1)

    def owner_of(self, point: tuple[float, float]) -> int | None:
        """The tile whose window contains mosaic ``point``, or None (in the padding)."""
        tile = int(self.owners(np.asarray(point))[0])
        return tile if tile >= 0 else None

    def to_frame(self, tile: int, point: tuple[float, float]) -> tuple[float, float]:
        """Mosaic ``point`` of ``tile`` in frame pixels."""
        dx, dy = self.offsets[tile]
        return (float(point[0] - dx), float(point[1] - dy))


def build_mosaic(
    image: np.ndarray, rects: list[Rect], gap: int = 4, max_width: int = 1024
) -> Mosaic:
    """Copy the windows ``rects`` of ``image`` into one mosaic (see the module docstring).

    Parameters
    ----------
    image : ndarray
        The frame, (H, W) or (H, W, C).
    rects : list of Rect
        Windows inside the frame (already clipped), ``(x0, y0, x1, y1)``.
    gap : int
        Replicated padding around each tile, pixels.
    max_width : int
        Width at which a new shelf starts (a wider window gets a shelf of its own).
    """
    placements: list[tuple[int, int]] = []
    x = y = shelf_h = width = 0
    for x0, y0, x1, y1 in rects:
        w, h = x1 - x0 + 2 * gap, y1 - y0 + 2 * gap
        if x > 0 and x + w > max_width:
            x, y, shelf_h = 0, y + shelf_h, 0
        placements.append((x, y))
        x += w
        shelf_h = max(shelf_h, h)
        width = max(width, x)
    height = y + shelf_h
    canvas = np.zeros((max(height, 1), max(width, 1), *image.shape[2:]), dtype=image.dtype)
    offsets = np.zeros((len(rects), 2), dtype=np.int64)
    tiles = np.zeros((len(rects), 4), dtype=np.int64)
    for i, ((x0, y0, x1, y1), (px, py)) in enumerate(zip(rects, placements, strict=True)):
        tile = cv2.copyMakeBorder(image[y0:y1, x0:x1], gap, gap, gap, gap, cv2.BORDER_REPLICATE)
        canvas[py : py + tile.shape[0], px : px + tile.shape[1]] = tile
        offsets[i] = (px + gap - x0, py + gap - y0)
        tiles[i] = (px + gap, py + gap, px + gap + x1 - x0, py + gap + y1 - y0)
    return Mosaic(canvas, list(rects), offsets, tiles)
