"""SQLAlchemy 2 models: everything a colony-picking run saw and did.

Tables: ``plates``, ``images``, ``runs``, ``detections``, ``colonies``, ``picks``,
``analyzer_results``, ``events``. The Alembic migrations in ``labauto.migrations`` create exactly
this schema (a test compares them with ``alembic.autogenerate.compare_metadata``).

Conventions
-----------
* Timestamps are :class:`~labauto.store.types.UTCDateTime`: stored in UTC, read back aware.
* States and classes are Python ``StrEnum`` members stored as their string values in a
  ``VARCHAR`` with a named ``CHECK`` constraint (``sqlalchemy.Enum(native_enum=False)``), so
  the schema is the same on every backend and autogenerate stays clean.
* Free-form structured data (run config, colony contours, analyzer values, event data) is JSON.
* Coordinates are pixels, origin at the top-left pixel's centre, x right, y down; ellipse angles
  in degrees from +x toward +y (DESIGN.md). Deck positions are millimetres.
* Constraint names follow :data:`NAMING_CONVENTION`, which Alembic's batch mode on SQLite needs.

Choices
------------------------
* ``plates.name`` is unique: a plate's name is its label (barcode), so adding a plate again
  returns the stored one.
* ``images.run_id`` (nullable) records the run that captured the image and ``images.position``
  the plate's place in that run (0, 1, ... in camera order); ``(run_id, position)`` is unique, so
  a run that resumes after a crash finds each plate by its place, never by its pixels (two
  plates with byte-identical images are still two plates).
* ``runs.config_hash`` ties a run to its effective config; ``runs.lease_*`` is the lease of the
  process that owns the run (pid, host, a random token and the last heartbeat).
* ``picks.colony_id`` must name a colony of the same run (checked by the repository).
"""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    Enum,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from .states import ColonyClass, PickState, RunState
from .types import UTCDateTime, utcnow

NAMING_CONVENTION: dict[str, str] = {
    "ix": "ix_%(table_name)s_%(column_0_N_name)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}
"""Names for indexes and constraints, so migrations can refer to them on every backend."""


def _enum_column_type(enum_class: type[StrEnum], name: str) -> Enum:
    """A VARCHAR column type with a CHECK constraint that stores the enum's string values."""
    return Enum(
        enum_class,
        name=name,
        native_enum=False,
        create_constraint=True,
        length=max(len(member.value) for member in enum_class),
        values_callable=lambda members: [member.value for member in members],
        validate_strings=True,
    )


class Base(DeclarativeBase):
    """Declarative base of every labauto table."""

    metadata = MetaData(naming_convention=NAMING_CONVENTION)


class Plate(Base):
    """A petri dish. ``name`` is its label; ``source`` is an image path or a camera id."""

    __tablename__ = "plates"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    source: Mapped[str | None] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)


class Run(Base):
    """One colony-picking run and its state (see :mod:`labauto.store.states`)."""

    __tablename__ = "runs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    state: Mapped[RunState] = mapped_column(
        _enum_column_type(RunState, "run_state"), default=RunState.IDLE, index=True
    )
    config: Mapped[Any | None] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime)
    error: Mapped[str | None] = mapped_column(Text)
    config_hash: Mapped[str | None] = mapped_column(String(64))
    lease_token: Mapped[str | None] = mapped_column(String(64))
    lease_pid: Mapped[int | None] = mapped_column(Integer)
    lease_host: Mapped[str | None] = mapped_column(String(255))
    lease_heartbeat_at: Mapped[datetime | None] = mapped_column(UTCDateTime)


