"""SQLite settings, constraints, UTC timestamps and concurrent writers, on a real file."""

from __future__ import annotations

import threading
from datetime import UTC, datetime, timedelta, timezone

import pytest
from sqlalchemy import insert, select, text
from sqlalchemy.exc import IntegrityError

from labauto.store import (
    Event,
    IntegrityViolation,
    Run,
    RunState,
    Store,
    UTCDateTime,
    make_engine,
)


def test_wal_foreign_keys_and_busy_timeout_are_on(store: Store):
    with store.engine.connect() as connection:
        assert connection.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert connection.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
        assert connection.exec_driver_sql("PRAGMA busy_timeout").scalar() == 10_000
        assert connection.exec_driver_sql("PRAGMA synchronous").scalar() == 2  # FULL


def test_busy_timeout_is_configurable(db_url):
    engine = make_engine(db_url, busy_timeout_s=0.25)
    try:
        with engine.connect() as connection:
            assert connection.exec_driver_sql("PRAGMA busy_timeout").scalar() == 250
    finally:
        engine.dispose()


def test_foreign_keys_stay_on_after_migrations_on_a_pooled_connection(db_url):
    # env.py switches foreign keys off while migrating; the connection it used goes back to
    # the pool and must come out with them on again.
    engine = make_engine(db_url)
    try:
        from labauto.store import upgrade

        upgrade(engine)
        with engine.connect() as connection:
            assert connection.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
    finally:
        engine.dispose()


def test_foreign_key_violation_raises_at_database_level(store: Store):
    event = insert(Event).values(
        run_id=999, ts=datetime.now(UTC), kind="x", source="t", message="m"
    )
    with (
        pytest.raises(IntegrityError, match="FOREIGN KEY constraint failed"),
        store.engine.begin() as connection,
    ):
        connection.execute(event)


def test_foreign_key_violation_through_the_store(store: Store, detection_row):
    with pytest.raises(IntegrityViolation, match="add_detections: FOREIGN KEY"):
        store.add_detections(None, 12345, [detection_row(0)])
    with pytest.raises(IntegrityViolation, match="record_event: FOREIGN KEY"):
        store.record_event(999, "run.note", "no such run")


def test_check_constraint_refuses_unknown_state_written_by_sql(store: Store):
    run_id = store.create_run("r")
    with (
        pytest.raises(IntegrityError, match="CHECK constraint failed"),
        store.engine.begin() as connection,
    ):
        connection.execute(
            text("UPDATE runs SET state = 'exploded' WHERE id = :id"), {"id": run_id}
        )


def test_utc_round_trip_gives_aware_utc_datetimes(store: Store):
    tokyo = timezone(timedelta(hours=9))
    moment = datetime(2026, 3, 1, 18, 30, 15, 123456, tzinfo=tokyo)
    with store.engine.begin() as connection:
        connection.execute(insert(Event).values(ts=moment, kind="t", source="test", message="tz"))
    with store.engine.connect() as connection:
        stored_text = connection.exec_driver_sql("SELECT ts FROM events").scalar()
        read_back = connection.execute(select(Event.ts)).scalar()
    assert stored_text.startswith("2026-03-01 09:30:15.123456")  # stored as UTC
    assert read_back.tzinfo is UTC
    assert read_back == moment
    assert read_back == datetime(2026, 3, 1, 9, 30, 15, 123456, tzinfo=UTC)


def test_store_timestamps_are_aware_and_ordered(store: Store):
    before = datetime.now(UTC)
    run_id = store.create_run("r")
    run = store.set_run_state(run_id, "running")
    after = datetime.now(UTC)
    assert run.created_at.tzinfo is UTC and run.started_at.tzinfo is UTC
    assert before <= run.created_at <= run.started_at <= after


def test_naive_datetime_is_refused():
    with pytest.raises(ValueError, match="naive datetime 2026-01-01T00:00:00 refused"):
        UTCDateTime().process_bind_param(datetime(2026, 1, 1), make_engine("sqlite://").dialect)


def test_naive_datetime_refused_by_add_image(store: Store):
    plate_id = store.add_plate("p").id
    with pytest.raises(Exception, match="naive datetime"):
        store.add_image(plate_id, "a.png", 1, 1, "0" * 64, captured_at=datetime(2026, 1, 1))


def test_two_stores_writing_at_once_lose_nothing(db_url):
    # Two Stores (two engines, as in two processes) append events in parallel threads.
    # BEGIN IMMEDIATE + busy_timeout make each writer wait for the other instead of failing.
    with Store.open(db_url) as first, Store.open(db_url, migrate=False) as second:
        run_id = first.create_run("parallel")
        errors: list[BaseException] = []

        def writer(store: Store, name: str) -> None:
            try:
                for i in range(150):
                    store.record_event(run_id, "test.write", f"{name} {i}", source=name)
                    if i % 25 == 0:
                        store.set_run_state(run_id, "running")  # read-then-write transaction
            except BaseException as exc:  # reported below
                errors.append(exc)

        threads = [
            threading.Thread(target=writer, args=(first, "a")),
            threading.Thread(target=writer, args=(second, "b")),
        ]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        assert errors == []
        written = first.events(run_id, "test.write")
        assert len(written) == 300
        assert [e.message for e in written if e.source == "a"] == [f"a {i}" for i in range(150)]
        assert first.get_run(run_id).state is RunState.RUNNING
        assert len(first.events(run_id, "run.state")) == 12


def test_records_are_snapshots_not_live_objects(store: Store):
    run_id = store.create_run("r")
    record = store.get_run(run_id)
    with pytest.raises(AttributeError):
        record.state = RunState.RUNNING  # type: ignore[misc]
    with store.engine.connect() as connection:
        assert connection.execute(select(Run.state)).scalar() is RunState.IDLE
