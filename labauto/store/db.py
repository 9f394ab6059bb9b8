"""Engines and migrations: open any SQLAlchemy URL, run the packaged Alembic migrations.

SQLite is the default backend (one file). Every SQLite connection made by :func:`make_engine` is
set up for a workcell that must survive a crash:

* ``journal_mode=WAL``: readers do not block the writer, and a killed process leaves a
  consistent database;
* ``synchronous=FULL``: a committed write survives a power cut, not only a killed process
  (choice: the audit trail is worth an fsync per commit; writes here are small and few);
* ``foreign_keys=ON`` and ``busy_timeout``: constraints are enforced, and a writer waits for a
  lock instead of failing at once;
* SQLAlchemy, not the ``sqlite3`` module, emits ``BEGIN``, so transactions (including DDL in
  migrations) are real. A connection with the execution option ``labauto_begin="IMMEDIATE"``
  begins with ``BEGIN IMMEDIATE``: it takes the write lock up front, so a read-then-write
  transaction cannot dead-end in ``database is locked``. The repository uses it for writes.

Migrations live in the package ``labauto.migrations`` (the top-level ``migrations/`` folder of
the source tree); :func:`migrations_dir` finds them for editable and regular installs alike.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, create_engine, event, inspect
from sqlalchemy.engine import URL, Connection, make_url
from sqlalchemy.exc import ArgumentError, NoSuchModuleError, SQLAlchemyError
from sqlalchemy.pool import StaticPool

from .errors import DatabaseUnavailable, MigrationError

DEFAULT_BUSY_TIMEOUT_S = 10.0
"""How long a SQLite connection waits for another writer's lock before giving up."""

BEGIN_OPTION = "labauto_begin"
"""Execution option naming the SQLite ``BEGIN`` mode (``"DEFERRED"`` or ``"IMMEDIATE"``)."""

_PASSWORD_IN_URL = re.compile(r"(://[^:/@]*:)[^@]*@")


def safe_url(url: str | URL) -> str:
    """Return the URL as text with any password replaced by ``***``.

    Parameters
    ----------
    url : str or sqlalchemy.engine.URL
        A database URL, well formed or not.

    Returns
    -------
    str
        The URL, safe to print in logs and error messages.
    """
    if isinstance(url, URL):
        return url.render_as_string(hide_password=True)
    return _PASSWORD_IN_URL.sub(r"\1***@", str(url))


def parse_url(url: str | URL) -> URL:
    """Parse a database URL, raising :class:`DatabaseUnavailable` naming it if it is malformed."""
    if isinstance(url, URL):
        return url
    try:
        return make_url(url)
    except (ArgumentError, ValueError, TypeError) as exc:
        raise DatabaseUnavailable(
            f"malformed database URL {safe_url(url)!r}: {exc}; "
            "expected e.g. 'sqlite:///path/to/labauto.db' or 'postgresql://user@host/db'"
        ) from exc


def make_engine(
    url: str | URL,
    *,
    busy_timeout_s: float = DEFAULT_BUSY_TIMEOUT_S,
    echo: bool = False,
    **engine_options: Any,
) -> Engine:
    """Create an engine for any SQLAlchemy URL, with labauto's SQLite settings.

    An in-memory SQLite URL (``"sqlite://"``) gets one shared connection (``StaticPool``) so
    that migrations and every session see the same database.

    No connection is made here: a URL for a server that is down, or for a SQLite file in a folder
    that does not exist, fails at first use (see :func:`check_connection`).

    Parameters
    ----------
    url : str or sqlalchemy.engine.URL
        Database URL, e.g. ``"sqlite:///labauto.db"`` or ``"postgresql+psycopg://u:p@host/db"``.
    busy_timeout_s : float
        SQLite only: seconds to wait for another connection's write lock.
    echo : bool
        Log every SQL statement (SQLAlchemy's ``echo``).
    **engine_options
        Passed on to :func:`sqlalchemy.create_engine` (e.g. ``pool_size``, ``connect_args``).

    Returns
    -------
    sqlalchemy.Engine

    Raises
    ------
    DatabaseUnavailable
        If the URL is malformed, its dialect is unknown or its DBAPI driver is not installed.
        The message names the URL with the password hidden.
    """
    parsed = parse_url(url)
    options: dict[str, Any] = {}
    if _is_sqlite_memory(parsed):
        # One shared connection, so every session and the migrations see the same database.
        options = {"poolclass": StaticPool, "connect_args": {"check_same_thread": False}}
    options.update(engine_options)
    try:
        engine = create_engine(parsed, echo=echo, **options)
    except NoSuchModuleError as exc:
        raise DatabaseUnavailable(
            f"unknown database dialect in URL {safe_url(parsed)!r}: {exc}"
        ) from exc
    except ImportError as exc:
        raise DatabaseUnavailable(
            f"the database driver for {safe_url(parsed)!r} is not installed ({exc}); "
            "install it or choose another URL"
        ) from exc
    except (ArgumentError, TypeError, ValueError) as exc:
        raise DatabaseUnavailable(f"cannot use database URL {safe_url(parsed)!r}: {exc}") from exc
    if engine.dialect.name == "sqlite":
        _configure_sqlite(engine, busy_timeout_s)
    return engine


def _is_sqlite_memory(url: URL) -> bool:
    return url.get_backend_name() == "sqlite" and (
        url.database in (None, "", ":memory:") or url.query.get("mode") == "memory"
    )


