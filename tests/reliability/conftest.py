"""Fixtures of the reliability suite (helpers live in reliability_helpers.py)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from labauto.plugin_manager import Plugins, load_plugins


@pytest.fixture(scope="session")
def plugins() -> Plugins:
    """The installed plugins, loaded once for the in-process runs of the suite."""
    return load_plugins()


@pytest.fixture(scope="session")
def dead_pid() -> int:
    """The pid of a process of this host that has ended (an owner known to be dead)."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid
