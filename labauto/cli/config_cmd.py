"""``labauto config show``: the effective configuration, every default filled in."""

from __future__ import annotations

import dataclasses

import click
import yaml

from labauto.cli.options import config_option
from labauto.config import DATACLASS_SECTIONS, Config, section_params


@click.group("config")
def config_group() -> None:
    """Inspect workcell configurations."""


@config_group.command("show")
@config_option
def show(config: Config) -> None:
    """Print the validated config as YAML, with every default and environment override."""
    document = config.model_dump(mode="json")
    for section in DATACLASS_SECTIONS:
        params = section_params(config, section)
        document[section] = _plain(dataclasses.asdict(params))
    click.echo(yaml.safe_dump(document, sort_keys=False), nl=False)


def _plain(value):
    """Tuples to lists, recursively, so the YAML reads like a config file."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    return value
