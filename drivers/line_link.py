"""A line transport over pyserial: open a URL, write bytes, read text lines.

The GRBL driver (:mod:`labauto.drivers.grbl`) speaks its protocol through this class and knows
nothing about ports. Anything ``serial.serial_for_url`` opens works: ``/dev/ttyUSB0``,
``socket://host:port``, a pseudo-terminal. Every line sent and received (and every real-time
byte written) is reported to an ``on_exchange(direction, text)`` callback, e.g. for an audit log.

Failures are the device errors of :mod:`labauto.drivers.errors`: an unopenable or broken port is
:class:`DeviceDisconnected` (and closes the link), no line before a deadline is
:class:`DeviceTimeout`, a write that blocks too long is :class:`DeviceTimeout`.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import time
from collections.abc import Callable
from threading import Lock

import serial
from serial.urlhandler import protocol_socket as socket_url

from .errors import DeviceDisconnected, DeviceTimeout

__all__ = ["ExchangeCallback", "LineLink"]

logger = logging.getLogger(__name__)

ExchangeCallback = Callable[[str, str], None]


class LineLink:
    """One serial connection that yields ``\\n``-terminated text lines.

    Parameters
    ----------
    url
        Anything ``serial.serial_for_url`` opens.
    device
        Device name used in error messages and log lines.
    baudrate
        Serial speed (ignored by ``socket://``).
    read_timeout
        pyserial's read timeout: the longest a read blocks, so deadlines are kept this closely.
    write_timeout
        Seconds a write may block before :class:`DeviceTimeout`.
    on_exchange
        ``callback(direction, text)`` for every non-empty line received (``"rx"``) and
        everything sent (``"tx"``); called synchronously, its exceptions reach the caller.
    """

    def __init__(
        self,
        url: str,
        *,
        device: str = "device",
        baudrate: int = 115200,
        read_timeout: float = 0.02,
        write_timeout: float = 2.0,
        on_exchange: ExchangeCallback | None = None,
    ) -> None:
        self.url = url
        self.device = device
        self.baudrate = baudrate
        self.read_timeout = read_timeout
        self.write_timeout = write_timeout
        self.on_exchange = on_exchange
        self._serial: serial.SerialBase | None = None
        self._rx = bytearray()
        self._write_lock = Lock()  # whole writes, also from other threads

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._serial is not None

    def open(self) -> None:
        """Open the port (no-op when open); unread input of an earlier connection is dropped.

        Raises
        ------
        DeviceDisconnected
            The port cannot be opened.
        """
        if self._serial is not None:
            return
        try:
            self._serial = serial.serial_for_url(
                self.url,
                baudrate=self.baudrate,
                timeout=self.read_timeout,
                write_timeout=self.write_timeout,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceDisconnected(f"cannot open {self.url}: {exc}", device=self.device) from exc
        self._rx.clear()

    def close(self) -> None:
        """Close the port (idempotent)."""
        port, self._serial = self._serial, None
        self._rx.clear()
        if port is not None:
            try:
                _close_quickly(port)
            except (serial.SerialException, OSError) as exc:  # already broken: nothing to save
                logger.debug("%s: error while closing %s: %s", self.device, self.url, exc)

    # ------------------------------------------------------------------ reading

    def poll(self) -> None:
        """Move whatever has already arrived into the line buffer, without waiting."""
        port = self._require()
        while True:
            try:
                waiting = port.in_waiting
                if not waiting:
                    return
                self._rx += port.read(waiting)
            except (serial.SerialException, OSError) as exc:
                self._lost(exc)

    def pop_line(self) -> str | None:
        """The next complete line already received (``""`` for a blank one), or ``None``."""
        end = self._rx.find(b"\n")
        if end < 0:
            return None
        raw = bytes(self._rx[:end])
        del self._rx[: end + 1]
        text = raw.decode("ascii", errors="replace").strip()
        if text:
            self._log("rx", text)
        return text

    def read_line(self, deadline: float, awaiting: str) -> str:
        """Return the next non-empty line, reading until ``deadline`` (monotonic seconds).

        Raises
        ------
        DeviceTimeout
            Nothing arrived in time; the message names ``awaiting``.
        DeviceDisconnected
        """
        port = self._require()
        while True:
            text = self.pop_line()
            if text:
                return text
            if text is None:
                if time.monotonic() >= deadline:
                    raise DeviceTimeout(f"no reply to {awaiting!r} in time", device=self.device)
                try:
                    self._rx += port.read(port.in_waiting or 1)
                except (serial.SerialException, OSError) as exc:
                    self._lost(exc)

    def read_until_quiet(self, quiet_s: float, limit_s: float) -> bool:
        """Read until nothing has arrived for ``quiet_s`` (at most ``limit_s``).

        Returns whether anything arrived. The bytes stay in the buffer for :meth:`pop_line`.
        """
        port = self._require()
        got = False
        quiet_until = time.monotonic() + quiet_s
        hard_stop = time.monotonic() + limit_s
        while (now := time.monotonic()) < quiet_until and now < hard_stop:
            try:
                chunk = port.read(port.in_waiting or 1)
            except (serial.SerialException, OSError) as exc:
                self._lost(exc)
            if chunk:
                self._rx += chunk
                got = True
                quiet_until = time.monotonic() + quiet_s
        return got

    # ------------------------------------------------------------------ writing

    def write_line(self, line: str) -> None:
        """Send ``line`` and a ``\\n``."""
        self.write(line.encode("ascii") + b"\n", shown=line)

    def write(self, data: bytes, *, shown: str | None = None) -> None:
        """Send raw bytes at once (safe from any thread); ``shown`` is what the log says."""
        port = self._require()
        self._log("tx", shown if shown is not None else data.hex())
        with self._write_lock:
            try:
                port.write(data)
            except serial.SerialTimeoutException as exc:
                raise DeviceTimeout(f"write to {self.url} timed out", device=self.device) from exc
            except (serial.SerialException, OSError) as exc:
                self._lost(exc)

    # ------------------------------------------------------------------ internals

    def _require(self) -> serial.SerialBase:
        port = self._serial
        if port is None:
            raise DeviceDisconnected(
                f"not connected to {self.url}; call connect()", device=self.device
            )
        return port

    def _lost(self, exc: BaseException) -> None:
        self.close()
        raise DeviceDisconnected(f"link to {self.url} lost: {exc}", device=self.device) from exc

    def _log(self, direction: str, line: str) -> None:
        logger.debug("%s %s %s", self.device, ">>" if direction == "tx" else "<<", line)
        if self.on_exchange is not None:
            self.on_exchange(direction, line)


def _close_quickly(port: serial.SerialBase) -> None:
    """Close a pyserial port; for ``socket://`` skip the 0.3 s sleep pyserial 3.5 adds to
    ``close()`` "in case of quick reconnects" (the driver does not need it)."""
    sock = getattr(port, "_socket", None)
    if isinstance(port, socket_url.Serial) and isinstance(sock, socket.socket):
        with contextlib.suppress(OSError):
            sock.shutdown(socket.SHUT_RDWR)
        sock.close()
        port._socket = None
        port.is_open = False
        return
    port.close()
