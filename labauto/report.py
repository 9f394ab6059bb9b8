"""Operator output for a plate: an annotated image and a CSV of its colonies.

As in Figure 4 of the paper, every colony's contour is drawn in the colour of its class, with its
id beside it; picked colonies get a ring around them as well. The colours (BGR) are chosen to stay
apart on light and dark agars and for the common colour-vision deficiencies.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from labauto.imageio import write_image

#: Contour colour of each class (BGR).
CLASS_COLOURS: dict[str, tuple[int, int, int]] = {
    "authentic": (80, 220, 60),  # green
    "merged": (0, 140, 255),  # orange
    "mixed": (255, 60, 200),  # purple
}
PICKED_COLOUR: tuple[int, int, int] = (255, 255, 255)  # white ring
CSV_COLUMNS = (
    "id",
    "class",
    "centroid_x",
    "centroid_y",
    "area_px",
    "d_alpha_median",
    "estimated_count",
    "picked",
)


def annotate_plate(image: np.ndarray, result: Any, picked: Iterable[int] = ()) -> np.ndarray:
    """Draw the colonies of a ``PlateResult`` on a copy of ``image``.

    Parameters
    ----------
    image : ndarray
        The plate image (BGR or grey).
    result : PlateResult
        Its analysis.
    picked : iterable of int
        Ids (``Colony.id``) of the colonies that were picked.

    Returns
    -------
    ndarray
        A BGR image with contours, ids, picked rings and a legend.
    """
    canvas = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    picked = set(picked)
    scale = max(canvas.shape[:2]) / 1280.0
    thickness = max(1, round(2 * scale))
    for colony in result.colonies:
        colour = CLASS_COLOURS.get(colony.klass, (200, 200, 200))
        contour = np.round(np.asarray(colony.contour)).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(canvas, [contour], True, colour, thickness, cv2.LINE_AA)
        x, y = (round(float(v)) for v in colony.centroid)
        radius = int(np.sqrt(colony.area_px / np.pi))
        if colony.id in picked:
            cv2.circle(canvas, (x, y), radius + 6, PICKED_COLOUR, thickness, cv2.LINE_AA)
        cv2.putText(
            canvas,
            str(colony.id),
            (x + radius + 4, y - radius),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.5 * scale,
            colour,
            thickness,
            cv2.LINE_AA,
        )
    _legend(canvas, result, len(picked & {c.id for c in result.colonies}), scale)
    return canvas


def _legend(canvas: np.ndarray, result: Any, n_picked: int, scale: float) -> None:
    counts = result.counts
    lines = [
        (f"authentic {counts['authentic']}", CLASS_COLOURS["authentic"]),
        (f"merged {counts['merged']}", CLASS_COLOURS["merged"]),
        (f"mixed {counts['mixed']}", CLASS_COLOURS["mixed"]),
        (f"picked {n_picked}", PICKED_COLOUR),
    ]
    height = int(24 * scale)
    cv2.rectangle(canvas, (0, 0), (int(190 * scale), height * len(lines) + 8), (0, 0, 0), -1)
    for row, (text, colour) in enumerate(lines):
        cv2.putText(
            canvas,
            text,
            (8, height * (row + 1)),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.6 * scale,
            colour,
            max(1, round(2 * scale)),
            cv2.LINE_AA,
        )


def write_colonies_csv(path: str | Path, result: Any, picked: Iterable[int] = ()) -> Path:
    """Write one row per colony (``CSV_COLUMNS``) to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    picked = set(picked)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(CSV_COLUMNS)
        for c in result.colonies:
            writer.writerow(
                [
                    c.id,
                    c.klass,
                    f"{c.centroid[0]:.2f}",
                    f"{c.centroid[1]:.2f}",
                    f"{c.area_px:.1f}",
                    f"{c.d_alpha_median:.2f}",
                    c.estimated_count,
                    int(c.id in picked),
                ]
            )
    return path


def write_plate_outputs(
    folder: str | Path, plate_name: str, image: np.ndarray, result: Any, picked: Iterable[int]
) -> tuple[Path, Path]:
    """Write ``<plate>.annotated.png`` and ``<plate>.colonies.csv`` into ``folder``."""
    folder = Path(folder)
    picked = set(picked)
    png = write_image(folder / f"{plate_name}.annotated.png", annotate_plate(image, result, picked))
    table = write_colonies_csv(folder / f"{plate_name}.colonies.csv", result, picked)
    return png, table
