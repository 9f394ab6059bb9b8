"""A stand-in for coded markers: grey disks whose grey level is their id, and their detector.

The tracker's logic (windows, full-frame searches, the id-swap guard) does not depend on how a
marker is decoded, so these tests drive it with markers that cost nothing to render and to
detect: a disk of radius ``R`` and grey ``BASE + STEP * id`` on a white background, found by
connected components. The detector works on any sub-image, like the real one, and drops a disk
cut by the image border (a partial marker has no reliable code either).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import cv2
import numpy as np

R = 9
BASE, STEP = 10, 6
SIZE = (480, 640)  # height, width


@dataclass(frozen=True)
class Blob:
    id: int
    centroid: tuple[float, float]
    center: tuple[float, float]
    ellipse: SimpleNamespace
    score: float = 1.0


def render(positions: dict[int, tuple[float, float]], size=SIZE, occluders=()) -> np.ndarray:
    """A grey frame with a disk per ``{id: (x, y)}`` (4x supersampled), occluder rects white."""
    h, w = size
    image = np.full((h, w), 255, np.uint8)
    shift = 4
    for mid, (x, y) in positions.items():
        cv2.circle(
            image,
            (round(x * 16), round(y * 16)),
            R * 16,
            BASE + STEP * mid,
            -1,
            cv2.LINE_AA,
            shift,
        )
    for x0, y0, x1, y1 in occluders:
        image[y0:y1, x0:x1] = 255
    return image


def detect_blobs(image: np.ndarray) -> list[Blob]:
    """Every whole disk of ``image`` with its id (from its grey) and centroid."""
    grey = image if image.ndim == 2 else image[..., 0]
    mask = (grey < 200).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    found = []
    h, w = grey.shape
    for label in range(1, n):
        x, y, bw, bh, area = stats[label]
        if area < 0.6 * np.pi * R * R or x == 0 or y == 0 or x + bw >= w or y + bh >= h:
            continue
        ys, xs = np.nonzero(labels[y : y + bh, x : x + bw] == label)
        weights = 255.0 - grey[y : y + bh, x : x + bw][ys, xs]
        cx = float((xs * weights).sum() / weights.sum()) + x
        cy = float((ys * weights).sum() / weights.sum()) + y
        inner = grey[y : y + bh, x : x + bw][ys, xs]
        level = float(np.median(inner))
        mid = round((level - BASE) / STEP)
        found.append(Blob(mid, (cx, cy), (cx, cy), SimpleNamespace(axes=(R, R))))
    return found


def swaps(result, truth: dict[int, tuple[float, float]], tol: float) -> int:
    """Reported markers nearer another marker's true place than ``tol`` and not their own."""
    count = 0
    for marker in result.markers:
        own = truth.get(marker.id)
        if own is not None and np.hypot(*np.subtract(marker.center, own)) <= tol:
            continue
        count += 1
    return count
