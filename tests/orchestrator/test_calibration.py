"""Pixel-to-deck calibration: exact recovery, residual reporting and refusal."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.errors import CalibrationError
from labauto.orchestrator.calibration import Calibration

TRUE_H = np.array([[0.1, 0.002, 20.0], [-0.001, 0.1, 15.0], [1e-6, 2e-6, 1.0]])
PIXELS = np.array([[0, 0], [1279, 0], [1279, 1023], [0, 1023], [640, 512], [300, 800]], float)


def deck_of(pixels: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(pixels.reshape(-1, 1, 2), TRUE_H).reshape(-1, 2)


def test_exact_points_recover_the_homography():
    calibration = Calibration.from_points(PIXELS, deck_of(PIXELS))
    assert calibration.residual_mm < 1e-4 and calibration.overdetermined
    probe = np.array([[123.4, 567.8], [1000.0, 20.0]])
    np.testing.assert_allclose(calibration.to_deck(probe), deck_of(probe), atol=1e-6)
    np.testing.assert_allclose(calibration.to_pixels(deck_of(probe)), probe, atol=1e-4)


def test_residual_is_reported_for_noisy_points():
    rng = np.random.default_rng(1)
    noisy = deck_of(PIXELS) + rng.normal(0, 0.05, PIXELS.shape)
    calibration = Calibration.from_points(PIXELS, noisy)
    assert 0.005 < calibration.residual_mm < 0.1
    assert calibration.max_error_mm >= calibration.residual_mm


def test_too_large_residual_is_refused_and_names_the_worst_point():
    deck = deck_of(PIXELS)
    deck[5] += (3.0, 0.0)
    with pytest.raises(CalibrationError, match=r"exceeds the limit of 0\.500 mm \(worst: point 5"):
        Calibration.from_points(PIXELS, deck, max_residual_mm=0.5)


@pytest.mark.parametrize(
    ("pixels", "message"),
    [
        (PIXELS[:3], "at least 4 point pairs, got 3"),
        (np.array([[0, 0], [1, 1], [2, 2], [3, 3]], float), "degenerate"),
    ],
)
def test_bad_point_sets_are_refused(pixels, message):
    with pytest.raises(CalibrationError, match=message):
        Calibration.from_points(pixels, deck_of(pixels))
