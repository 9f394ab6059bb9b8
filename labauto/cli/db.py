"""``labauto db``: database maintenance."""

from __future__ import annotations

import click

from labauto.cli.options import config_option
from labauto.config import Config


@click.group("db")
def db() -> None:
    """Database maintenance (migrations)."""


@db.command("upgrade")
@config_option
@click.option("--revision", default="head", show_default=True, help="Target revision.")
def upgrade(config: Config, revision: str) -> None:
    """Migrate the database to the latest (or given) schema revision."""
    from labauto.store.db import upgrade as run_upgrade

    run_upgrade(config.database.url, revision)
    click.echo(f"database {config.database.url} at revision {revision}")
