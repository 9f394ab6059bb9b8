"""The camera's pose over the deck and the pixel-to-deck map with undistortion.

A calibrated camera (intrinsics ``K`` and OpenCV distortion ``D``, :mod:`labauto.vision.
calibration`) looks at the deck. Given pairs of a pixel and the deck position (mm, machine
coordinates X, Y, Z) of the same point, the deck's pose in the camera frame is found by
``cv2.solvePnP`` (iterative, refined by ``cv2.solvePnPRefineLM``); the points may lie on one
plane (a board on the deck, the tool head at one height) or on several (the head at two
heights). Then a pixel maps to the deck by undoing the distortion (``cv2.undistortPoints``),
casting its ray from the camera centre and meeting the horizontal plane ``Z = surface_z``
(where colonies are picked), which a plane homography without a lens model cannot do.

The residual is in millimetres: every calibration pixel is mapped to the plane of its own point
(``Z`` of that point) and compared with the point's X, Y; ``residual_mm`` is the RMS of those
distances and a calibration over ``max_residual_mm`` is refused. Fewer than 6 points are refused
(4 fit any planar pose exactly, so their residual says nothing).

Deck frame: X, Y, Z of the robot's machine coordinates in mm, Z up. A sheet lying face up on the
deck with its x axis along +X has its y axis (down the page) along -Y
(:func:`board_to_deck`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

MIN_POINTS = 6


class DeckCalibrationFailed(ValueError):
    """The points cannot give a deck calibration; the message says why."""


def board_to_deck(points: np.ndarray, origin_mm: tuple, angle_deg: float = 0.0) -> np.ndarray:
    """Board points (x right, y down the page, mm) of a board lying face up on the deck.

    ``origin_mm`` is the deck position ``(X, Y, Z)`` of the board's top-left corner and
    ``angle_deg`` the turn of its x axis from +X toward +Y.
    """
    pts = np.asarray(points, np.float64)
    pts = pts.reshape(-1, pts.shape[-1])
    a = np.deg2rad(angle_deg)
    c, s = np.cos(a), np.sin(a)
    x, y = pts[:, 0], pts[:, 1]
    out = np.empty((len(pts), 3))
    out[:, 0] = origin_mm[0] + c * x + s * y
    out[:, 1] = origin_mm[1] + s * x - c * y
    out[:, 2] = origin_mm[2] if len(origin_mm) > 2 else 0.0
    return out


def residual_check(errors: np.ndarray, limit_mm: float, what: str) -> tuple[float, str | None]:
    """RMS of point errors (mm) and, when it exceeds ``limit_mm``, the message refusing it."""
    residual = float(np.sqrt(np.mean(np.square(errors))))
    if residual <= limit_mm:
        return residual, None
    worst = int(np.argmax(errors))
    return residual, (
        f"{what} residual {residual:.3f} mm exceeds the limit of {limit_mm:.3f} mm "
        f"(worst: point {worst}, {errors[worst]:.3f} mm off)"
    )


def undistort_points(
    pixels: np.ndarray, camera_matrix: np.ndarray, dist_coeffs: np.ndarray, iterations: int = 20
) -> np.ndarray:
    """Normalised undistorted coordinates (n, 2) of pixels, to 1e-6 px or better.

    ``cv2.undistortPoints`` (5 fixed-point steps) is the start; then each step moves the
    estimate by the pixel error of its reprojection mapped through ``K^-1``, until the
    reprojection matches within 1e-6 px (``cv2.projectPoints`` is exact forward).
    """
    px = np.asarray(pixels, np.float64).reshape(-1, 2)
    if not len(px):
        return np.zeros((0, 2))
    k = np.asarray(camera_matrix, np.float64)
    d = np.asarray(dist_coeffs, np.float64).ravel()
    norm = cv2.undistortPoints(px.reshape(-1, 1, 2), k, d).reshape(-1, 2)
    scale = np.array([k[0, 0], k[1, 1]])
    for _ in range(iterations):
        obj = np.column_stack((norm, np.ones(len(norm))))
        proj = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), k, d)[0].reshape(-1, 2)
        err = px - proj
        if np.abs(err).max() < 1e-6:
            break
        norm = norm + err / scale
    return norm


@dataclass(frozen=True)
class DeckCalibration:
    """A calibrated camera's pose over the deck, mapping pixels to deck millimetres.

    Attributes
    ----------
    camera_matrix, dist_coeffs : np.ndarray
        The camera's intrinsics and distortion.
    rvec, tvec : np.ndarray
        The deck frame's pose in the camera frame (``p_cam = R p_deck + t``; mm).
    surface_z : float
        Height ``Z`` (mm) of the plane that :meth:`to_deck` maps pixels onto.
    residual_mm, max_error_mm : float
        RMS and largest distance of the calibration points (see the module docstring).
    n_points : int
        Number of point pairs used.
    image_size : (int, int)
        Width and height of the images.
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    surface_z: float
    residual_mm: float
    max_error_mm: float
    n_points: int
    image_size: tuple[int, int]

    @classmethod
    def from_points(
        cls,
        pixels: np.ndarray,
        deck_mm: np.ndarray,
        camera_matrix: np.ndarray,
        dist_coeffs: np.ndarray,
        image_size: tuple[int, int],
        *,
        surface_z: float,
        max_residual_mm: float = 0.5,
    ) -> DeckCalibration:
        """Find the deck's pose from point pairs and check the residual.

        Raises
        ------
        DeckCalibrationFailed
            Fewer than 6 pairs, mismatched counts, no pose found, or a residual over
            ``max_residual_mm``.
        """
        px = np.asarray(pixels, np.float64).reshape(-1, 2)
        deck = np.asarray(deck_mm, np.float64).reshape(-1, 3)
        if len(px) != len(deck):
            raise DeckCalibrationFailed(f"{len(px)} pixels but {len(deck)} deck points")
        if len(px) < MIN_POINTS:
            raise DeckCalibrationFailed(
                f"a deck calibration needs at least {MIN_POINTS} points, got {len(px)}"
            )
        k = np.asarray(camera_matrix, np.float64)
        d = np.asarray(dist_coeffs, np.float64).ravel()
        ok, rvec, tvec = cv2.solvePnP(deck, px, k, d, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            raise DeckCalibrationFailed("no camera pose fits the points (are they degenerate?)")
        rvec, tvec = cv2.solvePnPRefineLM(deck, px, k, d, rvec, tvec)
        cal = cls(k, d, rvec.ravel(), tvec.ravel(), float(surface_z), 0.0, 0.0, len(px),
                  (int(image_size[0]), int(image_size[1])))  # fmt: skip
        errors = np.hypot(*(cal.to_deck(px, deck[:, 2]) - deck[:, :2]).T)
        residual, problem = residual_check(errors, max_residual_mm, "deck calibration")
        if problem:
            raise DeckCalibrationFailed(problem)
        return cls(k, d, cal.rvec, cal.tvec, float(surface_z), residual, float(errors.max()),
                   len(px), cal.image_size)  # fmt: skip

    @property
    def overdetermined(self) -> bool:
        """Always true: at least 6 points were used."""
        return self.n_points >= MIN_POINTS

    def _rotation(self) -> np.ndarray:
        return cv2.Rodrigues(np.asarray(self.rvec, np.float64))[0]

    def to_deck(self, pixels: np.ndarray, z: float | np.ndarray | None = None) -> np.ndarray:
        """Map (n, 2) pixels to (n, 2) deck X, Y (mm) on the plane ``Z = z`` (default the
        surface)."""
        norm = undistort_points(pixels, self.camera_matrix, self.dist_coeffs)
        rot = self._rotation()
        # ray in deck frame: origin C = -R^T t, direction R^T (x, y, 1)
        origin = -rot.T @ np.asarray(self.tvec, np.float64)
        rays = np.column_stack((norm, np.ones(len(norm)))) @ rot  # rows: R^T (x, y, 1)
        level = np.broadcast_to(self.surface_z if z is None else np.asarray(z, float), len(norm))
        s = (level - origin[2]) / rays[:, 2]
        return origin[:2] + s[:, None] * rays[:, :2]

    def to_pixels(self, deck_mm: np.ndarray) -> np.ndarray:
        """Map (n, 2) deck X, Y on the surface (or (n, 3) with Z) to (n, 2) pixels."""
        pts = np.asarray(deck_mm, np.float64)
        if pts.shape[-1] == 2:
            pts = np.column_stack((pts.reshape(-1, 2), np.full(pts.size // 2, self.surface_z)))
        img, _ = cv2.projectPoints(pts.reshape(-1, 3), self.rvec, self.tvec,
                                   self.camera_matrix, self.dist_coeffs)  # fmt: skip
        return img.reshape(-1, 2)

    def camera_position(self) -> np.ndarray:
        """The camera centre in deck coordinates (mm)."""
        return -self._rotation().T @ np.asarray(self.tvec, np.float64)

    def to_dict(self) -> dict:
        """JSON form (``labauto calibrate deck --json``)."""
        return {
            "kind": "deck",
            "residual_mm": float(self.residual_mm),
            "max_error_mm": float(self.max_error_mm),
            "n_points": int(self.n_points),
            "surface_z_mm": float(self.surface_z),
            "camera_matrix": np.asarray(self.camera_matrix, float).tolist(),
            "dist_coeffs": np.asarray(self.dist_coeffs, float).ravel().tolist(),
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "rvec": np.asarray(self.rvec, float).ravel().tolist(),
            "tvec": np.asarray(self.tvec, float).ravel().tolist(),
            "camera_position_mm": self.camera_position().tolist(),
        }

    @classmethod
    def from_dict(cls, doc: dict) -> DeckCalibration:
        """Rebuild from :meth:`to_dict` (e.g. a stored calibration's document)."""
        return cls(
            np.asarray(doc["camera_matrix"], np.float64).reshape(3, 3),
            np.asarray(doc["dist_coeffs"], np.float64).ravel(),
            np.asarray(doc["rvec"], np.float64).ravel(),
            np.asarray(doc["tvec"], np.float64).ravel(),
            float(doc["surface_z_mm"]),
            float(doc["residual_mm"]),
            float(doc.get("max_error_mm", doc["residual_mm"])),
            int(doc["n_points"]),
            (int(doc["image_size"][0]), int(doc["image_size"][1])),
        )
