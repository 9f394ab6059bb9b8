"""Camera calibration from board views (the paper's section 4.2, automated).

The paper calibrates "with boards ... with coded markers. With the known code of each marker, a
unique mapping from the world to the image coordinate system is possible", the markers' centres
being as precise as the ellipse fit makes them. Here:

1. every view's pairs of image and board points (:mod:`labauto.vision.board_points`);
2. views with fewer than ``min_points`` pairs are set aside with the reason;
3. ``cv2.calibrateCamera`` (OpenCV's pinhole model with radial k1, k2, k3 and tangential p1, p2
   distortion) on the remaining views;
4. a view whose reprojection RMS exceeds ``max(max_view_rms_px, 3 x the median view RMS)`` is
   set aside (the worst one at a time, then the camera is calibrated again);
5. for circle grids, whose centres are the centres of their image ellipses, the perspective bias
   is removed from the pose (Heikkila, PAMI 2000): with the views' poses, every circle of radius
   ``circle_radius_mm`` is projected as a conic (undistorted pixels), the gap between its
   ellipse's centre and the projected centre is subtracted from the measured point, and the
   camera is calibrated again (three rounds). Coded markers and ring grids need no such step:
   their centres come bias-free from concentric circles.

Fewer than ``min_views`` usable views is an error that says how many were usable and why the
others were not.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from labauto.vision.concentric import conic_to_ellipse


class CalibrationFailed(ValueError):
    """The views cannot calibrate the camera; the message says why, on one line."""


@dataclass(frozen=True)
class ViewPoints:
    """One view's point pairs (``reason`` says why it has none, e.g. no board found)."""

    name: str
    image_points: np.ndarray
    object_points: np.ndarray
    reason: str | None = None


@dataclass(frozen=True)
class ViewResult:
    """How one view served the calibration."""

    image: str
    markers: int
    rms_px: float | None
    used: bool
    reason: str | None

    def to_dict(self) -> dict:
        return {
            "image": self.image,
            "markers": int(self.markers),
            "rms_px": None if self.rms_px is None else float(self.rms_px),
            "used": bool(self.used),
            "reason": self.reason,
        }


@dataclass(frozen=True)
class CameraCalibration:
    """Intrinsics and distortion of a camera, and how each view fitted.

    ``rvecs``/``tvecs`` are the poses of the used views (in their order in ``views``).
    """

    rms_px: float
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    views: list[ViewResult]
    rvecs: list[np.ndarray] = field(default_factory=list, repr=False)
    tvecs: list[np.ndarray] = field(default_factory=list, repr=False)

    def to_dict(self) -> dict:
        """The ``labauto calibrate camera --json`` document."""
        return {
            "rms_px": float(self.rms_px),
            "camera_matrix": np.asarray(self.camera_matrix, float).tolist(),
            "dist_coeffs": np.asarray(self.dist_coeffs, float).ravel().tolist(),
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "views": [v.to_dict() for v in self.views],
        }


def _fit(views: list[ViewPoints], size: tuple[int, int], flags: int):
    obj = [v.object_points.astype(np.float32).reshape(-1, 1, 3) for v in views]
    img = [v.image_points.astype(np.float32).reshape(-1, 1, 2) for v in views]
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, k, d, rvecs, tvecs = cv2.calibrateCamera(
        obj, img, size, None, None, flags=flags, criteria=criteria
    )
    errors = []
    for v, r, t in zip(views, rvecs, tvecs, strict=True):
        proj, _ = cv2.projectPoints(v.object_points.astype(np.float64), r, t, k, d)
        diff = proj.reshape(-1, 2) - v.image_points
        errors.append(float(np.sqrt(np.mean(np.sum(diff**2, axis=1)))))
    return float(rms), k, d, list(rvecs), list(tvecs), errors


def circle_bias(
    object_points: np.ndarray,
    radius_mm: float,
    camera_matrix: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
) -> np.ndarray:
    """(n, 2) gap between the image ellipse's centre of each board circle and its projected
    centre, in undistorted pixels (the perspective bias of an ellipse centre)."""
    rot, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    out = np.empty((len(object_points), 2))
    for k, (x, y, _) in enumerate(np.asarray(object_points, np.float64)):
        # plane coordinates centred on the circle: p = (x + u, y + v, 0)
        h = camera_matrix @ np.column_stack(
            (rot[:, 0], rot[:, 1], rot @ [x, y, 0.0] + np.ravel(tvec))
        )
        hi = np.linalg.inv(h)
        conic = hi.T @ np.diag([1.0, 1.0, -(radius_mm**2)]) @ hi
        ellipse = conic_to_ellipse(conic)
        centre = h[:, 2] / h[2, 2]
        out[k] = (
            (0.0, 0.0)
            if ellipse is None
            else (ellipse.center[0] - centre[0], ellipse.center[1] - centre[1])
        )
    return out


