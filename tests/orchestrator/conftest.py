"""Fixtures for run tests (helpers live in run_helpers.py)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from run_helpers import workcell_config

from labauto.config import Config


@pytest.fixture()
def make_config(tmp_path: Path) -> Callable[..., Config]:
    """Build a simulated-workcell config in ``tmp_path``: ``make_config(plates=1, **sections)``."""
    return lambda plates=1, **sections: workcell_config(tmp_path, plates, **sections)
