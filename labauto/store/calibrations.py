"""Stored calibrations: save, find the one in force, list (table ``calibrations``).

Functions over an engine (e.g. ``Store.open(url).engine``), one transaction each. Several rows
may share a name; the newest (highest id) is the one in force.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from .models import CalibrationRecord

KINDS = ("camera", "deck")


@dataclass(frozen=True)
class StoredCalibration:
    """A calibration as stored."""

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
        return cls(
            row.id,
            row.name,
            row.kind,
            row.created_at,
            (row.image_width, row.image_height),
            row.rms_px,
            row.residual_mm,
            np.asarray(row.camera_matrix, np.float64).reshape(3, 3),
            np.asarray(row.dist_coeffs, np.float64).ravel(),
            dict(row.data or {}),
        )


def save_calibration(
    engine: Engine, name: str, kind: str, document: dict[str, Any], residual_mm: float | None = None
) -> StoredCalibration:
    """Store a calibration document (the ``--json`` of ``calibrate camera`` or ``deck``).

    The document needs ``camera_matrix``, ``dist_coeffs`` and ``image_size``; ``rms_px`` is
    taken when present.
    """
    if kind not in KINDS:
        raise ValueError(f"calibration kind must be one of {KINDS}, got {kind!r}")
    if not name or len(name) > 200:
        raise ValueError(f"calibration name must be 1-200 characters, got {name!r}")
    width, height = document["image_size"]
    row = CalibrationRecord(
        name=name,
        kind=kind,
        image_width=int(width),
        image_height=int(height),
        rms_px=None if document.get("rms_px") is None else float(document["rms_px"]),
        residual_mm=None if residual_mm is None else float(residual_mm),
        camera_matrix=np.asarray(document["camera_matrix"], float).tolist(),
        dist_coeffs=np.asarray(document["dist_coeffs"], float).ravel().tolist(),
        data=document,
    )
    with Session(engine, expire_on_commit=False) as session, session.begin():
        session.add(row)
    return StoredCalibration._of(row)


def load_calibration(
    engine: Engine, name: str | None = None, kind: str | None = None
) -> StoredCalibration | None:
    """The newest calibration of that name (and kind), or of any name; None when there is none."""
    query = select(CalibrationRecord).order_by(CalibrationRecord.id.desc()).limit(1)
    if name is not None:
        query = query.where(CalibrationRecord.name == name)
    if kind is not None:
        query = query.where(CalibrationRecord.kind == kind)
    with Session(engine) as session:
        row = session.scalars(query).first()
        return None if row is None else StoredCalibration._of(row)


def list_calibrations(engine: Engine) -> list[StoredCalibration]:
    """Every stored calibration, oldest first."""
    with Session(engine) as session:
        rows = session.scalars(select(CalibrationRecord).order_by(CalibrationRecord.id)).all()
        return [StoredCalibration._of(r) for r in rows]
