"""Calibration files in OpenCV's FileStorage YAML, so other tools read them.

Written with ``cv2.FileStorage`` itself: ``camera_matrix`` (3x3), ``distortion_coefficients``
(1xN), ``image_width``, ``image_height``, ``rms_px`` and, for a deck calibration, ``rvec``,
``tvec`` (the deck's pose in the camera frame, mm) and ``residual_mm``; OpenCV's own
calibration samples use the same names.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from labauto.errors import LabautoError


class CalibrationFileError(LabautoError):
    """A calibration file cannot be written."""


def write_opencv_yaml(path: str | Path, document: dict) -> Path:
    """Write a calibration document (``calibrate camera|deck --json``) as FileStorage YAML."""
    path = Path(path)
    if path.suffix.lower() not in (".yaml", ".yml", ".xml", ".json"):
        raise CalibrationFileError(f"{path}: use a .yaml, .yml, .xml or .json file name")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CalibrationFileError(f"{path.parent}: cannot create ({exc.strerror})") from None
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    if not fs.isOpened():
        raise CalibrationFileError(f"{path}: cannot write")
    try:
        width, height = document["image_size"]
        fs.write("image_width", int(width))
        fs.write("image_height", int(height))
        fs.write("camera_matrix", np.asarray(document["camera_matrix"], np.float64))
        dist = np.asarray(document["dist_coeffs"], np.float64).reshape(1, -1)
        fs.write("distortion_coefficients", dist)
        if document.get("rms_px") is not None:
            fs.write("rms_px", float(document["rms_px"]))
        for key in ("rvec", "tvec"):
            if key in document:
                fs.write(key, np.asarray(document[key], np.float64).reshape(3, 1))
        if document.get("residual_mm") is not None:
            fs.write("residual_mm", float(document["residual_mm"]))
    finally:
        fs.release()
    return path
