"""Files ``labauto track`` reads besides its frames: the rigid marker set and the camera.

Rigid set (``--board FILE.yaml``), any of:

* a coded board description as ``labauto markers board`` writes it:
  ``{type: coded, markers: [{id: 3, center_mm: [x, y]}, ...]}`` (a flat board, z = 0);
* ``{markers: [{id: 3, position_mm: [x, y, z]}, ...]}``;
* a mapping ``{3: [x, y, z], 4: [x, y, z], ...}`` (also under ``markers:``).

Camera (``--calibration FILE``): ``camera_matrix`` (3x3) and ``dist_coeffs`` from an OpenCV
FileStorage file (YAML, XML or JSON, as ``labauto calibrate camera --out`` writes it; also
``distortion_coefficients``, OpenCV's sample name) or from the JSON of
``labauto calibrate camera --json``. For two-camera triangulation (``--stereo``) each file also
gives the camera's pose in the common world frame: ``rvec`` (Rodrigues) and ``tvec`` (mm),
world to camera.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from labauto.errors import LabautoError
from labauto.safeyaml import YamlRefused, read_yaml_file
from labauto.vision.pose import CameraView

__all__ = ["CameraIntrinsics", "InputError", "read_camera", "read_camera_view", "read_rigid_set"]

CameraIntrinsics = tuple[np.ndarray, np.ndarray]


class InputError(LabautoError):
    """A board or calibration file is missing or malformed (the message names it)."""


def read_rigid_set(path: str | Path) -> dict[int, tuple[float, float, float]]:
    """``{id: (x, y, z)}`` in mm from a board or rigid-set YAML file (module docstring)."""
    try:
        data = read_yaml_file(path, what="board file")
    except FileNotFoundError:
        raise InputError(f"{path}: board file not found") from None
    except (YamlRefused, OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the board file ({exc})") from None
    except Exception as exc:  # yaml.YAMLError
        raise InputError(f"{path}: board file is not valid YAML ({type(exc).__name__})") from None
    markers = data.get("markers", data) if isinstance(data, dict) else None
    out: dict[int, tuple[float, float, float]] = {}
    if isinstance(markers, dict):
        entries = [{"id": k, "position_mm": v} for k, v in markers.items()]
    elif isinstance(markers, list):
        entries = markers
    else:
        raise InputError(f"{path}: expected markers as a list or a mapping of id -> [x, y, z]")
    for n, entry in enumerate(entries):
        where = f"{path}: markers[{n}]"
        if not isinstance(entry, dict) or "id" not in entry:
            raise InputError(f"{where}: expected a mapping with an id")
        position = entry.get("position_mm", entry.get("center_mm"))
        if not isinstance(position, list | tuple) or len(position) not in (2, 3):
            raise InputError(f"{where}: expected center_mm [x, y] or position_mm [x, y, z]")
        try:
            mid = int(entry["id"])
            xyz = tuple(float(v) for v in (*position, 0.0)[:3])
        except (TypeError, ValueError):
            raise InputError(f"{where}: id and coordinates must be numbers") from None
        if not all(math.isfinite(v) for v in xyz):
            raise InputError(f"{where}: coordinates must be finite")
        if mid in out:
            raise InputError(f"{where}: id {mid} appears twice")
        out[mid] = xyz  # type: ignore[assignment]
    if not out:
        raise InputError(f"{path}: board has no markers")
    return out


def read_camera(path: str | Path) -> CameraIntrinsics:
    """``(camera_matrix, dist_coeffs)`` from a calibration file (module docstring)."""
    fields = _read_fields(Path(path), ("camera_matrix", "dist_coeffs"))
    try:
        k = np.asarray(fields["camera_matrix"], np.float64).reshape(3, 3)
        d = np.asarray(
            fields["dist_coeffs"] if fields["dist_coeffs"] is not None else [], np.float64
        )
    except (TypeError, ValueError):
        raise InputError(f"{path}: expected camera_matrix (3x3) and dist_coeffs") from None
    d = d.ravel()
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(d))) or k[0, 0] <= 0 or k[1, 1] <= 0:
        raise InputError(f"{path}: camera_matrix must be finite with positive focal lengths")
    return k, d


def read_camera_view(path: str | Path) -> CameraView:
    """A calibrated camera with its pose in the world frame (``rvec``, ``tvec``)."""
    k, d = read_camera(path)
    fields = _read_fields(Path(path), ("rvec", "tvec"))
    try:
        rvec = np.asarray(fields["rvec"], np.float64).reshape(3)
        tvec = np.asarray(fields["tvec"], np.float64).reshape(3)
    except (TypeError, ValueError):
        raise InputError(
            f"{path}: --stereo needs the camera's pose: rvec and tvec (3 numbers each)"
        ) from None
    if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))):
        raise InputError(f"{path}: rvec and tvec must be finite")
    return CameraView(k, d, rvec, tvec)


def _read_fields(path: Path, names: tuple[str, ...]) -> dict[str, Any]:
    """The named matrices of a calibration file, ``None`` where absent."""
    if not path.is_file():
        raise InputError(f"{path}: calibration file not found")
    if path.suffix.lower() == ".json":
        try:
            data: dict[str, Any] = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"{path}: cannot read the calibration JSON ({exc})") from None
        if not isinstance(data, dict):
            raise InputError(f"{path}: expected a JSON object")
        if not _opencv_json(data):
            return {name: data.get(name) for name in names}
        # else the JSON flavour of FileStorage (``calibrate ... --out FILE.json``): read below
    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error:
        raise InputError(f"{path}: not an OpenCV FileStorage file") from None
    try:
        out = {name: storage.getNode(name).mat() for name in names}
        if "dist_coeffs" in out and out["dist_coeffs"] is None:
            out["dist_coeffs"] = storage.getNode("distortion_coefficients").mat()
        return out
    finally:
        storage.release()


def _opencv_json(data: dict[str, Any]) -> bool:
    """True for JSON written by ``cv2.FileStorage`` (its matrices are ``opencv-matrix`` objects)."""
    return any(isinstance(v, dict) and v.get("type_id") == "opencv-matrix" for v in data.values())
