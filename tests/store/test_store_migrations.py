"""Alembic migrations on a real SQLite file: up, down, up again; schema equals the models."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext

from labauto.store import (
    Base,
    DatabaseUnavailable,
    Store,
    current_revision,
    downgrade,
    head_revision,
    make_engine,
    migrations_dir,
    upgrade,
)

TABLES = {
    "plates",
    "images",
    "runs",
    "detections",
    "colonies",
    "picks",
    "analyzer_results",
    "events",
    "calibrations",
}


def _sqlite_path(url: str) -> str:
    return url.removeprefix("sqlite:///")


def _tables(url: str) -> set[str]:
    with sqlite3.connect(_sqlite_path(url)) as con:
        rows = con.execute("SELECT name FROM sqlite_master WHERE type = 'table'").fetchall()
    return {name for (name,) in rows} - {"alembic_version"}


def _schema(path: str) -> dict[str, set[str]]:
    """Each table's and index's SQL as a set of normalised lines (order-free constraints)."""
    with sqlite3.connect(path) as con:
        rows = con.execute(
            "SELECT name, sql FROM sqlite_master"
            " WHERE sql IS NOT NULL AND name != 'alembic_version'"
        ).fetchall()
    # a batch migration re-creates tables as CREATE TABLE "name": quoting is not a difference
    return {
        name: {line.strip().rstrip(",").replace('"', "") for line in sql.splitlines()}
        for name, sql in rows
    }


def test_packaged_migrations_are_found():
    folder = migrations_dir()
    assert (folder / "env.py").is_file()
    assert (folder / "script.py.mako").is_file()
    assert (folder / "versions" / "0001_initial.py").is_file()
    assert (folder / "versions" / "0002_run_integrity.py").is_file()
    assert (folder / "versions" / "0003_calibrations.py").is_file()
    assert head_revision() == "0003"


def test_upgrade_downgrade_upgrade(db_url):
    upgrade(db_url)
    assert _tables(db_url) == TABLES
    assert current_revision(db_url) == "0003"

    downgrade(db_url, "base")
    assert _tables(db_url) == set()
    assert current_revision(db_url) is None

    upgrade(db_url, "head")
    assert _tables(db_url) == TABLES
    assert current_revision(db_url) == head_revision()


def test_upgrade_twice_is_a_no_op_and_keeps_data(db_url):
    with Store.open(db_url) as store:
        run_id = store.create_run("kept")
    upgrade(db_url)
    with Store.open(db_url) as store:
        assert store.get_run(run_id).name == "kept"


def test_autogenerate_finds_no_difference_after_upgrade(db_url):
    upgrade(db_url)
    engine = make_engine(db_url)
    try:
        with engine.connect() as connection:
            diff = compare_metadata(MigrationContext.configure(connection), Base.metadata)
    finally:
        engine.dispose()
    assert diff == []


def test_migrated_schema_equals_create_all_including_check_constraints(db_url, tmp_path):
    # compare_metadata does not look at CHECK constraints; the SQL text does.
    upgrade(db_url)
    reference = tmp_path / "create_all.db"
    engine = make_engine(f"sqlite:///{reference}")
    Base.metadata.create_all(engine)
    engine.dispose()
    migrated, expected = _schema(_sqlite_path(db_url)), _schema(str(reference))
    assert migrated == expected
    assert any("CONSTRAINT ck_picks_pick_state CHECK" in line for line in migrated["picks"])


def test_upgrade_in_memory_database_through_the_same_engine():
    with Store.open("sqlite://") as store:
        run_id = store.create_run("in memory")
        assert store.get_run(run_id).state == "idle"


def test_open_without_migrate_leaves_the_database_unmigrated(db_url):
    with Store.open(db_url, migrate=False) as store:
        assert current_revision(store.engine) is None


def test_malformed_url_names_it():
    with pytest.raises(DatabaseUnavailable, match="malformed database URL 'not a url'"):
        Store.open("not a url")


def test_unopenable_database_names_url(tmp_path: Path):
    url = f"sqlite:///{tmp_path / 'missing-folder' / 'x.db'}"
    with pytest.raises(DatabaseUnavailable, match=r"cannot open database .*missing-folder"):
        upgrade(url)


def test_unknown_dialect_hides_password():
    with pytest.raises(DatabaseUnavailable) as info:
        make_engine("nosuchdb://operator:hunter2@host/db")
    assert "hunter2" not in str(info.value)
    assert "nosuchdb://operator:***@host/db" in str(info.value)


def test_postgresql_url_builds_an_engine_or_names_the_missing_driver():
    url = "postgresql://u:p@h/db"
    try:
        engine = make_engine(url)
    except DatabaseUnavailable as exc:  # no PostgreSQL driver in this environment
        message = str(exc)
        assert "driver" in message and "not installed" in message
        assert "postgresql://u:***@h/db" in message
        assert ":p@" not in message
    else:  # a driver is installed: the engine is built without connecting
        assert engine.dialect.name == "postgresql"
        engine.dispose()


def test_non_sqlite_url_is_accepted_without_connecting():
    # A stand-in DBAPI module replaces only the absent driver; the dialect, URL handling and
    # make_engine are real. No connection is made, so nothing of the module is called.
    import types

    dbapi = types.ModuleType("stand_in_pg8000")
    dbapi.paramstyle = "format"
    dbapi.__version__ = "1.31.2"
    engine = make_engine("postgresql+pg8000://lab:secret@db.example/labauto", module=dbapi)
    try:
        assert engine.dialect.name == "postgresql"
        assert "secret" not in repr(engine)
        assert "lab:***@db.example" in repr(engine)
    finally:
        engine.dispose()


def test_unknown_revision_raises_migration_error_naming_url_and_revision(db_url):
    from labauto.store import MigrationError

    upgrade(db_url)
    with pytest.raises(MigrationError, match=r"downgrade to 'nonexistent' failed for 'sqlite:///"):
        downgrade(db_url, "nonexistent")
    assert current_revision(db_url) == "0003"