def calibrate_camera(
    views: Sequence[ViewPoints],
    image_size: tuple[int, int],
    *,
    min_points: int = 8,
    min_views: int = 3,
    max_view_rms_px: float = 1.0,
    circle_radius_mm: float | None = None,
    flags: int = 0,
) -> CameraCalibration:
    """Calibrate a camera from board views.

    Parameters
    ----------
    views : sequence of ViewPoints
        Every image's point pairs (those without points carry their reason).
    image_size : (width, height)
        Size of the images.
    min_points : int
        Least pairs for a view to be used.
    min_views : int
        Least usable views.
    max_view_rms_px : float
        A view whose RMS exceeds this and 3 times the median view RMS is set aside.
    circle_radius_mm : float, optional
        The radius of a circle grid's circles: remove their centres' perspective bias.
    flags : int
        ``cv2.calibrateCamera`` flags.

    Raises
    ------
    CalibrationFailed
        Too few usable views (the message names how many and why the others are not).
    """
    # views are told apart by their place in ``views``: two may share a name
    reasons: dict[int, str] = {}
    usable: list[int] = []
    for i, v in enumerate(views):
        if v.reason is not None:
            reasons[i] = v.reason
        elif len(v.image_points) < min_points:
            reasons[i] = f"only {len(v.image_points)} board points (needs {min_points})"
        else:
            usable.append(i)
    _need(usable, views, reasons, min_views)
    while True:
        rms, k, d, rvecs, tvecs, errors = _fit([views[i] for i in usable], image_size, flags)
        limit = max(max_view_rms_px, 3.0 * float(np.median(errors)))
        worst = int(np.argmax(errors))
        if errors[worst] <= limit or len(usable) <= min_views:
            break
        reasons[usable[worst]] = (
            f"reprojection RMS {errors[worst]:.3f} px, over {limit:.3f} px (an outlier)"
        )
        usable.pop(worst)
    if circle_radius_mm is not None:
        fitted = [views[i] for i in usable]
        measured = [v.image_points for v in fitted]
        for _ in range(3):
            fitted = [
                ViewPoints(
                    v.name, m - _bias_in_image(v, circle_radius_mm, k, d, r, t), v.object_points
                )
                for v, m, r, t in zip(fitted, measured, rvecs, tvecs, strict=True)
            ]
            rms, k, d, rvecs, tvecs, errors = _fit(fitted, image_size, flags)
    error_of = dict(zip(usable, errors, strict=True))
    results = [
        ViewResult(
            v.name,
            len(v.image_points),
            error_of.get(i),
            i in error_of,
            None if i in error_of else reasons.get(i),
        )
        for i, v in enumerate(views)
    ]
    return CameraCalibration(
        rms, k, d.ravel(), (int(image_size[0]), int(image_size[1])), results, rvecs, tvecs
    )


def _bias_in_image(
    view: ViewPoints,
    radius: float,
    k: np.ndarray,
    d: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
) -> np.ndarray:
    """The circles' bias moved from undistorted to distorted pixels (by the local map)."""
    gap = circle_bias(view.object_points, radius, k, rvec, tvec)
    proj, _ = cv2.projectPoints(view.object_points.astype(np.float64), rvec, tvec, k, d)
    ideal, _ = cv2.projectPoints(view.object_points.astype(np.float64), rvec, tvec, k, None)
    ideal = ideal.reshape(-1, 2)
    shifted = ideal + gap
    norm = cv2.undistortPoints(shifted.reshape(-1, 1, 2), k, None).reshape(-1, 2)
    moved = cv2.projectPoints(
        np.column_stack((norm, np.ones(len(norm)))), np.zeros(3), np.zeros(3), k, d
    )[0].reshape(-1, 2)
    return moved - proj.reshape(-1, 2)


def _need(
    usable: list[int], views: Sequence[ViewPoints], reasons: dict[int, str], min_views: int
) -> None:
    if len(usable) >= min_views:
        return
    why = Counter(reasons.values())  # every view not usable has its reason
    detail = "; ".join(f"{n} x {r}" for r, n in why.most_common(3))
    if not views:
        detail = "no views given"
    elif not detail:
        detail = f"every view showed the board; give at least {min_views} views"
    raise CalibrationFailed(
        f"too few usable views: {len(usable)} of {len(views)} (needs {min_views}): {detail}"
    )
