"""Pixel-to-deck calibration: a homography from point pairs, with its residual.

The camera looks down on a flat deck, so image pixels map to deck millimetres by a plane
homography H (3x3). It is estimated by least squares (``cv2.findHomography`` with method 0) from
four or more pairs of a pixel position and its deck position (fiducials on the deck or points
configured by hand). The residual is the RMS distance, in millimetres, between each configured deck
point and where H maps its pixel; a calibration whose residual exceeds ``max_residual_mm`` is
refused. With exactly four pairs the homography fits them exactly and the residual is 0 by
construction, which says nothing about its quality: ``overdetermined`` tells the two cases apart.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from labauto.errors import CalibrationError
from labauto.vision.deck import DeckCalibration, residual_check

if TYPE_CHECKING:
    from labauto.store.calibrations import CalibrationStore


@dataclass(frozen=True)
class Calibration:
    """A pixel-to-deck homography and how well it fits its points.

    Attributes
    ----------
    homography : ndarray
        3x3 matrix mapping homogeneous pixel coordinates to deck millimetres.
    residual_mm : float
        RMS reprojection error of the calibration points, in millimetres.
    max_error_mm : float
        Largest reprojection error of one point, in millimetres.
    n_points : int
        Number of point pairs used.
    """

    homography: np.ndarray
    residual_mm: float
    max_error_mm: float
    n_points: int

    @property
    def overdetermined(self) -> bool:
        """True when more than four points were used, so the residual is meaningful."""
        return self.n_points > 4

    @classmethod
    def from_points(
        cls, pixels: np.ndarray, deck_mm: np.ndarray, max_residual_mm: float = 0.5
    ) -> Calibration:
        """Estimate the homography from point pairs and check its residual.

        Parameters
        ----------
        pixels : ndarray
            (n, 2) pixel positions, n >= 4.
        deck_mm : ndarray
            (n, 2) deck positions in millimetres of the same points.
        max_residual_mm : float
            Largest RMS residual accepted.

        Raises
        ------
        CalibrationError
            Fewer than four pairs, a degenerate set (e.g. collinear points), or a residual over
            ``max_residual_mm``.
        """
        src = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        dst = np.asarray(deck_mm, dtype=np.float64).reshape(-1, 2)
        if len(src) != len(dst):
            raise CalibrationError(f"{len(src)} pixel points but {len(dst)} deck points")
        if len(src) < 4:
            raise CalibrationError(f"a homography needs at least 4 point pairs, got {len(src)}")
        if _collinear(src) or _collinear(dst):
            raise CalibrationError("calibration points are degenerate (collinear or repeated)")
        homography, _ = cv2.findHomography(src, dst, 0)
        if homography is None or not np.all(np.isfinite(homography)):
            raise CalibrationError("calibration points are degenerate (collinear or repeated)")
        errors = np.linalg.norm(_apply(homography, src) - dst, axis=1)
        residual, problem = residual_check(errors, max_residual_mm, "calibration")
        if problem:
            raise CalibrationError(problem)
        return cls(homography, residual, float(errors.max()), len(src))

    def to_deck(self, pixels: np.ndarray) -> np.ndarray:
        """Map (n, 2) pixel positions to (n, 2) deck positions in millimetres."""
        return _apply(self.homography, np.asarray(pixels, dtype=np.float64).reshape(-1, 2))

    def to_pixels(self, deck_mm: np.ndarray) -> np.ndarray:
        """Map (n, 2) deck positions in millimetres back to pixel positions."""
        inverse = np.linalg.inv(self.homography)
        return _apply(inverse, np.asarray(deck_mm, dtype=np.float64).reshape(-1, 2))

    def to_dict(self) -> dict:
        """JSON form: the matrix and the residuals."""
        return {
            "homography": self.homography.tolist(),
            "residual_mm": self.residual_mm,
            "max_error_mm": self.max_error_mm,
            "n_points": self.n_points,
        }


def _collinear(points: np.ndarray) -> bool:
    """True when the points do not span the plane (all on one line, or repeated)."""
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(spread[1] <= 1e-9 * max(spread[0], 1.0))


def _apply(homography: np.ndarray, points: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(points.reshape(-1, 1, 2), homography).reshape(-1, 2)


#: What to do about a stored deck calibration that a run refuses.
REDO_DECK = "calibrate the deck again (labauto calibrate deck) or set calibration.use_stored: false"


def stored_deck_calibration(config: Any, store: CalibrationStore) -> DeckCalibration | None:
    """The stored deck calibration a run uses, or None (then the homography of the config).

    ``calibration.use_stored`` on and a stored ``deck`` calibration named
    ``calibration.deck.name``: it is used if its residual is within
    ``calibration.max_residual_mm``, else refused.

    Raises
    ------
    CalibrationError
        The stored calibration cannot be read, or its residual is over the limit (one line
        naming it and what to do).
    """
    if not config.calibration.use_stored:
        return None
    name = config.calibration.deck.name
    stored = store.latest_calibration(name, "deck")
    if stored is None:
        return None
    try:
        deck = DeckCalibration.from_dict(stored.data)
    except (KeyError, TypeError, ValueError) as exc:
        problem = f"no {exc}" if isinstance(exc, KeyError) else str(exc)
        raise CalibrationError(
            f"stored deck calibration {name!r} (id {stored.id}) cannot be read ({problem}): "
            + REDO_DECK
        ) from None
    limit = config.calibration.max_residual_mm
    if deck.residual_mm > limit:
        raise CalibrationError(
            f"stored deck calibration {name!r} (id {stored.id}) has a residual of "
            f"{deck.residual_mm:.3f} mm, over the limit of {limit:.3f} mm: " + REDO_DECK
        )
    return deck
