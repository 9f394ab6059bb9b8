"""Pose of a rigid set of markers from one calibrated camera; 3D points from two cameras.

The paper's tracking application (section 4.3) computes "the actual position ... based on the
positions of the coded markers" seen by spatially calibrated cameras. Two pieces:

Pose of a rigid marker set (:func:`estimate_pose`)
    A rigid set is its markers' 3D positions (mm) in the object's own frame. With the image
    centres of at least ``min_markers`` of them and a calibrated camera (OpenCV's pinhole and
    distortion model), the pose (``rvec``, ``tvec``: object to camera) is solved by
    ``cv2.solvePnP`` (SQPnP, a global solver, no initial guess) and refined by Levenberg-
    Marquardt on the reprojection error (``cv2.solvePnPRefineLM``). The reprojection RMS says
    how well the centres fit; with ``sigma`` the per-coordinate residual (RMS scaled by
    ``sqrt(2n / (2n - 6))``), the pose's covariance is ``sigma^2 (J^T J)^-1`` with ``J`` the
    Jacobian of the projections (``cv2.projectPoints``). :attr:`Pose.std_translation_mm` and
    :attr:`Pose.std_rotation_deg` are its square roots: the error the reprojection residual
    predicts, to compare a render's true error with.
Two-camera triangulation (:func:`triangulate`)
    With two calibrated cameras (intrinsics, distortion and pose in a common world frame), each
    marker seen by both is the linear (DLT) triangulation of its undistorted centres
    (``cv2.undistortPoints``, ``cv2.triangulatePoints``), with the reprojection error in each
    view.

Pure functions over arrays; positions are pixels with the origin at the top-left pixel's
centre, which is OpenCV's convention too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["CameraView", "Pose", "TriangulatedPoint", "estimate_pose", "triangulate"]

Point2 = tuple[float, float]
Point3 = tuple[float, float, float]


@dataclass(frozen=True)
class Pose:
    """Pose of a rigid marker set in a camera's frame.

    Attributes
    ----------
    rvec, tvec : ndarray
        Rodrigues rotation and translation (mm) taking object points into the camera frame.
    ids : tuple of int
        Markers used.
    residuals_px : ndarray
        (n,) reprojection error of each marker used, pixels.
    covariance : ndarray
        (6, 6) covariance of (rvec, tvec) predicted from the residuals.
    """

    rvec: np.ndarray
    tvec: np.ndarray
    ids: tuple[int, ...]
    residuals_px: np.ndarray
    covariance: np.ndarray

    @property
    def rms_px(self) -> float:
        """Reprojection RMS, pixels."""
        return float(np.sqrt(np.mean(self.residuals_px**2)))

    @property
    def rotation(self) -> np.ndarray:
        """3x3 rotation matrix (object to camera)."""
        return cv2.Rodrigues(self.rvec)[0]

    @property
    def std_translation_mm(self) -> float:
        """Predicted standard error of the position (mm, root of the trace of its covariance)."""
        return float(math.sqrt(max(np.trace(self.covariance[3:, 3:]), 0.0)))

    @property
    def std_rotation_deg(self) -> float:
        """Predicted standard error of the rotation angle (degrees)."""
        return float(math.degrees(math.sqrt(max(np.trace(self.covariance[:3, :3]), 0.0))))

    def to_dict(self) -> dict:
        """JSON form."""
        return {
            "rvec": [float(v) for v in self.rvec],
            "tvec_mm": [float(v) for v in self.tvec],
            "markers": list(self.ids),
            "reprojection_rms_px": self.rms_px,
            "std_translation_mm": self.std_translation_mm,
            "std_rotation_deg": self.std_rotation_deg,
        }


def rotation_error_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (degrees) of the rotation between two Rodrigues vectors."""
    ra, rb = (
        cv2.Rodrigues(np.asarray(a, np.float64))[0],
        cv2.Rodrigues(np.asarray(b, np.float64))[0],
    )
    cos = (np.trace(ra.T @ rb) - 1.0) / 2.0
    return float(math.degrees(math.acos(min(max(cos, -1.0), 1.0))))


