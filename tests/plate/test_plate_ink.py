"""Print on a coarse frame (a webcam's): its dots have merged, its colour still tells it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.vision import plate_ink
from labauto.vision.plate import PlateParams, analyze_plate

PX_PER_MM = 6.0  # coarser than min_analysis_px_per_mm: resampled up for the analysis
AGAR_BGR = (120, 180, 205)
CREAM_BGR = (60, 110, 170)  # takes more blue than red away: a pigmented colony
GREY_BGR = (70, 80, 85)  # takes a like share of every channel away: as ink does
SINGLES = [(80, 80), (280, 80), (80, 280), (180, 100), (100, 180)]


def _frame(colony_bgr: tuple[int, int, int], printed: bool) -> np.ndarray:
    """360 px at 6 px/mm: five colonies 2 mm across, a touching pair, and optionally a printed
    "38" (2.5 mm tall, dark grey), all blurred as a webcam's optics do."""
    img = np.zeros((360, 360, 3), np.uint8)
    img[:] = AGAR_BGR
    for x, y in [*SINGLES, (250, 260), (260, 260)]:
        cv2.circle(img, (x, y), 6, colony_bgr, -1, cv2.LINE_AA)
    if printed:
        cv2.putText(img, "38", (150, 200), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (55, 80, 90), 3)
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    noise = np.random.default_rng(0).normal(0.0, 2.0, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


def _counts(img: np.ndarray) -> tuple[list[int], int]:
    result = analyze_plate(img, PlateParams(region=(180.0, 180.0, 175.0), px_per_mm=PX_PER_MM))
    counts = sorted(c.estimated_count for c in result.colonies)
    return counts, result.rejected.get("ink", 0)


def test_blurred_print_among_pigmented_colonies_is_ink(monkeypatch: pytest.MonkeyPatch) -> None:
    img = _frame(CREAM_BGR, printed=True)
    assert _counts(img) == ([1, 1, 1, 1, 1, 2], 1)
    # without the coarse-frame rule the merged dots are counted as colonies
    monkeypatch.setattr(plate_ink, "INK_SINGLES", 0.0)
    counts, ink = _counts(img)
    assert sum(counts) > 7 and ink == 0


def test_a_plate_of_grey_colonies_keeps_its_pairs(monkeypatch: pytest.MonkeyPatch) -> None:
    # every colony is ink-coloured: colour cannot tell print here, the pair stays counted
    img = _frame(GREY_BGR, printed=False)
    assert _counts(img) == ([1, 1, 1, 1, 1, 2], 0)
    monkeypatch.setattr(plate_ink, "INK_SINGLES", 1.01)  # the rule used regardless
    assert _counts(img) == ([1, 1, 1, 1, 1], 1)
