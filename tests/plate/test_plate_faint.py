"""The faint pass on hand-made agar: wide, low-contrast colonies and what is not one."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.synthetic.plates import generate_plate
from labauto.vision import plate_faint
from labauto.vision.plate import PlateParams, analyze_plate
from labauto.vision.plate_faint import faint_bodies

PX_PER_MM = 10.0
AGAR_BGR = (150.0, 190.0, 205.0)


def _agar_with_soft_disc(radius_mm: float, edge_mm: float, contrast: float) -> np.ndarray:
    """600 px of flat agar (10 px/mm, sensor noise) with a darker disc whose edge is a Gaussian
    ramp of ``edge_mm`` (sigma) and ``contrast`` grey levels deep in every channel."""
    disc = np.zeros((600, 600), np.float32)
    cv2.circle(disc, (300, 300), round(radius_mm * PX_PER_MM), 1.0, -1, cv2.LINE_AA)
    disc = cv2.GaussianBlur(disc, (0, 0), edge_mm * PX_PER_MM)
    img = np.empty((600, 600, 3), np.float32)
    img[:] = AGAR_BGR
    img -= contrast * disc[..., None]
    img += np.random.default_rng(0).normal(0.0, 2.0, img.shape)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def _found(img: np.ndarray) -> bool:
    usable = np.zeros(img.shape[:2], np.uint8)
    cv2.circle(usable, (300, 300), 290, 255, -1)
    found = faint_bodies(img, usable, np.zeros_like(usable), PX_PER_MM, margin_mm=1.0)
    return bool(found[300, 300])


def test_a_large_colony_with_a_soft_edge_is_found(monkeypatch: pytest.MonkeyPatch) -> None:
    # 8 mm across, 8 grey levels, its edge a Gaussian ramp of sigma 0.4 mm (found where it is
    # a fifth deep, the outline lies on its tail), as the large translucent colonies of AGAR
    # plates 12031 and 11924: sharp for its size, though not within a millimetre
    img = _agar_with_soft_disc(4.0, 0.4, 8.0)
    assert _found(img)
    # the former rule (an edge within a millimetre, whatever the size) missed it
    monkeypatch.setattr(plate_faint, "_EDGE_RADII", 0.0)
    monkeypatch.setattr(plate_faint, "_LEAST_EDGE", 0.25)
    assert not _found(img)


def test_a_drift_of_the_agar_is_no_colony() -> None:
    # as deep, but fading with sigma 1 mm (measured: from 0.5 mm on, nothing is found): a
    # change of the agar, not a colony's edge
    assert not _found(_agar_with_soft_disc(4.0, 1.0, 8.0))


def _textured_agar_with_hued_disc(delta_bgr: tuple[float, float, float]) -> np.ndarray:
    """600 px of agar (10 px/mm) whose brightness wanders by 4 grey levels (std) over ~0.6 mm
    blotches, as thickness and lighting do, with a 5 mm disc departing by ``delta_bgr``."""
    rng = np.random.default_rng(1)
    blotches = cv2.GaussianBlur(rng.normal(0.0, 1.0, (600, 600)).astype(np.float32), (0, 0), 6.0)
    blotches *= 4.0 / blotches.std()
    disc = np.zeros((600, 600), np.float32)
    cv2.circle(disc, (300, 300), 25, 1.0, -1, cv2.LINE_AA)
    disc = cv2.GaussianBlur(disc, (0, 0), 2.0)
    img = np.empty((600, 600, 3), np.float32)
    img[:] = AGAR_BGR
    img += blotches[..., None] + disc[..., None] * np.asarray(delta_bgr, np.float32)
    img += rng.normal(0.0, 2.0, img.shape)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def test_a_colony_departing_in_hue_only_is_found_through_the_agars_texture() -> None:
    # a yellower disc (10 levels less blue, 5 more red: its brightness changes by 1.3 levels),
    # as the small and large faint colonies of AGAR plates 11924 and 12033; the agar's
    # brightness texture lifts the full deviation's threshold above it, not the hue's
    usable = np.zeros((600, 600), np.uint8)
    cv2.circle(usable, (300, 300), 290, 255, -1)
    none = np.zeros_like(usable)

    def found(img: np.ndarray, chroma: bool) -> np.ndarray:
        return faint_bodies(img, usable, none, PX_PER_MM, margin_mm=1.0, chroma=chroma)

    img = _textured_agar_with_hued_disc((-10.0, 1.0, 5.0))
    assert not found(img, chroma=False).any()
    body = found(img, chroma=True) > 0
    disc = np.zeros_like(usable)
    cv2.circle(disc, (300, 300), 25, 255, -1)
    overlap = np.count_nonzero(body & (disc > 0))
    assert overlap >= 0.8 * np.count_nonzero(disc) and np.count_nonzero(body) <= 1.4 * overlap
    # the texture alone is no colony, in either part of the deviation
    assert not found(_textured_agar_with_hued_disc((0.0, 0.0, 0.0)), chroma=True).any()


def _agar_with_small_hued_disc(diameter_mm: float, depth: float = 1.0) -> np.ndarray:
    """600 px of flat agar (10 px/mm, sensor noise) with a disc of ``diameter_mm`` that is
    yellower (``depth`` times 12 levels less blue, 4 more red), as the small faint colonies of
    AGAR plates 11761, 11924 and 12033."""
    disc = np.zeros((600, 600), np.float32)
    cv2.circle(disc, (300, 300), round(diameter_mm * PX_PER_MM / 2), 1.0, -1, cv2.LINE_AA)
    img = np.empty((600, 600, 3), np.float32)
    img[:] = AGAR_BGR
    img += disc[..., None] * np.float32([-12.0, 0.0, 4.0]) * depth
    img += np.random.default_rng(2).normal(0.0, 2.0, img.shape)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def test_a_small_colony_departing_in_hue_is_found_below_the_grey_searchs_size() -> None:
    usable = np.zeros((600, 600), np.uint8)
    cv2.circle(usable, (300, 300), 290, 255, -1)
    none = np.zeros_like(usable)
    img = _agar_with_small_hued_disc(1.4)

    def found(**kwargs: float) -> bool:
        mask = faint_bodies(img, usable, none, PX_PER_MM, margin_mm=1.0, **kwargs)
        return bool(mask[300, 300])

    assert found()  # the hue search keeps bodies from 1 mm on
    assert not found(min_hue_diameter_mm=2.0)  # the grey search's least size would miss it


def test_a_small_hued_body_must_depart_more_than_a_large_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # a third as yellow: over the threshold, but not by the quarter more that a body under the
    # grey search's 2 mm must show (a blotch of texture or of a JPEG's colour blocks is as
    # small); 3 mm across, the same departure is a colony
    usable = np.zeros((600, 600), np.uint8)
    cv2.circle(usable, (300, 300), 290, 255, -1)
    none = np.zeros_like(usable)

    def found(diameter_mm: float) -> bool:
        img = _agar_with_small_hued_disc(diameter_mm, depth=0.32)
        return bool(faint_bodies(img, usable, none, PX_PER_MM, margin_mm=1.0)[300, 300])

    assert found(3.0)
    assert not found(1.8)
    monkeypatch.setattr(plate_faint, "_SMALL_CONTRAST", 1.0)
    assert found(1.8)


def test_a_dark_speck_smeared_by_the_smoothing_is_no_faint_body(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # the generator's dust on amber agar: a dark speck about 0.5 mm across at (855, 402),
    # too small for a colony; smoothed, it departs in hue as a disc of about a millimetre
    img, truth = generate_plate(1000, agar="amber")
    params = PlateParams(region=(*truth.dish.center, truth.dish.radius))

    def reported_at_speck() -> bool:
        centroids = np.array([c.centroid for c in analyze_plate(img, params).colonies])
        return bool((np.hypot(*(centroids - (855.0, 402.0)).T) < 4.0).any())

    assert not reported_at_speck()
    monkeypatch.setattr(plate_faint, "_MIN_SPREAD", 0.0)  # without the test: a colony
    assert reported_at_speck()