def estimate_pose(
    centers: Mapping[int, Point2],
    rigid_set: Mapping[int, Point3],
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray | None = None,
    *,
    min_markers: int = 4,
) -> Pose | None:
    """Pose of a rigid marker set from the image centres of its markers.

    Parameters
    ----------
    centers : mapping
        ``{id: (x, y)}`` image centres of markers found (others are ignored).
    rigid_set : mapping
        ``{id: (x, y, z)}`` the set's markers in its own frame, mm.
    camera_matrix, dist_coeffs : ndarray
        The camera's intrinsics and OpenCV distortion coefficients.
    min_markers : int
        Fewest markers of the set that must be seen (>= 4).

    Returns
    -------
    Pose or None
        ``None`` when fewer than ``min_markers`` markers of the set are seen.
    """
    if min_markers < 4:
        raise ValueError(f"min_markers must be >= 4, got {min_markers}")
    ids = tuple(sorted(mid for mid in centers if mid in rigid_set))
    if len(ids) < min_markers:
        return None
    obj = np.array([rigid_set[mid] for mid in ids], np.float64).reshape(-1, 1, 3)
    img = np.array([centers[mid] for mid in ids], np.float64).reshape(-1, 1, 2)
    k = np.asarray(camera_matrix, np.float64)
    d = np.zeros(5) if dist_coeffs is None else np.asarray(dist_coeffs, np.float64).ravel()
    ok, rvec, tvec = cv2.solvePnP(obj, img, k, d, flags=cv2.SOLVEPNP_SQPNP)
    if not ok:
        return None
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, k, d, rvec, tvec)
    projected, jacobian = cv2.projectPoints(obj, rvec, tvec, k, d)
    residuals = np.hypot(*(projected - img).reshape(-1, 2).T)
    n = len(ids)
    dof = max(2 * n - 6, 1)
    sigma2 = float(np.sum(residuals**2)) / dof
    j = jacobian[:, :6]
    try:
        covariance = sigma2 * np.linalg.inv(j.T @ j)
    except np.linalg.LinAlgError:
        covariance = np.full((6, 6), np.inf)
    return Pose(rvec.ravel(), tvec.ravel(), ids, residuals, covariance)


@dataclass(frozen=True)
class CameraView:
    """A calibrated camera: intrinsics, distortion and pose (world to camera)."""

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray | None
    rvec: np.ndarray
    tvec: np.ndarray

    def projection(self) -> np.ndarray:
        """3x4 ``[R | t]`` in normalised (undistorted) image coordinates."""
        r = cv2.Rodrigues(np.asarray(self.rvec, np.float64))[0]
        return np.hstack((r, np.asarray(self.tvec, np.float64).reshape(3, 1)))

    def normalised(self, pixels: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates of (n, 2) pixels."""
        d = None if self.dist_coeffs is None else np.asarray(self.dist_coeffs, np.float64)
        pts = np.asarray(pixels, np.float64).reshape(-1, 1, 2)
        return cv2.undistortPoints(pts, np.asarray(self.camera_matrix, np.float64), d).reshape(
            -1, 2
        )

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels of (n, 3) world points."""
        d = np.zeros(5) if self.dist_coeffs is None else np.asarray(self.dist_coeffs, np.float64)
        img, _ = cv2.projectPoints(
            np.asarray(points, np.float64).reshape(-1, 1, 3),
            np.asarray(self.rvec, np.float64),
            np.asarray(self.tvec, np.float64),
            np.asarray(self.camera_matrix, np.float64),
            d,
        )
        return img.reshape(-1, 2)


@dataclass(frozen=True)
class TriangulatedPoint:
    """A marker's 3D position (world frame, mm) and its reprojection error in both views."""

    id: int
    position: Point3
    errors_px: tuple[float, float]

    def to_dict(self) -> dict:
        """JSON form."""
        return {
            "id": self.id,
            "position_mm": [float(v) for v in self.position],
            "reprojection_px": [float(e) for e in self.errors_px],
        }


def triangulate(
    centers_a: Mapping[int, Point2],
    centers_b: Mapping[int, Point2],
    view_a: CameraView,
    view_b: CameraView,
) -> list[TriangulatedPoint]:
    """3D positions of the markers seen in both views (see the module docstring)."""
    ids = sorted(set(centers_a) & set(centers_b))
    if not ids:
        return []
    pa = view_a.normalised(np.array([centers_a[i] for i in ids]))
    pb = view_b.normalised(np.array([centers_b[i] for i in ids]))
    homogeneous = cv2.triangulatePoints(view_a.projection(), view_b.projection(), pa.T, pb.T)
    points = (homogeneous[:3] / homogeneous[3]).T
    err_a = np.hypot(*(view_a.project(points) - [centers_a[i] for i in ids]).T)
    err_b = np.hypot(*(view_b.project(points) - [centers_b[i] for i in ids]).T)
    return [
        TriangulatedPoint(mid, tuple(float(v) for v in p), (float(ea), float(eb)))  # type: ignore[arg-type]
        for mid, p, ea, eb in zip(ids, points, err_a, err_b, strict=True)
    ]
