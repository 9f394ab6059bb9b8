"""Stored calibrations: save, find the one in force, list (table ``calibrations``).

Part of :class:`~labauto.store.Store` (see :mod:`labauto.store.repository` for the rules every
method follows, with two exceptions: ``save_calibration`` returns the stored calibration, not
only its id, and :class:`StoredCalibration` holds numpy matrices and has no ``to_dict()``).
Several rows may share a name; the newest (highest id) is the one in force.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np
from sqlalchemy import select

from .base import StoreBase
from .errors import InvalidValue
from .models import CalibrationRecord
from .rows import json_data

__all__ = ["KINDS", "CalibrationStore", "StoredCalibration"]

#: The kinds of calibration the store keeps.
KINDS = ("camera", "deck")


def _matrix(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``value`` as a float64 array of ``shape`` (``(-1,)``: any length), else InvalidValue."""
    try:
        return np.asarray(value, np.float64).reshape(shape)
    except (TypeError, ValueError) as exc:
        raise InvalidValue(f"{what}: not a {'x'.join(map(str, shape))} matrix: {exc}") from None


@dataclass(frozen=True)
class StoredCalibration:
    """A calibration as stored (a frozen copy of its row, like the store's records).

    Attributes
    ----------
    id, name, kind : int, str, str
        The row's id, its name and ``"camera"`` or ``"deck"``.
    created_at : datetime
        When it was stored (aware UTC).
    image_size : (width, height)
        Pixels.
    rms_px, residual_mm : float or None
        The camera calibration's reprojection RMS, the deck calibration's residual.
    camera_matrix, dist_coeffs : np.ndarray
        3x3 intrinsics and the flat distortion coefficients (OpenCV's model).
    data : dict
        The whole document it was stored from.
    """

    id: int
    name: str
    kind: str
    created_at: datetime
    image_size: tuple[int, int]
    rms_px: float | None
    residual_mm: float | None
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    data: dict

    @classmethod
    def _of(cls, row: CalibrationRecord) -> StoredCalibration:
        what = f"stored calibration {row.name!r} (id {row.id})"
        return cls(
            row.id,
            row.name,
            row.kind,
            row.created_at,
            (row.image_width, row.image_height),
            row.rms_px,
            row.residual_mm,
            _matrix(row.camera_matrix, (3, 3), f"{what} camera_matrix"),
            _matrix(row.dist_coeffs, (-1,), f"{what} dist_coeffs"),
            dict(row.data or {}),
        )


def _row(
    name: str, kind: str, document: Mapping[str, Any], residual_mm: float | None
) -> CalibrationRecord:
    """The row of a calibration document (see :meth:`CalibrationStore.save_calibration`)."""
    if kind not in KINDS:
        raise InvalidValue(f"calibration kind must be one of {KINDS}, got {kind!r}")
    if not name or len(name) > 200:
        raise InvalidValue(f"calibration name must be 1-200 characters, got {name!r}")
    what = f"calibration {name!r}"
    missing = [key for key in ("camera_matrix", "dist_coeffs", "image_size") if key not in document]
    if missing:
        raise InvalidValue(f"{what}: the document has no {', '.join(missing)}")
    try:
        width, height = (int(v) for v in document["image_size"])
        rms_px = None if document.get("rms_px") is None else float(document["rms_px"])
        residual = None if residual_mm is None else float(residual_mm)
    except (TypeError, ValueError) as exc:
        raise InvalidValue(
            f"{what}: image_size, rms_px or residual_mm is not a number: {exc}"
        ) from None
    return CalibrationRecord(
        name=name,
        kind=kind,
        image_width=width,
        image_height=height,
        rms_px=rms_px,
        residual_mm=residual,
        camera_matrix=_matrix(document["camera_matrix"], (3, 3), f"{what} camera_matrix").tolist(),
        dist_coeffs=_matrix(document["dist_coeffs"], (-1,), f"{what} dist_coeffs").tolist(),
        data=json_data(dict(document), f"{what} document"),
    )


class CalibrationStore(StoreBase):
    """Camera and deck calibrations, by name; the newest of a name is the one in force."""

    def save_calibration(
        self,
        name: str,
        kind: str,
        document: Mapping[str, Any],
        residual_mm: float | None = None,
    ) -> StoredCalibration:
        """Store a calibration document (the ``--json`` of ``calibrate camera`` or ``deck``).

        Parameters
        ----------
        name : str
            1-200 characters; a calibration stored later under the same name replaces it.
        kind : str
            ``"camera"`` or ``"deck"``.
        document : mapping
            Needs ``camera_matrix`` (3x3), ``dist_coeffs`` and ``image_size`` (width, height);
            ``rms_px`` is taken when present. It is stored whole.
        residual_mm : float, optional
            A deck calibration's residual.

        Raises
        ------
        InvalidValue
            An unknown kind, an empty or long name, or a document without those fields (the
            message names them).
        """
        row = _row(name, kind, document, residual_mm)
        with self._write("save_calibration") as session:
            session.add(row)
            session.flush()
            return StoredCalibration._of(row)

    def latest_calibration(
        self, name: str | None = None, kind: str | None = None
    ) -> StoredCalibration | None:
        """The newest calibration of that name and kind (either may be any), or ``None``."""
        query = select(CalibrationRecord).order_by(CalibrationRecord.id.desc()).limit(1)
        if name is not None:
            query = query.where(CalibrationRecord.name == name)
        if kind is not None:
            query = query.where(CalibrationRecord.kind == kind)
        with self._read() as session:
            row = session.scalars(query).first()
            return None if row is None else StoredCalibration._of(row)

    def list_calibrations(self) -> list[StoredCalibration]:
        """Every stored calibration, oldest first."""
        with self._read() as session:
            rows = session.scalars(select(CalibrationRecord).order_by(CalibrationRecord.id))
            return [StoredCalibration._of(row) for row in rows]