def _configure_sqlite(engine: Engine, busy_timeout_s: float) -> None:
    """Install the connect and begin hooks described in the module docstring."""
    busy_timeout_ms = max(0, round(busy_timeout_s * 1000))

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, connection_record: Any) -> None:
        # Hand transaction control to SQLAlchemy (see the "begin" hook below).
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        try:
            cursor.execute(f"PRAGMA busy_timeout = {busy_timeout_ms}")
            cursor.execute("PRAGMA journal_mode = WAL")  # an in-memory db answers "memory"
            cursor.execute("PRAGMA synchronous = FULL")
            cursor.execute("PRAGMA foreign_keys = ON")
        finally:
            cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(connection: Connection) -> None:
        options = connection.get_execution_options()
        if options.get("isolation_level") == "AUTOCOMMIT":
            return
        mode = options.get(BEGIN_OPTION, "DEFERRED")
        if mode not in ("DEFERRED", "IMMEDIATE"):
            raise ValueError(f"{BEGIN_OPTION} must be 'DEFERRED' or 'IMMEDIATE', not {mode!r}")
        connection.exec_driver_sql(f"BEGIN {mode}")


def check_connection(engine: Engine) -> None:
    """Open one connection, raising :class:`DatabaseUnavailable` naming the URL if that fails."""
    try:
        with engine.connect() as connection:
            inspect(connection).get_table_names()
    except SQLAlchemyError as exc:
        raise DatabaseUnavailable(
            f"cannot open database {safe_url(engine.url)!r}: {_root_message(exc)}"
        ) from exc


def migrations_dir() -> Path:
    """Return the folder of the packaged Alembic environment (``labauto.migrations``).

    Found through the imported package, so it is the source folder for an editable install and
    the installed copy for a regular ``pip install .``.
    """
    import labauto.migrations

    return Path(labauto.migrations.__file__).resolve().parent


def alembic_config(target: str | URL | Engine) -> Any:
    """Build an Alembic ``Config`` for the packaged migrations and a database.

    Parameters
    ----------
    target : str, URL or Engine
        A database URL (``env.py`` opens it with :func:`make_engine`), or an engine whose
        connection the migrations should use (needed for ``sqlite://`` in-memory databases).

    Returns
    -------
    alembic.config.Config
        With ``script_location`` and ``sqlalchemy.url`` set; an engine is passed to ``env.py``
        in ``config.attributes["engine"]``.
    """
    from alembic.config import Config

    config = Config()
    config.set_main_option("script_location", str(migrations_dir()))
    config.set_main_option("path_separator", "os")
    if isinstance(target, Engine):
        config.attributes["engine"] = target
        url = target.url
    else:
        url = parse_url(target)
    # ConfigParser interpolates '%': escape it (URL-encoded passwords contain it).
    config.set_main_option(
        "sqlalchemy.url", url.render_as_string(hide_password=False).replace("%", "%%")
    )
    return config


def upgrade(target: str | URL | Engine, revision: str = "head") -> None:
    """Migrate a database up to ``revision`` with the packaged Alembic migrations.

    Parameters
    ----------
    target : str, URL or Engine
        The database (see :func:`alembic_config`). A new SQLite file is created.
    revision : str
        Alembic revision to reach, ``"head"`` by default.

    Raises
    ------
    DatabaseUnavailable
        If the URL is malformed or the database cannot be opened.
    MigrationError
        If a migration step fails. The message names the URL (password hidden) and revision.
    """
    _run_alembic("upgrade", target, revision)


def downgrade(target: str | URL | Engine, revision: str) -> None:
    """Migrate a database down to ``revision`` (``"base"`` drops every labauto table).

    Parameters
    ----------
    target : str, URL or Engine
        The database (see :func:`alembic_config`).
    revision : str
        Alembic revision to reach, e.g. ``"base"`` or ``"-1"``.

    Raises
    ------
    DatabaseUnavailable, MigrationError
        As for :func:`upgrade`.
    """
    _run_alembic("downgrade", target, revision)


def current_revision(target: str | URL | Engine) -> str | None:
    """Return the Alembic revision the database is at, or ``None`` if it was never migrated."""
    from alembic.migration import MigrationContext

    engine = target if isinstance(target, Engine) else make_engine(target)
    check_connection(engine)
    try:
        with engine.connect() as connection:
            return MigrationContext.configure(connection).get_current_revision()
    finally:
        if engine is not target:
            engine.dispose()


def head_revision() -> str:
    """Return the newest revision of the packaged migrations."""
    from alembic.script import ScriptDirectory

    head = ScriptDirectory(str(migrations_dir())).get_current_head()
    if head is None:  # pragma: no cover - the package always ships a revision
        raise MigrationError(f"no migration revisions found in {migrations_dir()}")
    return head


def _run_alembic(direction: str, target: str | URL | Engine, revision: str) -> None:
    from alembic import command
    from alembic.util import CommandError

    config = alembic_config(target)
    shown = safe_url(target.url if isinstance(target, Engine) else parse_url(target))
    if isinstance(target, Engine):
        check_connection(target)
    else:
        probe = make_engine(target)
        try:
            check_connection(probe)
        finally:
            probe.dispose()
    try:
        getattr(command, direction)(config, revision)
    except DatabaseUnavailable:
        raise
    except (CommandError, SQLAlchemyError) as exc:
        raise MigrationError(
            f"alembic {direction} to {revision!r} failed for {shown!r}: {_root_message(exc)}"
        ) from exc


def _root_message(exc: BaseException) -> str:
    """The DBAPI's own message when there is one (shorter than SQLAlchemy's wrapper text)."""
    orig = getattr(exc, "orig", None)
    return str(orig) if orig is not None else str(exc)
