"""Print on a coarse frame (a webcam's): its dots have merged, its colour still tells it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.vision import plate_ink
from labauto.vision.plate import PlateParams, analyze_plate
from labauto.vision.plate_bodies import measure_bodies

PX_PER_MM = 6.0  # coarser than min_analysis_px_per_mm: resampled up for the analysis
AGAR_BGR = (120, 180, 205)
CREAM_BGR = (60, 110, 170)  # takes more blue than red away: a pigmented colony
GREY_BGR = (70, 80, 85)  # takes a like share of every channel away: as ink does
SINGLES = [(80, 80), (280, 80), (80, 280), (180, 100), (100, 180)]


def _frame(
    colony_bgr: tuple[int, int, int],
    printed: bool,
    spots: tuple[tuple[int, int], ...] = (*SINGLES, (250, 260), (260, 260)),
) -> np.ndarray:
    """360 px at 6 px/mm: colonies 2 mm across at ``spots`` (by default five and a touching
    pair), and optionally a printed "38" (2.5 mm tall, dark grey), all blurred as a webcam's
    optics do."""
    img = np.zeros((360, 360, 3), np.uint8)
    img[:] = AGAR_BGR
    for x, y in spots:
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


def test_merged_print_on_a_sparse_plate_is_ink(monkeypatch: pytest.MonkeyPatch) -> None:
    # two colonies, too few single colonies to tell whether the plate's colonies are grey, and
    # two printed characters blurred into one dark grey blob (two discs of 1.2 mm radius): its
    # colour and its shape, no single colony's, say print
    img = _frame(CREAM_BGR, printed=False, spots=tuple(SINGLES[:2]))
    for x in (160, 170):
        cv2.circle(img, (x, 200), 7, (55, 80, 90), -1, cv2.LINE_AA)
    img = cv2.GaussianBlur(img, (0, 0), 1.0)  # the blob as blurred as the rest
    assert _counts(img) == ([1, 1], 1)
    # judged only with three single colonies or more, the blob was counted as two colonies
    monkeypatch.setattr(plate_ink, "MIN_SINGLES", 0)
    monkeypatch.setattr(plate_ink, "INK_SINGLES", 0.0)
    assert _counts(img) == ([1, 1, 2], 0)


def test_a_plate_of_grey_colonies_keeps_its_pairs(monkeypatch: pytest.MonkeyPatch) -> None:
    # every colony is ink-coloured: colour cannot tell print here, the pair stays counted
    img = _frame(GREY_BGR, printed=False)
    assert _counts(img) == ([1, 1, 1, 1, 1, 2], 0)
    monkeypatch.setattr(plate_ink, "INK_SINGLES", 1.01)  # the rule used regardless
    assert _counts(img) == ([1, 1, 1, 1, 1], 1)


DARK_AGAR_BGR = np.array([60.0, 66.0, 70.0])  # a dark plate's agar, as the 2048 px AGAR photos


def _faint_bodies(dot_bgr: np.ndarray, dotted: bool = True) -> tuple[np.ndarray, float]:
    """``ink_bodies`` of one body of radius 30 px (12 px/mm) on the dark agar: a dot-matrix
    character's dots blurred into one body by the faint pass (dots of 2 px radius, 7 px apart,
    of the colour ``dot_bgr``), or the same darkening spread evenly over it; and the body's
    mean darkening."""
    rng = np.random.default_rng(1)
    roi = np.tile(DARK_AGAR_BGR, (100, 100, 1))
    disc = np.zeros((100, 100), np.uint8)
    cv2.circle(disc, (50, 50), 30, 1, -1)
    dots = np.zeros_like(disc)
    for y in range(22, 80, 7):
        for x in range(22, 80, 7):
            cv2.circle(dots, (x, y), 2, 1, -1)
    dots &= disc
    if dotted:
        roi[dots > 0] = dot_bgr
    else:  # the dots' darkening spread over the whole body
        share = dots.sum() / disc.sum()
        roi[disc > 0] = DARK_AGAR_BGR + share * (dot_bgr - DARK_AGAR_BGR)
    roi = np.clip(roi + rng.normal(0.0, 1.0, roi.shape), 0, 255).astype(np.uint8)
    background = np.tile(DARK_AGAR_BGR, (100, 100, 1)).astype(np.uint8)
    contours, _ = cv2.findContours(disc, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    params = PlateParams(
        px_per_mm=12.0, min_colony_area_px=10.0, max_colony_area_px=1e6, min_width_px=1.0
    )
    bodies = measure_bodies(list(contours), disc * 255, np.zeros(1, bool), params, {})
    darkening = 1.0 - float(roi[disc > 0].astype(float).sum() / (DARK_AGAR_BGR.sum() * disc.sum()))
    return plate_ink.ink_bodies(roi, background, bodies, np.ones(1, bool), 12.0), darkening


def test_faint_dot_matrix_print_on_dark_agar_is_ink(monkeypatch: pytest.MonkeyPatch) -> None:
    grey_dots = 0.75 * DARK_AGAR_BGR  # a quarter of every channel's light taken away
    ink, darkening = _faint_bodies(grey_dots)
    assert 0.05 < darkening < 0.10  # dark enough for a dotted body, not for any ink body
    assert ink.tolist() == [True]
    # the same darkening spread evenly (a faint grey colony) is solid: no print
    assert _faint_bodies(grey_dots, dotted=False)[0].tolist() == [False]
    # yellow dots (more blue than red taken away: pigment) are no print either
    assert _faint_bodies(DARK_AGAR_BGR * [0.6, 0.75, 0.85])[0].tolist() == [False]
    # with the least darkening of every ink body, the dotted print was counted as a colony
    monkeypatch.setattr(plate_ink, "INK_DOTTED_DARKER", plate_ink.INK_DARKER)
    assert _faint_bodies(grey_dots)[0].tolist() == [False]
