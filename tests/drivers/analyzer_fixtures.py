"""Fixtures for the analyzer tests: simulated analyzers on real TCP sockets and real ptys.

Plain helpers (no pytest fixtures, so the shared ``tests/drivers/conftest.py`` stays untouched and
ruff sees no shadowed imports): each ``test_analyzer_*`` module wraps them in its own fixtures.
Every simulator started through :func:`sim_pool` is stopped on exit, and the test fails if a
simulator or pty-relay thread is still alive.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import yaml

from labauto.drivers.analyzer import Analyzer
from labauto.drivers.analyzer_map import DEFAULT_MAP_PATH
from labauto.drivers.analyzer_sim import SimulatedAnalyzer

TRANSPORTS = ("tcp", "rtu")
REPLY_TIMEOUT_S = 0.5  # what the driver waits for a reply in tests (no_reply costs this)
SIM_ANALYSIS_S = 1.0
SIM_SPEED = 20.0  # an analysis takes 50 ms
_OUR_THREADS = ("labauto-analyzer-sim", "labauto-pty-link")


def our_threads() -> list[threading.Thread]:
    """Live threads started by the simulator or the pty link."""
    return [t for t in threading.enumerate() if t.name in _OUR_THREADS and t.is_alive()]


def assert_no_leaked_threads(timeout: float = 2.0) -> None:
    """Fail if simulator threads outlive their simulators (after a short grace period)."""
    deadline = time.monotonic() + timeout
    while our_threads() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not our_threads(), f"leaked threads: {[t.name for t in our_threads()]}"


class SimPool:
    """Starts simulated analyzers and stops them all on :meth:`close` (checking for leaks)."""

    def __init__(self) -> None:
        self.sims: list[SimulatedAnalyzer] = []

    def __call__(
        self, transport: str = "tcp", **kwargs: Any
    ) -> tuple[SimulatedAnalyzer, dict[str, Any]]:
        """Start a simulator; returns ``(sim, where)`` where ``where`` are Analyzer kwargs."""
        kwargs.setdefault("analysis_seconds", SIM_ANALYSIS_S)
        kwargs.setdefault("speed_factor", SIM_SPEED)
        sim = SimulatedAnalyzer(**kwargs)
        self.sims.append(sim)
        if transport == "tcp":
            host, port = sim.start_tcp()
            return sim, {"transport": "tcp", "host": host, "port": port}
        # A Linux pty refuses even parity (EINVAL) and carries no parity bits: 8N1 here.
        return sim, {"transport": "rtu", "serial_port": sim.start_rtu(), "parity": "N"}

    def close(self) -> None:
        for sim in self.sims:
            sim.stop()
        assert_no_leaked_threads()


@contextmanager
def sim_pool() -> Iterator[SimPool]:
    """A :class:`SimPool` whose simulators are stopped, and threads checked, on exit."""
    pool = SimPool()
    try:
        yield pool
    finally:
        pool.close()


@contextmanager
def connected_rig(pool: SimPool, transport: str) -> Iterator[tuple[SimulatedAnalyzer, Analyzer]]:
    """A running simulator and a connected driver on ``transport`` (closed on exit)."""
    sim, where = pool(transport)
    analyzer = Analyzer(**where, timeout=REPLY_TIMEOUT_S, poll_interval=0.01)
    analyzer.connect()
    try:
        yield sim, analyzer
    finally:
        analyzer.close()


def default_map_data() -> dict[str, Any]:
    """The default register map as plain data, to mutate in tests."""
    return yaml.safe_load(DEFAULT_MAP_PATH.read_text(encoding="utf-8"))


def write_map(folder: Path, data: dict[str, Any], name: str = "map.yaml") -> Path:
    """Write a register map YAML file and return its path."""
    path = folder / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path
