"""Plain, frozen snapshots of stored rows, as the :class:`~labauto.store.Store` returns them.

The store never hands out live ORM objects: a record is a copy taken when it was read, safe to
keep after the session is gone and to pass between threads. Change stored data through the
``Store`` methods only. Timestamps are aware UTC datetimes; states are the enums of
:mod:`labauto.store.states` (which compare equal to their string values).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from datetime import datetime
from enum import Enum
from typing import Any, TypeVar

from .states import ColonyClass, PickState, RunState


def _jsonable(value: Any) -> Any:
    if isinstance(value, Record):
        return value.to_dict()
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, datetime):
        return value.isoformat()
    if isinstance(value, dict):
        return {_jsonable(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    return value


class Record:
    """Base of the records: adds :meth:`to_dict`."""

    def to_dict(self) -> dict[str, Any]:
        """Return the record as JSON-ready data: ISO 8601 timestamps, enums as their values."""
        return {f.name: _jsonable(getattr(self, f.name)) for f in fields(self)}  # type: ignore[arg-type]


@dataclass(frozen=True)
class PlateRecord(Record):
    """A stored plate."""

    id: int
    name: str
    source: str | None
    created_at: datetime


@dataclass(frozen=True)
class ImageRecord(Record):
    """A stored image of a plate, captured during run ``run_id`` (or outside any run)."""

    id: int
    plate_id: int
    run_id: int | None
    path: str
    width: int
    height: int
    sha256: str
    captured_at: datetime
    position: int | None = None


@dataclass(frozen=True)
class RunRecord(Record):
    """A stored run. ``config`` is the run's configuration as JSON data."""

    id: int
    name: str
    state: RunState
    config: Any
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    error: str | None
    config_hash: str | None = None
    lease_token: str | None = None
    lease_pid: int | None = None
    lease_host: str | None = None
    lease_heartbeat_at: datetime | None = None


@dataclass(frozen=True)
class StoredPlate(Record):
    """What :meth:`Store.store_plate` wrote for one plate, ids in the order of the given rows."""

    plate_id: int
    image_id: int
    detection_ids: list[int]
    colony_ids: list[int]
    pick_ids: list[int]


@dataclass(frozen=True)
class RunSummary(Record):
    """A run with the number of its picks in each state (states without picks are absent).

    ``to_dict()`` gives ``{"run": {...}, "picks_by_state": {"planned": 3, ...}}``.
    """

    run: RunRecord
    picks_by_state: dict[PickState, int] = field(default_factory=dict)

    @property
    def picks_total(self) -> int:
        """Number of picks planned in the run."""
        return sum(self.picks_by_state.values())


@dataclass(frozen=True)
class DetectionRecord(Record):
    """A stored detection (see :class:`labauto.store.models.Detection` for the columns)."""

    id: int
    run_id: int | None
    image_id: int
    object_index: int
    method: str
    centroid_x: float
    centroid_y: float
    n_points: int
    closed: bool
    d_alpha_median: float | None
    d_alpha_mean: float | None
    centroid_inside: bool | None
    is_des: bool
    shape: str | None
    ellipse_cx: float | None
    ellipse_cy: float | None
    ellipse_a: float | None
    ellipse_b: float | None
    ellipse_angle: float | None
    area_px: float | None


@dataclass(frozen=True)
class ColonyRecord(Record):
    """A stored colony. ``contour`` is a list of ``[x, y]`` pixel points (or ``None``)."""

    id: int
    run_id: int
    image_id: int
    detection_id: int | None
    colony_index: int
    klass: ColonyClass
    centroid_x: float
    centroid_y: float
    area_px: float | None
    d_alpha_median: float | None
    estimated_count: int
    mix_score: float | None
    contour: Any


@dataclass(frozen=True)
class PickRecord(Record):
    """A stored pick."""

    id: int
    run_id: int
    colony_id: int
    sequence: int
    state: PickState
    deck_x_mm: float | None
    deck_y_mm: float | None
    sample_id: str | None
    needs_attention: bool
    error: str | None
    created_at: datetime
    updated_at: datetime


@dataclass(frozen=True)
class AnalyzerResultRecord(Record):
    """A stored analyzer result; ``values`` is JSON data, ``error_code`` the analyzer's own."""

    id: int
    pick_id: int
    sample_id: str
    values: Any
    error_code: int | None
    created_at: datetime


@dataclass(frozen=True)
class EventRecord(Record):
    """A stored audit-log event."""

    id: int
    run_id: int | None
    ts: datetime
    kind: str
    source: str
    message: str
    data: Any


R = TypeVar("R")


def to_record(record_class: type[R], row: Any) -> R:
    """Copy the attributes named by ``record_class``'s fields from an ORM object or row."""
    return record_class(**{f.name: getattr(row, f.name) for f in fields(record_class)})  # type: ignore[arg-type]
