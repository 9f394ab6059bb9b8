"""Alembic environment for labauto.

The database comes from the Alembic config: ``config.attributes["engine"]`` when
:func:`labauto.store.db.upgrade` was handed an engine, otherwise the ``sqlalchemy.url`` main
option (set by ``upgrade()``/``downgrade()``, or by ``alembic.ini`` when the ``alembic`` command
is used by hand). Engines are made by :func:`labauto.store.db.make_engine`, so SQLite gets WAL,
real transactions and a busy timeout here too.

On SQLite, ``render_as_batch=True`` lets ALTER-style operations run as "copy and move" batches,
and foreign keys are switched off while migrating (a batch re-creates tables that other tables
point at) and checked with ``PRAGMA foreign_key_check`` before the transaction commits.
"""

from __future__ import annotations

from logging.config import fileConfig

from alembic import context
from sqlalchemy import Connection

from labauto.store.db import make_engine
from labauto.store.models import Base

config = context.config
if config.config_file_name is not None:  # the `alembic` command run by hand with alembic.ini
    fileConfig(config.config_file_name, disable_existing_loggers=False)
target_metadata = Base.metadata


def run_migrations_offline() -> None:
    """Write the migration SQL to stdout (``alembic upgrade --sql``) without a database."""
    url = config.get_main_option("sqlalchemy.url")
    context.configure(
        url=url,
        target_metadata=target_metadata,
        literal_binds=True,
        dialect_opts={"paramstyle": "named"},
        render_as_batch=url is not None and url.startswith("sqlite"),
    )
    with context.begin_transaction():
        context.run_migrations()


def _set_sqlite_foreign_keys(connection: Connection, enabled: bool) -> None:
    """Switch SQLite foreign keys on the DBAPI connection itself.

    The pragma is a no-op inside a transaction, and any statement on the SQLAlchemy connection
    would begin one; labauto's SQLite connections are in driver autocommit, so this takes effect.
    """
    connection.connection.dbapi_connection.execute(
        f"PRAGMA foreign_keys = {'ON' if enabled else 'OFF'}"
    )


def _migrate(connection: Connection) -> None:
    is_sqlite = connection.dialect.name == "sqlite"
    if is_sqlite:
        # Restored below: the pooled connection may be used again by the application.
        _set_sqlite_foreign_keys(connection, False)
    try:
        context.configure(
            connection=connection,
            target_metadata=target_metadata,
            render_as_batch=is_sqlite,
            # labauto's SQLite connections run real transactions (SQLAlchemy emits BEGIN),
            # so a failed migration rolls back as a whole, as on PostgreSQL.
            transactional_ddl=True,
            compare_type=True,
        )
        with context.begin_transaction():
            context.run_migrations()
            if is_sqlite:
                broken = connection.exec_driver_sql("PRAGMA foreign_key_check").fetchall()
                if broken:
                    raise RuntimeError(f"migration left broken foreign keys: {broken[:5]}")
    finally:
        if is_sqlite:
            if connection.in_transaction():  # e.g. after an error; the pragma needs none open
                connection.rollback()
            _set_sqlite_foreign_keys(connection, True)


def run_migrations_online() -> None:
    """Migrate a live database."""
    engine = config.attributes.get("engine")
    if engine is not None:
        with engine.connect() as connection:
            _migrate(connection)
        return
    url = config.get_main_option("sqlalchemy.url")
    if not url:
        raise RuntimeError("no database: set sqlalchemy.url in the Alembic config")
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            _migrate(connection)
    finally:
        engine.dispose()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
