"""Driver for a Modbus analyzer (TCP or RTU) described by a YAML register map.

Typical use::

    with Analyzer("tcp", host="10.0.0.7", port=502) as analyzer:
        result = analyzer.analyze("S-0001", timeout=120)   # {"od600": 0.71, "ph": 7.02, ...}

Behaviour and choices:

* ``connect()`` opens the link and reads the state once, so a connected driver has seen the
  analyzer answer. No automatic retries: every failure is raised, and after any failure
  ``reconnect()`` (close + connect) brings the driver back.
* Errors: a Modbus exception reply raises the ``ModbusExceptionReply`` subclass for its code
  (e.g. ``ModbusServerDeviceBusy`` for a load while busy); no reply -> ``DeviceTimeout``;
  dropped connection -> ``DeviceDisconnected``; a state code the map does not know ->
  ``UnexpectedReply``; the analyzer's error state -> ``AnalyzerError`` with its error code;
  a sample id that does not fit the map -> ``DeviceRefused`` before anything is sent.
* Every command is confirmed before the next step, because many instruments act on a command
  only at their next PLC scan (10-100 ms later) and a ``done`` still showing from the last
  sample would otherwise pass for the new one: the command register must read 0 again
  (``command.clears`` in the map), ``load`` must show the new id in the ``sample_echo`` register
  (if the map has one), and ``start`` must be seen taken - the state goes busy or error, the
  ``result_counter`` moves, or the state changes to done from something else. Not seen within
  ``timing.command_timeout_s``: :class:`DeviceTimeout` naming the command and what was seen.
  ``wait_done()`` then accepts ``done`` only with the sample's id in the echo register.
* ``wait_done()`` polls the state every ``poll_interval`` seconds: done returns, error raises,
  idle and busy keep waiting (an analyzer may show idle for a moment after start).
* RTU line: ``baudrate`` and ``parity``/``stopbits`` (default 8E1, Modbus's standard framing;
  ``parity="N"`` needs ``stopbits=2`` by the standard, but 8N1 is accepted as devices use it).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

from .analyzer_map import (
    AnalyzerMap,
    ReadSpan,
    RegisterField,
    Value,
    decode_spans,
    decode_value,
    encode_value,
    load_map,
    read_spans,
)
from .errors import AnalyzerError, DeviceRefused, DeviceTimeout, UnexpectedReply
from .modbus_adapter import ExchangeCallback, ModbusClientLink


class Analyzer:
    """A Modbus analyzer: load a sample, start, wait, read the named results.

    Parameters
    ----------
    transport : {"tcp", "rtu"}
        Modbus TCP or Modbus RTU over a serial line.
    host, port : str, int
        TCP: the analyzer's address (default port 502).
    serial_port : str
        RTU: the serial device path or pyserial URL (e.g. ``/dev/ttyUSB0``).
    baudrate : int
        RTU line speed.
    parity : {"E", "O", "N"}
        RTU parity (default ``"E"``: 8E1, the Modbus standard's default).
    stopbits : {1, 2}
        RTU stop bits.
    unit_id : int, optional
        Modbus unit / device id, 1..247; default: ``device.unit_id`` of the map.
    register_map : AnalyzerMap or path, optional
        The register map; default: ``drivers/analyzer_map.yaml``.
    timeout : float
        Seconds to wait for each Modbus reply.
    poll_interval : float, optional
        Seconds between state reads in :meth:`wait_done`; default from the map's timing.
    name : str
        Device name used in errors and logs.
    on_exchange : callable, optional
        ``on_exchange(direction, text)`` for each request (``"tx"``) and outcome (``"rx"``).
    """

    def __init__(
        self,
        transport: Literal["tcp", "rtu"] = "tcp",
        *,
        host: str = "127.0.0.1",
        port: int = 502,
        serial_port: str | None = None,
        baudrate: int = 19200,
        parity: Literal["E", "O", "N"] = "E",
        stopbits: Literal[1, 2] = 1,
        unit_id: int | None = None,
        register_map: AnalyzerMap | str | Path | None = None,
        timeout: float = 1.0,
        poll_interval: float | None = None,
        name: str = "analyzer",
        on_exchange: ExchangeCallback | None = None,
    ) -> None:
        self.map = register_map if isinstance(register_map, AnalyzerMap) else load_map(register_map)
        self.name = name
        self.unit_id = self.map.unit_id if unit_id is None else unit_id
        if isinstance(self.unit_id, bool) or not (
            isinstance(self.unit_id, int) and 1 <= self.unit_id <= 247
        ):
            raise ValueError(
                f"{name}: unit_id must be 1..247 (0 is broadcast, 248-255 are reserved), "
                f"got {self.unit_id!r}"
            )
        if parity not in ("E", "O", "N"):
            raise ValueError(f"{name}: parity must be 'E', 'O' or 'N', got {parity!r}")
        if stopbits not in (1, 2):
            raise ValueError(f"{name}: stopbits must be 1 or 2, got {stopbits!r}")
        self.poll_interval = self.map.poll_interval_s if poll_interval is None else poll_interval
        if self.poll_interval <= 0:
            raise ValueError(f"poll_interval must be > 0 seconds, got {self.poll_interval!r}")
        self._link = ModbusClientLink(
            transport,
            host=host,
            port=port,
            serial_port=serial_port,
            baudrate=baudrate,
            parity=parity,
            stopbits=stopbits,
            timeout=timeout,
            device=name,
            on_exchange=on_exchange,
        )
        self._expected_echo: str | int | None = None
        self._result_spans = read_spans(self.map.results)
        self._identification_spans = read_spans(self.map.identification)

    @property
    def on_exchange(self) -> ExchangeCallback | None:
        """The ``on_exchange(direction, text)`` callback; may be set at any time."""
        return self._link.on_exchange

    @on_exchange.setter
    def on_exchange(self, callback: ExchangeCallback | None) -> None:
        self._link.on_exchange = callback

    @property
    def endpoint(self) -> str:
        """Where the analyzer is, e.g. ``tcp 127.0.0.1:5020``."""
        return self._link.endpoint

    # -- connection ---------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the connection and check that the analyzer answers (reads its state).

        Raises
        ------
        DeviceDisconnected, DeviceTimeout, ModbusExceptionReply, UnexpectedReply
        """
        self._link.connect()
        try:
            self.state()
        except BaseException:
            self._link.close()
            raise

    def close(self) -> None:
        """Close the connection (idempotent)."""
        self._link.close()

    def reconnect(self) -> None:
        """Close the link and connect again: the way back after any failure.

        Renews only the link (it does not call :meth:`close`, which a subclass may extend).
        """
        self._link.close()
        self.connect()

    def __enter__(self) -> Analyzer:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- commands -------------------------------------------------------------------------------
    def state(self) -> str:
        """The analyzer's state: ``"idle"``, ``"busy"``, ``"done"`` or ``"error"``.

        Raises
        ------
        UnexpectedReply
            The state register holds a code the map does not know.
        """
        code = self._read_field(self.map.state.field, "state")
        name = self.map.state.name_of(int(code))
        if name is None:
            raise UnexpectedReply(
                f"state register holds {code}, which the map {self.map.source} does not know",
                device=self.name,
            )
        return name

    def error_code(self) -> int:
        """The analyzer's error code register (meaningful in the error state)."""
        return int(self._read_field(self.map.error_code, "error code"))

    def load_sample(self, sample_id: str | int) -> None:
        """Write the sample id, then the ``load`` command.

        Raises
        ------
        DeviceRefused
            The id does not fit the map's sample id field (too long, not ASCII, wrong kind).
        ModbusServerDeviceBusy
            The analyzer is busy (as the simulated one answers).
        """
        field = self.map.sample_id
        try:
            registers = encode_value(field, sample_id)
        except ValueError as exc:
            raise DeviceRefused(f"sample id not sent: {exc}", device=self.name) from None
        self._link.write_registers(
            field.address, registers, self.unit_id, label=f"sample id {sample_id!r}"
        )
        self.command("load")
        echo = self.map.sample_echo
        if echo is not None:
            wanted = decode_value(field, registers)
            self._confirm(
                f"load of sample {sample_id!r}",
                lambda: (
                    None
                    if (shown := self._read_field(echo, "sample echo")) == wanted
                    else f"the sample echo reads {shown!r}"
                ),
            )

    def start(self) -> None:
        """Send the ``start`` command and confirm the analyzer took it.

        Taken means: the state went busy or error, the result counter moved, or the state
        changed to done from another state.

        Raises
        ------
        DeviceTimeout
            Not seen taken within the map's ``command_timeout_s``.
        """
        counter = self.map.result_counter
        before_state = self.state()
        before_count = self._read_field(counter, "result counter") if counter else None

        def started() -> str | None:
            state = self.state()
            if state in ("busy", "error"):
                return None
            count = self._read_field(counter, "result counter") if counter else None
            if count is not None and count != before_count:
                return None
            if state == "done" and before_state != "done":
                return None
            return f"the state stays {state}" + (
                f" and the result counter {count}" if count is not None else ""
            )

        self.command("start")
        self._confirm("start", started)

    def abort(self) -> None:
        """Send the ``abort`` command."""
        self.command("abort")

    def reset(self) -> None:
        """Send the ``reset`` command (leaves the error state)."""
        self.command("reset")

    def command(self, name: str) -> None:
        """Write the code of command ``name`` (any command the map defines).

        With ``command.clears`` in the map, waits until the command register reads 0 again
        (the analyzer took it), at most ``timing.command_timeout_s``.
        """
        try:
            code = self.map.command.code(name)
        except KeyError as exc:
            raise DeviceRefused(str(exc.args[0]), device=self.name) from None
        register = self.map.command.field
        self._link.write_registers(register.address, [code], self.unit_id, label=f"command {name}")
        if self.map.command_clears and code != 0:
            self._confirm(
                f"command {name}",
                lambda: (
                    None
                    if (shown := self._read_field(register, "command")) == 0
                    else f"the command register still reads {shown}"
                ),
            )

    def wait_done(self, timeout: float = 60.0) -> None:
        """Poll the state until the analysis is done.

        Parameters
        ----------
        timeout : float
            Seconds to wait for the done state.

        Raises
        ------
        AnalyzerError
            The analyzer went to its error state (``code`` = its error code register).
        DeviceTimeout
            Not done within ``timeout`` (the message says the last state seen).
        """
        deadline = time.monotonic() + timeout
        while True:
            state = self.state()
            if state == "done":
                if self._expected_echo is None or self._echo_matches():
                    return
                state = "done (of another sample: the echo does not match)"
            if state == "error":
                code = self.error_code()
                raise AnalyzerError(
                    f"analysis failed with error code {code}", device=self.name, code=code
                )
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DeviceTimeout(
                    f"analysis not done after {timeout:g} s (state {state})", device=self.name
                )
            time.sleep(min(self.poll_interval, remaining))

    def read_result(self) -> dict[str, Value]:
        """Read every result register: ``{name: value}`` in map order (scaled, decoded)."""
        values = self._read_spans(self._result_spans, "results")
        return {f.name: values[f.name] for f in self.map.results}

    def analyze(self, sample_id: str | int, timeout: float = 60.0) -> dict[str, Value]:
        """Load ``sample_id``, start, wait until done (at most ``timeout`` s), read the result.

        Each step is confirmed (see the module docstring), so the result is the sample's own.
        """
        self.load_sample(sample_id)
        self.start()
        self._expected_echo = sample_id
        try:
            self.wait_done(timeout)
        finally:
            self._expected_echo = None
        return self.read_result()

    def identify(self) -> dict[str, Any]:
        """What ``labauto devices check`` shows: endpoint, unit, state, error code, identity.

        Keys: ``name``, ``endpoint``, ``unit_id``, ``model`` (the map's, unless the analyzer
        reports its own in an identification register), ``state``, ``error_code``, and one key
        per identification register of the map. Raises like :meth:`state` when there is no answer.
        """
        info: dict[str, Any] = {
            "name": self.name,
            "endpoint": self.endpoint,
            "unit_id": self.unit_id,
            "model": self.map.model,
            "state": self.state(),
            "error_code": self.error_code(),
        }
        info.update(self._read_spans(self._identification_spans, "identification"))
        return info

    # -- internals ------------------------------------------------------------------------------
    def _confirm(self, what: str, check: Callable[[], str | None]) -> None:
        """Poll ``check()`` (None = confirmed, else what was seen) up to the command timeout."""
        limit = self.map.command_timeout_s
        deadline = time.monotonic() + limit
        while (seen := check()) is not None:
            if time.monotonic() >= deadline:
                raise DeviceTimeout(
                    f"the analyzer did not take the {what} within {limit:g} s: {seen}",
                    device=self.name,
                )
            time.sleep(min(self.poll_interval, 0.02))

    def _echo_matches(self) -> bool:
        echo = self.map.sample_echo
        if echo is None:
            return True
        wanted = decode_value(
            self.map.sample_id, encode_value(self.map.sample_id, self._expected_echo)
        )
        return self._read_field(echo, "sample echo") == wanted

    def _read_field(self, field: RegisterField, label: str) -> Value:
        registers = self._link.read_registers(
            field.table,
            field.address,
            field.registers,
            self.unit_id,
            label=label,
        )
        return decode_value(field, registers)

    def _read_spans(self, spans: list[ReadSpan], label: str) -> dict[str, Value]:
        blocks = [
            self._link.read_registers(
                s.table,
                s.address,
                s.count,
                self.unit_id,
                label=label,
            )
            for s in spans
        ]
        return decode_spans(spans, blocks)


def exchange_logger(sink: Callable[[str], None], name: str = "analyzer") -> ExchangeCallback:
    """An ``on_exchange`` callback writing lines like ``analyzer > read input 0 unit 1``."""

    def log(direction: str, text: str) -> None:
        sink(f"{name} {'>' if direction == 'tx' else '<'} {text}")

    return log
