"""Helpers for the GRBL tests: simulated gantries on real ptys and TCP sockets.

Plain helpers, no pytest fixtures (so the shared ``tests/drivers/conftest.py`` stays untouched):
each ``test_grbl_*`` module wraps them in its own fixtures. :func:`gantry` stops its simulator on
exit and fails the test if the simulator thread is still alive.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from labauto.drivers.grbl import GrblRobot, TravelLimits
from labauto.drivers.grbl_sim import SimulatedGantry

TRANSPORTS = ("pty", "tcp")
SPEED = 200.0  # simulated durations / 200: a 300 mm travel takes 30 ms
SLOW_SPEED = 10.0  # for tests that must catch a move in progress: 200 mm take 0.4 s
REPLY_TIMEOUT_S = 0.3  # what the driver waits for a reply (each no-reply test costs this)
MOTION_TIMEOUT_S = 5.0
#: The deck of most driver tests: a HOMING_FORCE_SET_ORIGIN build with X/Y homing to their
#: minimum, so positions read like the bed (the stock build's negative space has its own tests).
DECK = TravelLimits(x=(0.0, 300.0), y=(0.0, 200.0), z=(-50.0, 0.0))
_THREAD_NAME = "labauto-grbl-sim"


class ExchangeLog(list[tuple[str, str]]):
    """An ``on_exchange`` callback that records ``(direction, line)`` pairs."""

    def __call__(self, direction: str, line: str) -> None:
        self.append((direction, line))

    def sent(self) -> list[str]:
        """Lines and real-time commands sent, in order."""
        return [line for direction, line in self if direction == "tx"]


def serve(sim: SimulatedGantry, transport: str) -> str:
    """Start serving ``sim`` on ``transport`` (``"pty"`` or ``"tcp"``); return the driver URL."""
    return sim.start_pty() if transport == "pty" else sim.start_tcp()


def make_robot(url: str, **kwargs: Any) -> GrblRobot:
    """A driver with test timeouts (not connected)."""
    kwargs.setdefault("timeout", REPLY_TIMEOUT_S)
    kwargs.setdefault("motion_timeout", MOTION_TIMEOUT_S)
    kwargs.setdefault("poll_interval", 0.005)
    kwargs.setdefault("boot_timeout", 0.0)
    kwargs.setdefault("limits", DECK)
    return GrblRobot(url, **kwargs)


def _sim_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == _THREAD_NAME and t.is_alive()]


@contextmanager
def gantry(**kwargs: Any) -> Iterator[SimulatedGantry]:
    """A simulated gantry (``speed_factor=SPEED`` unless given), stopped and checked on exit."""
    kwargs.setdefault("speed_factor", SPEED)
    kwargs.setdefault("limits", DECK)
    before = set(_sim_threads())
    sim = SimulatedGantry(**kwargs)
    try:
        yield sim
    finally:
        sim.stop()
        deadline = time.monotonic() + 2.0
        while set(_sim_threads()) - before and time.monotonic() < deadline:
            time.sleep(0.01)
        leaked = set(_sim_threads()) - before
        assert not leaked, f"simulator thread still running after stop(): {leaked}"


@contextmanager
def rig(
    transport: str, sim_options: dict[str, Any] | None = None, **robot_options: Any
) -> Iterator[tuple[SimulatedGantry, GrblRobot]]:
    """A simulator and a connected driver on ``transport``, both closed on exit."""
    with gantry(**(sim_options or {})) as sim:
        robot = make_robot(serve(sim, transport), **robot_options)
        robot.connect()
        try:
            yield sim, robot
        finally:
            robot.close()


def wait_for(predicate: Any, timeout: float = 2.0) -> bool:
    """Poll ``predicate()`` until true or ``timeout`` s have passed; return its last value."""
    deadline = time.monotonic() + timeout
    while not (result := predicate()) and time.monotonic() < deadline:
        time.sleep(0.005)
    return bool(result)
