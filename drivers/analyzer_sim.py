"""Simulated Modbus analyzer: a real pymodbus server (TCP on 127.0.0.1, or RTU on a pty).

It serves the registers of an :class:`~labauto.drivers.analyzer_map.AnalyzerMap` and runs the
analyzer's state machine, so the real driver can be tested over the real transport.

State machine (codes from the map; the command register reads back 0):

====================  ==================================================================
command               effect
====================  ==================================================================
``load``              copy the sample id registers; state idle, results cleared.
                      Refused with SERVER_DEVICE_BUSY (6) while busy, with
                      ILLEGAL_DATA_VALUE (3) in the error state or if the id is empty.
``start``             state busy for ``analysis_seconds / speed_factor``, then done with
                      the sample's result. Refused like ``load``, and with
                      ILLEGAL_DATA_VALUE if no sample is loaded (each load allows one run).
``abort``             busy -> idle (the sample is unloaded); no effect in other states.
``reset``             any state -> idle; clears the sample, results and error code.
``none``              nothing. Unknown codes are refused with ILLEGAL_DATA_VALUE.
====================  ==================================================================

With ``scan_cycle_s`` the analyzer acts like a PLC front-end: a command written to the command
register is taken only at the next scan (every ``scan_cycle_s`` wall-clock seconds); until then
the register reads back the code written, and a second command written before the scan replaces
the first (the first is never seen). A command the state forbids is then dropped silently
instead of being refused with an exception. The ``sample_echo`` register (if the map has one)
shows the sample id loaded or last analysed; ``result_counter`` counts finished analyses.

Results are a deterministic function of the sample id (SHA-256 of the id picks each value in
a plausible range), so a test knows what the driver must read: :meth:`expected_result`.

Faults (``faults=`` at construction, or :meth:`inject_fault` / :meth:`clear_fault` at any time;
each stays until cleared):

* ``busy``: the state reads busy and ``load``/``start`` are refused with SERVER_DEVICE_BUSY;
  a running analysis does not finish while the fault is active.
* ``error_state`` (``code``, default 17): the running or next analysis ends in the error state
  with that error code.
* ``exception`` (``code``, default 6 SERVER_DEVICE_BUSY; e.g. 2 ILLEGAL_DATA_ADDRESS): every
  request is answered with that Modbus exception.
* ``no_reply``: the analyzer ignores requests and sends nothing (hung, or off the bus).
* ``drop_connection``: requests are ignored and the connection is closed instead of answered
  (TCP: the server closes the socket; RTU: the pty link hangs up, like an unplugged adapter,
  and a fresh line appears behind the same path).
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from types import TracebackType
from typing import Any, Literal

from .analyzer_map import AnalyzerMap, RegisterField, Value, decode_value, encode_value, load_map
from .modbus_adapter import ModbusServerThread, RegisterBlock, Table
from .pty_link import PtyLink

FAULTS = ("busy", "error_state", "exception", "no_reply", "drop_connection")
DEFAULT_ERROR_CODE = 17
DEFAULT_EXCEPTION_CODE = 6  # SERVER_DEVICE_BUSY

ILLEGAL_DATA_VALUE = 3
SERVER_DEVICE_BUSY = 6
_STANDARD_EXCEPTION_CODES = (1, 2, 3, 4, 5, 6, 7, 8, 10, 11)

#: Plausible ranges for the default map's result names; other names get a range by type.
_PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = {
    "od600": (0.05, 2.5),
    "ph": (5.5, 8.5),
    "cell_count": (1e5, 1e9),
    "temperature_c": (30.0, 37.5),
}
_RANGE_BY_TYPE: dict[str, tuple[float, float]] = {
    "uint16": (0, 60000),
    "int16": (-30000, 30000),
    "uint32": (0, 1e9),
    "int32": (-1e9, 1e9),
    "float32": (0.0, 1000.0),
}


def result_for(register_map: AnalyzerMap, sample_id: str) -> dict[str, Value]:
    """The deterministic result of ``sample_id``, exactly as the registers will hold it.

    Each result field takes 4 bytes of ``sha256(f"{sample_id}/{field name}")`` as a fraction
    ``u`` in [0, 1) and maps it onto the field's range (``low + u * (high - low)``); the value
    is then passed through the field's encoding, so it equals what a correct driver reads.
    """
    values: dict[str, Value] = {}
    for f in register_map.results:
        digest = hashlib.sha256(f"{sample_id}/{f.name}".encode()).digest()
        u = int.from_bytes(digest[:4], "big") / 2**32
        low, high = _PLAUSIBLE_RANGES.get(f.name) or _scaled(_RANGE_BY_TYPE[f.type], f)
        value: Value = low + u * (high - low)
        if f.type != "float32" and f.scale == 1:
            value = round(value)
        values[f.name] = decode_value(f, encode_value(f, value))
    return values


def _scaled(raw_range: tuple[float, float], f: RegisterField) -> tuple[float, float]:
    low, high = raw_range
    return (low * f.scale, high * f.scale) if f.scale > 0 else (high * f.scale, low * f.scale)


class SimulatedAnalyzer:
    """A simulated Modbus analyzer serving a register map over TCP or RTU.

    Parameters
    ----------
    register_map : AnalyzerMap or path, optional
        The map to serve (default: ``drivers/analyzer_map.yaml``).
    analysis_seconds : float
        How long an analysis takes on the real instrument.
    speed_factor : float
        Time runs this many times faster (an analysis takes ``analysis_seconds / speed_factor``).
    faults : mapping or iterable, optional
        Faults active from the start: names, or ``{name: {"code": n}}`` / ``{name: n}``.
    identity : mapping, optional
        Values of the identification registers by name (defaults: the map's model name,
        serial number 4242, firmware version 102).
    clock : callable
        Monotonic time source in seconds.
    scan_cycle_s : float
        0: commands act at once. Otherwise they act at the next scan (see the module docstring).
    """

    def __init__(
        self,
        register_map: AnalyzerMap | str | Path | None = None,
        *,
        analysis_seconds: float = 2.0,
        speed_factor: float = 1.0,
        faults: Mapping[str, Any] | Iterable[str] | None = None,
        identity: Mapping[str, Value] | None = None,
        clock: Callable[[], float] = time.monotonic,
        scan_cycle_s: float = 0.0,
    ) -> None:
        if analysis_seconds < 0:
            raise ValueError(f"analysis_seconds must be >= 0, got {analysis_seconds!r}")
        if speed_factor <= 0:
            raise ValueError(f"speed_factor must be > 0, got {speed_factor!r}")
        if not scan_cycle_s >= 0:
            raise ValueError(f"scan_cycle_s must be >= 0, got {scan_cycle_s!r}")
        self.scan_cycle_s = float(scan_cycle_s)
        self._pending_command: tuple[int, float] | None = None  # (code, scan time)
        self._echo = ""
        self._finished = 0
        self.map = register_map if isinstance(register_map, AnalyzerMap) else load_map(register_map)
        self.analysis_seconds = analysis_seconds
        self.speed_factor = speed_factor
        self._clock = clock
        self._lock = threading.RLock()
        self._faults: dict[str, int | None] = {}
        self._phase = "idle"
        self._loaded: str | None = None
        self._result_of: str | None = None
        self._busy_until = 0.0
        self._error_code = 0
        self._holding: dict[int, int] = {}
        self._identity = {
            "model": self.map.model,
            "serial_number": 4242,
            "firmware_version": 102,
            **(identity or {}),
        }
        self._server = ModbusServerThread(self, self.map.unit_id, name="labauto-analyzer-sim")
        self._link: PtyLink | None = None
        for name, options in _fault_items(faults):
            self.inject_fault(name, **options)

    # -- life cycle -------------------------------------------------------------------------------
    def start_tcp(self, host: str = "127.0.0.1", port: int = 0) -> tuple[str, int]:
        """Serve Modbus TCP; port 0 picks a free port. Returns ``(host, port)``."""
        return self._server.start_tcp(host, port)

    def start_rtu(self, baudrate: int = 19200) -> str:
        """Serve Modbus RTU on a pty pair. Returns the serial port path for the client."""
        link = PtyLink("analyzer")
        client_path, server_path = link.open()
        try:
            self._server.start_rtu(server_path, baudrate=baudrate, hang_up=link.request_hang_up)
        except BaseException:
            link.close()
            raise
        self._link = link
        return client_path

    def stop(self) -> None:
        """Stop the server and the pty link (idempotent)."""
        self._server.stop()
        if self._link is not None:
            self._link.close()
            self._link = None

    def __enter__(self) -> SimulatedAnalyzer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    # -- faults -----------------------------------------------------------------------------------
    def inject_fault(self, name: str, *, code: int | None = None) -> None:
        """Activate a fault (see the module docstring); ``code`` for error_state / exception."""
        if name not in FAULTS:
            raise ValueError(f"unknown fault {name!r}; known: {', '.join(FAULTS)}")
        if name == "exception":
            code = DEFAULT_EXCEPTION_CODE if code is None else code
            if code not in _STANDARD_EXCEPTION_CODES:
                raise ValueError(f"exception code must be one of {_STANDARD_EXCEPTION_CODES}")
        elif name == "error_state":
            code = DEFAULT_ERROR_CODE if code is None else code
            if not 1 <= code <= 65535:
                raise ValueError(f"error_state code must be 1..65535, got {code!r}")
        elif code is not None:
            raise ValueError(f"fault {name!r} takes no code")
        with self._lock:
            self._faults[name] = code

    def clear_fault(self, name: str | None = None) -> None:
        """Clear one fault, or all faults when ``name`` is None."""
        with self._lock:
            if name is None:
                self._faults.clear()
            else:
                self._faults.pop(name, None)

    @property
    def faults(self) -> dict[str, int | None]:
        """Active faults and their codes."""
        with self._lock:
            return dict(self._faults)

    # -- observation (for tests and the orchestrator's dry runs) ----------------------------------
    @property
    def state(self) -> str:
        """The state name the analyzer reports now."""
        with self._lock:
            self._advance()
            return self._shown_state()

    def expected_result(self, sample_id: str) -> dict[str, Value]:
        """What ``read_result()`` must return after analysing ``sample_id``."""
        return result_for(self.map, sample_id)

    # -- RegisterStore (called in the server thread) ---------------------------------------------
    def blocks(self) -> list[RegisterBlock]:
        """Registers served: every map field; command and sample id are writable."""
        writable = {self.map.command.field.name, self.map.sample_id.name}
        return [
            RegisterBlock(f.table, f.address, f.registers, f.name in writable)
            for f in self.map.fields()
        ]

    def read(self, table: Table, address: int, count: int) -> list[int] | int:
        """Register values (or an exception code) for a read request."""
        with self._lock:
            if "exception" in self._faults:
                return self._faults["exception"] or DEFAULT_EXCEPTION_CODE
            self._advance()
            image = self._register_image(table)
            return [image.get(a, 0) for a in range(address, address + count)]

    def write(self, table: Table, address: int, values: list[int]) -> int | None:
        """Apply a write request; returns an exception code to refuse it."""
        with self._lock:
            if "exception" in self._faults:
                return self._faults["exception"] or DEFAULT_EXCEPTION_CODE
            if "no_reply" in self._faults or "drop_connection" in self._faults:
                return None  # ignored: the reply will not be sent either
            self._advance()
            command = self.map.command.field
            for offset, value in enumerate(values):
                a = address + offset
                if a == command.address:
                    if self.scan_cycle_s:
                        scan = (int(self._clock() / self.scan_cycle_s) + 1) * self.scan_cycle_s
                        self._pending_command = (value, scan)
                        continue
                    refusal = self._command(value)
                    if refusal:
                        return refusal
                else:
                    self._holding[a] = value
            return None

    def reply_action(self) -> Literal["reply", "silent", "drop"]:
        """Whether the reply to the current request is sent, swallowed or replaced by a hang-up."""
        with self._lock:
            if "drop_connection" in self._faults:
                return "drop"
            if "no_reply" in self._faults:
                return "silent"
            return "reply"

    # -- state machine ----------------------------------------------------------------------------
    def _advance(self) -> None:
        """Finish a running analysis whose time is up, take a command at its scan (lazy)."""
        self._finish_analysis()
        if self._pending_command is not None and self._clock() >= self._pending_command[1]:
            code, _ = self._pending_command
            self._pending_command = None
            self._command(code)  # a refusal cannot be answered any more: the command is dropped
            self._finish_analysis()

    def _finish_analysis(self) -> None:
        if self._phase != "busy" or "busy" in self._faults:
            return
        if self._clock() < self._busy_until:
            return
        if "error_state" in self._faults:
            self._phase = "error"
            self._error_code = self._faults["error_state"] or DEFAULT_ERROR_CODE
            self._result_of = None
        else:
            self._phase = "done"
            self._result_of = self._loaded
            self._finished = (self._finished + 1) % 65536
        self._loaded = None

    def _shown_state(self) -> str:
        return "busy" if "busy" in self._faults else self._phase

    def _command(self, code: int) -> int | None:
        name = self.map.command.name_of(code)
        shown = self._shown_state()
        if name in ("none", "abort", "reset"):
            if name == "reset" or (name == "abort" and self._phase == "busy"):
                self._phase, self._loaded, self._result_of = "idle", None, None
                if name == "reset":
                    self._error_code = 0
                    self._echo = ""
            return None
        if name not in ("load", "start"):
            return ILLEGAL_DATA_VALUE  # unknown command code
        if shown == "busy":
            return SERVER_DEVICE_BUSY
        if shown == "error":
            return ILLEGAL_DATA_VALUE
        if name == "load":
            sample_id = self._sample_id()
            if sample_id in ("", 0):
                return ILLEGAL_DATA_VALUE
            self._phase, self._loaded, self._result_of = "idle", str(sample_id), None
            self._echo = str(sample_id)
            return None
        if self._loaded is None:
            return ILLEGAL_DATA_VALUE
        self._phase = "busy"
        self._result_of = None
        self._busy_until = self._clock() + self.analysis_seconds / self.speed_factor
        return None

    def _sample_id(self) -> Value:
        f = self.map.sample_id
        return decode_value(f, [self._holding.get(a, 0) for a in range(f.address, f.end)])

    def _register_image(self, table: Table) -> dict[int, int]:
        """Every register value of ``table`` as the analyzer shows it now."""
        image: dict[int, int] = {}
        if table == "holding":
            image.update(self._holding)
        m = self.map
        pending = self._pending_command[0] if self._pending_command is not None else 0
        shown: dict[str, Value] = {
            m.command.field.name: pending,
            m.state.field.name: m.state.code(self._shown_state()),
            m.error_code.name: self._error_code if self._phase == "error" else 0,
        }
        result = result_for(m, self._result_of) if self._result_of is not None else {}
        for f in m.results:
            shown[f.name] = result.get(f.name, "" if f.type == "string" else 0)
        for f in m.identification:
            shown[f.name] = self._identity.get(f.name, "" if f.type == "string" else 0)
        confirmation = [f for f in (m.sample_echo, m.result_counter) if f is not None]
        if m.sample_echo is not None:
            echo: Value = self._echo
            if m.sample_echo.type != "string":
                echo = int(self._echo) if self._echo else 0
            shown[m.sample_echo.name] = echo
        if m.result_counter is not None:
            shown[m.result_counter.name] = self._finished
        fields = (m.command.field, m.state.field, m.error_code, *m.results, *m.identification)
        for f in (*fields, *confirmation):
            if f.table == table:
                registers = _encode_fitting(f, shown[f.name])
                image.update(zip(range(f.address, f.end), registers, strict=True))
        return image


def _encode_fitting(f: RegisterField, value: Value) -> list[int]:
    """Encode ``value``, truncating strings that are longer than the field."""
    if isinstance(value, str):
        value = value.encode("ascii", errors="replace").decode()[: 2 * f.registers]
    return encode_value(f, value)


def _fault_items(faults: Mapping[str, Any] | Iterable[str] | None) -> list[tuple[str, dict]]:
    if faults is None:
        return []
    if isinstance(faults, Mapping):
        items = []
        for name, options in faults.items():
            if options is None or options is True:
                items.append((name, {}))
            elif isinstance(options, int) and not isinstance(options, bool):
                items.append((name, {"code": options}))
            elif isinstance(options, Mapping):
                items.append((name, dict(options)))
            else:
                raise ValueError(f"faults[{name!r}]: expected a code, a mapping or None")
        return items
    return [(name, {}) for name in faults]
