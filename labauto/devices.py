"""What the workcell needs from its devices: the ``Robot``, ``Analyzer`` and ``Camera`` Protocols.

The orchestrator, the driver hook (``labauto_register_drivers``) and integrators' plugins depend
on these, never on a concrete driver class. A driver satisfies a Protocol by having its methods
(structural typing); ``isinstance(device, Robot)`` checks that the names exist (not their
signatures). The built-in drivers are :class:`labauto.drivers.grbl.GrblRobot`,
:class:`labauto.drivers.analyzer.Analyzer` and the cameras of :mod:`labauto.drivers.camera`.

Contracts beyond the signatures:

* Failures are :class:`labauto.drivers.errors.DeviceError` subclasses whose ``device`` is the
  device's ``name``; after any of them ``reconnect()`` brings the device back.
* ``close()`` releases the device and everything it owns (e.g. the simulator a simulated device
  started); ``reconnect()`` only renews the link and never stops what the device owns.
* ``on_exchange(direction, text)``, when set, is called for every exchange (``"tx"``/``"rx"``),
  e.g. for the run's audit log.
* A robot refuses motion after an emergency stop (``soft_reset()``) or an unexpected controller
  restart until ``home()`` (or a driver's own unlock) re-arms it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Analyzer", "Camera", "Device", "ExchangeCallback", "Robot", "RobotStatus"]

#: ``callback(direction, text)`` with direction ``"tx"`` or ``"rx"``.
ExchangeCallback = Callable[[str, str], None]


class RobotStatus(Protocol):
    """A robot's status report: its state name and machine position (mm, or ``None``)."""

    @property
    def state(self) -> str: ...

    @property
    def position(self) -> tuple[float, float, float] | None: ...


@runtime_checkable
class Device(Protocol):
    """What every device of the workcell has: a name, an exchange log, a link to manage."""

    name: str
    on_exchange: ExchangeCallback | None

    def connect(self) -> None:
        """Open the link and check that the device answers (a robot: identify the controller)."""

    def close(self) -> None:
        """Release the device (idempotent)."""

    def reconnect(self) -> None:
        """Renew the link after a failure."""

    def identify(self) -> Mapping[str, Any]:
        """What ``labauto devices check`` shows."""
        ...


@runtime_checkable
class Robot(Device, Protocol):
    """A picking robot: moves in deck millimetres, takes and delivers probes."""

    def status(self) -> RobotStatus:
        """The current state and position."""
        ...

    def home(self) -> RobotStatus:
        """Home (clears alarms, re-arms after an e-stop) and return the status."""
        ...

    def move_to(
        self, x: float, y: float, z: float | None = None, *, wait: bool = True
    ) -> RobotStatus | None:
        """Travel at safe height to (x, y), then to ``z``."""
        ...

    def pick(self, x: float, y: float, z_pick: float, dwell_s: float = 0.5) -> RobotStatus:
        """Take a probe at (x, y)."""
        ...

    def deposit(self, x: float, y: float, z_deposit: float, dwell_s: float = 0.5) -> RobotStatus:
        """Deliver the probe at (x, y)."""
        ...

    def tool_off(self) -> None:
        """Switch the pick tool off (allowed in any state)."""

    def soft_reset(self) -> None:
        """Emergency stop: stop now; motion is refused until re-armed."""


@runtime_checkable
class Analyzer(Device, Protocol):
    """An analyzer that measures a delivered sample."""

    def analyze(self, sample_id: str, timeout: float = 60.0) -> Mapping[str, Any]:
        """Measure ``sample_id`` and return its named results."""
        ...

    def reset(self) -> None:
        """Leave an error state."""


@runtime_checkable
class Camera(Protocol):
    """A source of plate images: ``(name, BGR uint8 image)`` pairs."""

    def __iter__(self) -> Iterator[tuple[str, np.ndarray]]: ...
