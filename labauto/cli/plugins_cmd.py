"""``labauto plugins``: what is loaded, with version, source and hooks, and what failed."""

from __future__ import annotations

import json

import click

from labauto.cli.options import config_option
from labauto.config import Config
from labauto.plugin_manager import load_plugins


@click.command("plugins")
@config_option
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
def plugins(config: Config, as_json: bool) -> None:
    """List the loaded plugins (name, version, source, hooks) and the ones that failed."""
    loaded = load_plugins(config.plugins.enabled, config.plugins.disabled)
    if as_json:
        click.echo(
            json.dumps(
                {
                    "plugins": [
                        {
                            "name": p.name,
                            "version": p.version,
                            "source": p.source,
                            "hooks": list(p.hooks),
                        }
                        for p in loaded.loaded
                    ],
                    "failed": [
                        {"name": f.name, "source": f.source, "error": f.error}
                        for f in loaded.failed
                    ],
                    "segmenters": sorted(loaded.registry.segmenters),
                    "classifiers": sorted(loaded.registry.classifiers),
                    "applications": sorted(loaded.registry.applications),
                    "drivers": sorted(f"{k}:{n}" for k, n in loaded.registry.drivers),
                },
                indent=2,
            )
        )
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="labauto plugins")
    for column in ("name", "version", "source", "hooks"):
        table.add_column(column)
    for p in loaded.loaded:
        table.add_row(p.name, p.version, p.source, "\n".join(p.hooks))
    console = Console()
    console.print(table)
    for f in loaded.failed:
        console.print(f"[red]failed[/red] {f.name} ({f.source}): {f.error}")
