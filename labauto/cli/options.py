"""Options shared by several subcommands."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import click

from labauto.config import load_config


def config_option(func: Callable[..., Any]) -> Callable[..., Any]:
    """Add ``--config FILE`` and pass the validated ``Config`` as ``config``."""

    @click.option(
        "--config",
        "config_path",
        type=click.Path(dir_okay=False),
        default=None,
        help="Workcell config (YAML). Default: a simulated workcell.",
    )
    @functools.wraps(func)
    def wrapper(*args: Any, config_path: str | None, **kwargs: Any) -> Any:
        return func(*args, config=load_config(config_path), **kwargs)

    return wrapper
