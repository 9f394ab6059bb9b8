"""Errors shared by every device driver.

Each failure a device can show has its own type so callers (the orchestrator, an operator's script)
can react to it: retry on a timeout, re-home after an alarm, reconnect after a disconnect.
"""

from __future__ import annotations


class DeviceError(Exception):
    """Base class for every device failure. ``device`` names the device (e.g. ``"robot"``)."""

    def __init__(self, message: str, *, device: str = "device") -> None:
        super().__init__(f"{device}: {message}")
        self.device = device


class DeviceTimeout(DeviceError):
    """The device did not answer within the timeout."""


class DeviceDisconnected(DeviceError):
    """The connection to the device is gone (port closed, socket reset, cable pulled)."""


class UnexpectedReply(DeviceError):
    """The device answered something the protocol does not allow here (garbled or out of order)."""


class DeviceRefused(DeviceError):
    """The driver refused a command before sending it (e.g. a move outside the travel limits)."""


class DeviceFault(DeviceError):
    """The device reported an error or fault state of its own (e.g. GRBL error:N, analyzer error)."""

    def __init__(self, message: str, *, device: str = "device", code: int | None = None) -> None:
        super().__init__(message, device=device)
        self.code = code
