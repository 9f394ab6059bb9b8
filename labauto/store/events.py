"""The audit log: events of a run, written one at a time or in batches, and followed.

Part of :class:`~labauto.store.Store` (see :mod:`labauto.store.repository` for the rules every
method follows).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from datetime import datetime
from typing import Any

from sqlalchemy import and_, func, insert, select

from .base import StoreBase
from .errors import InvalidValue
from .models import Event
from .records import EventRecord, to_record
from .rows import json_data
from .types import utcnow


def event_rows(
    run_id: int | None, events: Sequence[Mapping[str, Any]], now: datetime
) -> list[dict[str, Any]]:
    """Rows for one insert of ``events`` (see :meth:`EventStore.record_events`).

    Raises
    ------
    InvalidValue
        An event without a kind, or data that is not JSON-able (names the event).
    """
    rows = []
    for position, event in enumerate(events):
        if not event.get("kind"):
            raise InvalidValue(f"event {position}: kind must not be empty")
        rows.append(
            {
                "run_id": run_id,
                "kind": event["kind"],
                "source": event.get("source", "orchestrator"),
                "message": event["message"],
                "data": json_data(event.get("data"), f"event {position} data"),
                "ts": event.get("ts") or now,
            }
        )
    return rows


class EventStore(StoreBase):
    """Audit events."""

    def record_event(
        self,
        run_id: int | None,
        kind: str,
        message: str,
        source: str = "orchestrator",
        data: Any = None,
    ) -> int:
        """Append an event to the audit log and return its id.

        Parameters
        ----------
        run_id : int or None
            The run it belongs to (``None``: not part of a run).
        kind : str
            Dotted kind, e.g. ``"plate.analyzed"``, ``"robot.tx"``, ``"analyzer.rx"``.
        message : str
            Human-readable text (for a device exchange: the line sent or received).
        source : str
            Who wrote it (component or device name).
        data : JSON-able, optional
            Structured details.
        """
        if not kind:
            raise InvalidValue("event kind must not be empty")
        data_value = json_data(data, f"event {kind!r} data")
        with self._write("record_event") as session:
            event = Event(
                run_id=run_id,
                kind=kind,
                source=source,
                message=message,
                data=data_value,
                ts=utcnow(),
            )
            session.add(event)
            session.flush()
            return event.id

    def record_events(self, run_id: int | None, events: Sequence[Mapping[str, Any]]) -> None:
        """Append many events in one transaction (e.g. a step's buffered device exchanges).

        Parameters
        ----------
        run_id : int or None
            The run they belong to.
        events : sequence of mappings
            Each with ``kind``, ``message``, ``source`` and optionally ``ts`` (an aware
            datetime: when it happened; default now) and ``data``.
        """
        if not events:
            return
        rows = event_rows(run_id, events, utcnow())
        with self._write("record_events") as session:
            session.execute(insert(Event), rows)

    def events(
        self, run_id: int | None, kind: str | None = None, *, after_id: int | None = None
    ) -> list[EventRecord]:
        """Return the events of a run in the order they were written.

        Parameters
        ----------
        run_id : int or None
            The run; ``None`` returns the events that belong to no run.
        kind : str, optional
            Only events of this kind; a kind ending in ``"."`` (e.g. ``"robot."``) selects
            every kind that starts with it.
        after_id : int, optional
            Only events with a larger id (to follow the log as it grows).
        """
        query = select(Event).where(self._event_filter(run_id, kind))
        if after_id is not None:
            query = query.where(Event.id > after_id)
        with self._read() as session:
            return [to_record(EventRecord, e) for e in session.scalars(query.order_by(Event.id))]

    def events_after(
        self, run_id: int | None, after_id: int | None, kind_prefix: str | None = None
    ) -> list[EventRecord]:
        """Return a run's events with an id above ``after_id`` (all if None), oldest first.

        For following the log as it grows. ``kind_prefix`` keeps the kinds that start with it
        (e.g. ``"control."``).
        """
        query = select(Event).where(self._event_filter(run_id, kind_prefix, prefix=True))
        if after_id is not None:
            query = query.where(Event.id > after_id)
        with self._read() as session:
            return [to_record(EventRecord, e) for e in session.scalars(query.order_by(Event.id))]

    def last_event_id(self, run_id: int | None, kind_prefix: str | None = None) -> int | None:
        """Return the id of a run's newest event (whose kind starts with ``kind_prefix``)."""
        filter_ = self._event_filter(run_id, kind_prefix, prefix=True)
        with self._read() as session:
            return session.scalar(select(func.max(Event.id)).where(filter_))

    def latest_events(self, run_id: int | None, n: int) -> list[EventRecord]:
        """Return a run's newest ``n`` events, oldest first."""
        query = (
            select(Event).where(self._event_filter(run_id, None)).order_by(Event.id.desc())
        ).limit(max(0, int(n)))
        with self._read() as session:
            return [to_record(EventRecord, e) for e in session.scalars(query)][::-1]

    @staticmethod
    def _event_filter(run_id: int | None, kind: str | None, *, prefix: bool = False) -> Any:
        """WHERE clause for a run's events (``None``: no run) of a kind.

        ``kind`` matches exactly, or as a prefix if ``prefix`` or if it ends with ``"."``.
        """
        clause = Event.run_id.is_(None) if run_id is None else Event.run_id == run_id
        if kind is None:
            return clause
        if prefix or kind.endswith("."):
            return and_(clause, Event.kind.startswith(kind, autoescape=True))
        return and_(clause, Event.kind == kind)