class Image(Base):
    """A camera image of a plate. ``sha256`` is the hex digest of the image's pixels.

    ``position`` is the plate's place in its run (camera order); it, not the digest, identifies
    the plate within the run.
    """

    __tablename__ = "images"
    __table_args__ = (UniqueConstraint("run_id", "position"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    plate_id: Mapped[int] = mapped_column(ForeignKey("plates.id"), index=True)
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"))
    path: Mapped[str] = mapped_column(Text)
    width: Mapped[int] = mapped_column(Integer)
    height: Mapped[int] = mapped_column(Integer)
    sha256: Mapped[str] = mapped_column(String(64), index=True)
    captured_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    position: Mapped[int | None] = mapped_column(Integer)


class Detection(Base):
    """One object found on an image by the D_alpha detector (Teutsch et al.).

    ``d_alpha_*`` are the shape angle statistics as the detector reports them; ``is_des`` says
    whether the object passed as a deformed elliptic shape; ``shape`` is the detector's shape
    label; ``ellipse_*`` is the fitted ellipse (semi-axes ``a >= b``, angle in degrees), NULL
    when no ellipse was fitted.
    """

    __tablename__ = "detections"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"), index=True)
    image_id: Mapped[int] = mapped_column(ForeignKey("images.id"), index=True)
    object_index: Mapped[int] = mapped_column(Integer)
    method: Mapped[str] = mapped_column(String(32))
    centroid_x: Mapped[float] = mapped_column(Float)
    centroid_y: Mapped[float] = mapped_column(Float)
    n_points: Mapped[int] = mapped_column(Integer)
    closed: Mapped[bool] = mapped_column(Boolean)
    d_alpha_median: Mapped[float | None] = mapped_column(Float)
    d_alpha_mean: Mapped[float | None] = mapped_column(Float)
    centroid_inside: Mapped[bool | None] = mapped_column(Boolean)
    is_des: Mapped[bool] = mapped_column(Boolean)
    shape: Mapped[str | None] = mapped_column(String(32))
    ellipse_cx: Mapped[float | None] = mapped_column(Float)
    ellipse_cy: Mapped[float | None] = mapped_column(Float)
    ellipse_a: Mapped[float | None] = mapped_column(Float)
    ellipse_b: Mapped[float | None] = mapped_column(Float)
    ellipse_angle: Mapped[float | None] = mapped_column(Float)
    area_px: Mapped[float | None] = mapped_column(Float)


class Colony(Base):
    """A colony chosen from the detections of an image, with its class and contour.

    ``contour`` is a JSON list of ``[x, y]`` pixel points; ``estimated_count`` is the number of
    colonies the body is thought to hold (1 for an authentic colony). ``mix_score`` (beyond the
    contract) keeps the colour/texture evidence behind the ``mixed`` class for the audit.
    """

    __tablename__ = "colonies"
    __table_args__ = (Index(None, "run_id", "image_id"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"))
    image_id: Mapped[int] = mapped_column(ForeignKey("images.id"), index=True)
    detection_id: Mapped[int | None] = mapped_column(ForeignKey("detections.id"), index=True)
    colony_index: Mapped[int] = mapped_column(Integer)
    klass: Mapped[ColonyClass] = mapped_column(_enum_column_type(ColonyClass, "colony_class"))
    centroid_x: Mapped[float] = mapped_column(Float)
    centroid_y: Mapped[float] = mapped_column(Float)
    area_px: Mapped[float | None] = mapped_column(Float)
    d_alpha_median: Mapped[float | None] = mapped_column(Float)
    estimated_count: Mapped[int] = mapped_column(Integer, default=1)
    mix_score: Mapped[float | None] = mapped_column(Float)
    contour: Mapped[Any | None] = mapped_column(JSON)


class Pick(Base):
    """One colony taken (or to be taken) by the robot to the analyzer during a run.

    ``UNIQUE(run_id, colony_id)``: no colony is planned twice in a run. ``needs_attention`` flags
    a pick the operator must look at (set with the ``unknown`` state after a crash).
    """

    __tablename__ = "picks"
    __table_args__ = (
        UniqueConstraint("run_id", "colony_id"),
        Index(None, "run_id", "state"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"))
    colony_id: Mapped[int] = mapped_column(ForeignKey("colonies.id"), index=True)
    sequence: Mapped[int] = mapped_column(Integer)
    state: Mapped[PickState] = mapped_column(
        _enum_column_type(PickState, "pick_state"), default=PickState.PLANNED
    )
    deck_x_mm: Mapped[float | None] = mapped_column(Float)
    deck_y_mm: Mapped[float | None] = mapped_column(Float)
    sample_id: Mapped[str | None] = mapped_column(String(100))
    needs_attention: Mapped[bool] = mapped_column(Boolean, default=False)
    error: Mapped[str | None] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow, onupdate=utcnow)


class AnalyzerResult(Base):
    """What the analyzer reported for one pick's sample (at most one result per pick)."""

    __tablename__ = "analyzer_results"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    pick_id: Mapped[int] = mapped_column(ForeignKey("picks.id"), unique=True)
    sample_id: Mapped[str] = mapped_column(String(100))
    values: Mapped[Any | None] = mapped_column(JSON)
    error_code: Mapped[int | None] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)


class Event(Base):
    """One line of the audit log: a state change, a step, a device exchange.

    ``kind`` is dotted, e.g. ``run.state``, ``pick.state``, ``plate.analyzed``, ``robot.tx``,
    ``robot.rx``, ``analyzer.tx``; ``source`` names who wrote it.
    """

    __tablename__ = "events"
    __table_args__ = (Index(None, "run_id", "kind"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int | None] = mapped_column(ForeignKey("runs.id"))
    ts: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    kind: Mapped[str] = mapped_column(String(64))
    source: Mapped[str] = mapped_column(String(64))
    message: Mapped[str] = mapped_column(Text)
    data: Mapped[Any | None] = mapped_column(JSON)


class CalibrationRecord(Base):
    """A stored camera or deck calibration (``labauto calibrate camera|deck --save NAME``).

    ``kind`` is ``camera`` (intrinsics and distortion) or ``deck`` (a camera calibration plus
    the camera's pose over the deck). Several rows may share a name: the newest is the one in
    force. ``data`` keeps the whole JSON document of the calibration (views, pose, residuals).
    """

    __tablename__ = "calibrations"
    __table_args__ = (Index(None, "name"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    kind: Mapped[str] = mapped_column(String(16))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)
    image_width: Mapped[int] = mapped_column(Integer)
    image_height: Mapped[int] = mapped_column(Integer)
    rms_px: Mapped[float | None] = mapped_column(Float)
    residual_mm: Mapped[float | None] = mapped_column(Float)
    camera_matrix: Mapped[Any] = mapped_column(JSON)
    dist_coeffs: Mapped[Any] = mapped_column(JSON)
    data: Mapped[Any | None] = mapped_column(JSON)
