"""The one place labauto touches pymodbus: a small synchronous client and a threaded server.

pymodbus changes keyword names between minor versions (``unit=`` -> ``slave=`` -> ``device_id=``,
``count`` keyword-only, server datastores replaced by ``SimDevice``). Everything else in labauto
talks to :class:`ModbusClientLink` and :class:`ModbusServerThread`, whose API does not change, and
gets labauto's own errors (:mod:`labauto.drivers.errors`) instead of pymodbus exceptions:

* a Modbus exception reply -> the :class:`~labauto.drivers.errors.ModbusExceptionReply` subclass
  for its code (e.g. ``ModbusServerDeviceBusy``), naming the code and the request;
* no reply within the timeout -> :class:`~labauto.drivers.errors.DeviceTimeout`;
* connection refused, closed by the peer, serial port gone or hung up ->
  :class:`~labauto.drivers.errors.DeviceDisconnected`;
* a reply of the wrong shape -> :class:`~labauto.drivers.errors.UnexpectedReply`.

Version support: pyproject pins pymodbus to ``>=3.13,<3.17``, the range the tests pass on
(run on 3.13.0 and 3.16.1; the simulator's ``SimDevice`` server crashes on 3.12.1). The client
detects the unit keyword by signature; :class:`ModbusServerThread` says clearly if the installed
version lacks ``SimDevice`` actions.
Requests are sent once (``retries=0``) so ``timeout`` is the real time to wait for an answer.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import inspect
import logging
import select
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any, Literal, Protocol

import pymodbus
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerType

from .errors import (
    DeviceDisconnected,
    DeviceTimeout,
    UnexpectedReply,
    modbus_exception_reply,
)

Table = Literal["holding", "input"]
ExchangeCallback = Callable[[str, str], None]
"""``on_exchange(direction, text)``: direction is ``"tx"`` (sent) or ``"rx"`` (received)."""

PYMODBUS_VERSION: str = pymodbus.__version__

# Every pymodbus failure becomes a labauto error here, so pymodbus's own error log lines would
# only duplicate them on stderr when the application configured no logging. Records still reach
# the application's handlers (propagation is unchanged).
logging.getLogger("pymodbus").addHandler(logging.NullHandler())


def _unit_keyword() -> str:
    """The keyword pymodbus uses for the unit id in this version (detected by signature)."""
    parameters = inspect.signature(ModbusTcpClient.read_holding_registers).parameters
    for name in ("device_id", "slave", "unit"):
        if name in parameters:
            return name
    raise RuntimeError(f"pymodbus {PYMODBUS_VERSION}: cannot find the unit id keyword")


_UNIT_KEYWORD = _unit_keyword()


def _unit(unit: int) -> dict[str, int]:
    """The unit id as this pymodbus version wants it (``device_id=`` or ``slave=``)."""
    return {_UNIT_KEYWORD: unit}


# -- client -----------------------------------------------------------------------------------
class ModbusClientLink:
    """A synchronous Modbus client over TCP or RTU (serial) that raises labauto errors.

    Parameters
    ----------
    transport : {"tcp", "rtu"}
        Modbus TCP (MBAP framing over a socket) or Modbus RTU over a serial line.
    host, port : str, int
        TCP only: where the device listens (default port 502).
    serial_port : str
        RTU only: a device path (``/dev/ttyUSB0``, a pty) or a pyserial URL.
    baudrate, parity, stopbits, bytesize :
        RTU line settings (default 19200 8N1).
    timeout : float
        Seconds to wait for each reply (and for the TCP connect).
    device : str
        Name used in error messages (e.g. ``"analyzer"``).
    on_exchange : callable, optional
        Called as ``on_exchange("tx", text)`` before each request and
        ``on_exchange("rx", text)`` with the outcome, for the orchestrator's audit log.
    """

    def __init__(
        self,
        transport: Literal["tcp", "rtu"],
        *,
        host: str = "127.0.0.1",
        port: int = 502,
        serial_port: str | None = None,
        baudrate: int = 19200,
        parity: str = "N",
        stopbits: int = 1,
        bytesize: int = 8,
        timeout: float = 1.0,
        device: str = "device",
        on_exchange: ExchangeCallback | None = None,
    ) -> None:
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"transport must be 'tcp' or 'rtu', got {transport!r}")
        if timeout <= 0:
            raise ValueError(f"timeout must be > 0 seconds, got {timeout!r}")
        self.transport = transport
        self.device = device
        self.timeout = timeout
        self.on_exchange = on_exchange
        self._lock = threading.RLock()
        self._client: ModbusTcpClient | ModbusSerialClient
        if transport == "tcp":
            self.endpoint = f"tcp {host}:{port}"
            self._client = ModbusTcpClient(host, port=port, timeout=timeout, retries=0)
        else:
            if not serial_port:
                raise ValueError("transport 'rtu' needs serial_port (a device path or URL)")
            self.endpoint = f"rtu {serial_port} {baudrate} {bytesize}{parity}{stopbits}"
            self._client = ModbusSerialClient(
                serial_port,
                framer=FramerType.RTU,
                baudrate=baudrate,
                parity=parity,
                stopbits=stopbits,
                bytesize=bytesize,
                timeout=timeout,
                retries=0,
            )

    @property
    def connected(self) -> bool:
        """True while the socket or serial port is open."""
        return bool(self._client.connected)

    def connect(self) -> None:
        """Open the socket or serial port.

        Raises
        ------
        DeviceDisconnected
            The connection cannot be opened (refused, no such port, port in use).
        """
        with self._lock:
            if not self._client.connect():
                raise DeviceDisconnected(f"cannot connect to {self.endpoint}", device=self.device)

    def close(self) -> None:
        """Close the socket or serial port (idempotent)."""
        with self._lock:
            self._client.close()

    def read_registers(
        self, table: Table, address: int, count: int, unit: int, *, label: str = ""
    ) -> list[int]:
        """Read ``count`` registers from the holding or input table.

        ``label`` says what is read (e.g. ``"state"``); it starts the log text and error messages.

        Returns
        -------
        list of int
            The register values (0..65535).
        """
        request = _labelled(label, f"read {table} {_span(address, count)} unit {unit}")
        method = (
            self._client.read_holding_registers
            if table == "holding"
            else self._client.read_input_registers
        )
        response = self._execute(request, partial(method, address, count=count, **_unit(unit)))
        registers = list(getattr(response, "registers", None) or [])
        if len(registers) < count:
            self._log("rx", f"short reply {registers}")
            raise UnexpectedReply(
                f"{request}: expected {count} registers, got {len(registers)}", device=self.device
            )
        registers = registers[:count]
        self._log("rx", str(registers))
        return registers

    def write_registers(
        self, address: int, values: Sequence[int], unit: int, *, label: str = ""
    ) -> None:
        """Write holding registers: function code 6 for one value, 16 for several."""
        values = [int(v) for v in values]
        span = _span(address, len(values))
        request = _labelled(label, f"write holding {span} = {values} unit {unit}")
        if len(values) == 1:
            call = partial(self._client.write_register, address, values[0], **_unit(unit))
        else:
            call = partial(self._client.write_registers, address, values, **_unit(unit))
        self._execute(request, call)
        self._log("rx", "ok")

    # -- internals ----------------------------------------------------------------------------
    def _execute(self, request: str, call: Callable[[], Any]) -> Any:
        with self._lock:
            self._log("tx", request)
            try:
                response = call()
            except ModbusIOException as exc:
                if self._serial_hung_up():
                    self._client.close()
                    self._log("rx", "serial port hung up")
                    raise DeviceDisconnected(
                        f"{request}: serial port {self.endpoint} hung up", device=self.device
                    ) from exc
                self._log("rx", f"no reply within {self.timeout:g} s")
                raise DeviceTimeout(
                    f"{request}: no reply within {self.timeout:g} s from {self.endpoint}",
                    device=self.device,
                ) from exc
            except ConnectionException as exc:
                self._client.close()
                self._log("rx", "connection lost")
                raise DeviceDisconnected(
                    f"{request}: connection to {self.endpoint} lost or refused", device=self.device
                ) from exc
            except ModbusException as exc:
                self._log("rx", f"protocol error: {exc}")
                raise UnexpectedReply(f"{request}: {exc}", device=self.device) from exc
            except OSError as exc:  # pymodbus < 3.16 lets the port's own error through
                self._client.close()
                self._log("rx", f"I/O error: {exc}")
                what = (
                    "serial port {} hung up" if self.transport == "rtu" else "connection to {} lost"
                )
                raise DeviceDisconnected(
                    f"{request}: {what.format(self.endpoint)} ({exc})", device=self.device
                ) from exc
            if response is None:
                raise UnexpectedReply(f"{request}: empty reply", device=self.device)
            if response.isError():
                code = int(getattr(response, "exception_code", 0))
                error = modbus_exception_reply(code, device=self.device, request=request)
                self._log("rx", f"exception {error.exception_name} ({code})")
                raise error
            return response

    def _serial_hung_up(self) -> bool:
        """True if the serial line reports a hang-up (unplugged adapter, closed pty)."""
        if self.transport != "rtu":
            return False
        port = getattr(self._client, "socket", None)
        try:
            fd = port.fileno() if port is not None else -1
        except (AttributeError, OSError, ValueError):
            return False
        if fd < 0:
            return False
        poller = select.poll()
        poller.register(fd, select.POLLIN)
        return any(events & (select.POLLHUP | select.POLLERR) for _, events in poller.poll(0))

    def _log(self, direction: str, text: str) -> None:
        if self.on_exchange is not None:
            self.on_exchange(direction, text)


def _labelled(label: str, request: str) -> str:
    return f"{label}: {request}" if label else request


def _span(address: int, count: int) -> str:
    return f"{address}" if count == 1 else f"{address}..{address + count - 1}"


# -- server -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class RegisterBlock:
    """Consecutive registers a simulated device answers for."""

    table: Table
    address: int
    count: int
    writable: bool = False


class RegisterStore(Protocol):
    """What :class:`ModbusServerThread` asks of a simulated device (called in the server thread).

    Register addresses outside the blocks are answered with ILLEGAL_DATA_ADDRESS and writes to
    read-only blocks likewise, before the store is asked. ``read``/``write`` may return a Modbus
    exception code (int) instead; ``reply_action`` decides, per request, whether the answer is
    sent (``"reply"``), swallowed (``"silent"``) or replaced by closing the connection
    (``"drop"``).
    """

    def blocks(self) -> Iterable[RegisterBlock]: ...

    def read(self, table: Table, address: int, count: int) -> list[int] | int: ...

    def write(self, table: Table, address: int, values: list[int]) -> int | None: ...

    def reply_action(self) -> Literal["reply", "silent", "drop"]: ...


_FUNCTION_TABLE: dict[int, Table] = {3: "holding", 4: "input", 6: "holding", 16: "holding"}


class ModbusServerThread:
    """A real pymodbus server (TCP or RTU) serving a :class:`RegisterStore`, in its own thread.

    pymodbus servers are asyncio; this runs an event loop in a daemon thread and offers blocking
    ``start_*`` / ``stop`` calls.

    Parameters
    ----------
    store : RegisterStore
        The simulated device.
    unit_id : int
        Modbus unit / device id the server answers as.
    name : str
        Thread name (shows up in leak checks).
    """

    def __init__(self, store: RegisterStore, unit_id: int, *, name: str = "labauto-modbus-sim"):
        self.store = store
        self.unit_id = unit_id
        self.name = name
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: Any = None
        self._hang_up: Callable[[], None] | None = None

    @property
    def running(self) -> bool:
        """True between a successful start and stop."""
        return self._thread is not None

    def start_tcp(self, host: str = "127.0.0.1", port: int = 0) -> tuple[str, int]:
        """Serve Modbus TCP on ``host:port`` (port 0 = a free port). Returns ``(host, port)``."""
        return self._start("tcp", host=host, port=port)

    def start_rtu(
        self,
        serial_port: str,
        *,
        baudrate: int = 19200,
        hang_up: Callable[[], None] | None = None,
    ) -> None:
        """Serve Modbus RTU on a serial port (e.g. one end of a :class:`PtyLink`).

        ``hang_up`` is called when the store asks to drop the connection (a serial line has no
        connection to close; a pty link can hang up its other end instead).
        """
        self._hang_up = hang_up
        self._start("rtu", serial_port=serial_port, baudrate=baudrate)

    def stop(self, timeout: float = 5.0) -> None:
        """Shut the server down and join its thread (idempotent)."""
        thread, loop, server = self._thread, self._loop, self._server
        if thread is None or loop is None:
            return
        if server is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError, concurrent.futures.TimeoutError):
                asyncio.run_coroutine_threadsafe(server.shutdown(), loop).result(timeout)
        thread.join(timeout)
        self._thread = self._loop = self._server = None

    # -- internals ----------------------------------------------------------------------------
    def _start(self, kind: str, **options: Any) -> Any:
        if self._thread is not None:
            raise RuntimeError(f"{self.name}: already running")
        sim_device = self._sim_device()
        started: concurrent.futures.Future[Any] = concurrent.futures.Future()
        self._thread = threading.Thread(
            target=self._run, args=(kind, sim_device, options, started), name=self.name, daemon=True
        )
        self._thread.start()
        try:
            return started.result(timeout=10)
        except BaseException:
            self._thread.join(5)
            self._thread = self._loop = self._server = None
            raise

    def _run(
        self,
        kind: str,
        sim_device: Any,
        options: dict[str, Any],
        started: concurrent.futures.Future[Any],
    ) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._serve(kind, sim_device, options, started))
        except BaseException as exc:  # report start-up failures to the caller
            if not started.done():
                started.set_exception(exc)
        finally:
            pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
            for task in pending:
                task.cancel()
            if pending:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            loop.close()

    async def _serve(
        self,
        kind: str,
        sim_device: Any,
        options: dict[str, Any],
        started: concurrent.futures.Future[Any],
    ) -> None:
        from pymodbus.server import ModbusSerialServer, ModbusTcpServer

        if kind == "tcp":
            server = ModbusTcpServer(
                sim_device,
                address=(options["host"], options["port"]),
                trace_packet=self._trace_packet,
            )
        else:
            server = ModbusSerialServer(
                sim_device,
                framer=FramerType.RTU,
                port=options["serial_port"],
                baudrate=options["baudrate"],
                trace_packet=self._trace_packet,
            )
        self._server = server
        await server.serve_forever(background=True)
        if kind == "tcp":
            host, port = server.transport.sockets[0].getsockname()[:2]
            started.set_result((host, port))
        else:
            started.set_result(None)
        await server.serving  # resolved by server.shutdown()

    def _sim_device(self) -> Any:
        try:
            from pymodbus.simulator import DataType, SimData, SimDevice
        except ImportError:
            SimDevice = None
        if SimDevice is None or "action" not in getattr(SimDevice, "__dataclass_fields__", {}):
            raise RuntimeError(
                f"the simulated Modbus device needs pymodbus with SimDevice actions "
                f"(tested with 3.16); installed: {PYMODBUS_VERSION}"
            )
        tables: dict[str, list[Any]] = {"holding": [], "input": []}
        for block in self.store.blocks():
            tables[block.table].append(
                SimData(
                    block.address,
                    count=block.count,
                    values=0,
                    datatype=DataType.REGISTERS,
                    readonly=not block.writable,
                )
            )
        for blocks in tables.values():
            if not blocks:  # pymodbus needs a block per table; an invalid one answers nothing
                blocks.append(SimData(0, count=1, datatype=DataType.INVALID))
        unused_bits = [SimData(0, values=False, datatype=DataType.BITS)]
        return SimDevice(
            self.unit_id,
            simdata=(unused_bits, list(unused_bits), tables["holding"], tables["input"]),
            action=self._action,
        )

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> Any:
        """pymodbus SimDevice hook: let the store answer, then mirror its registers."""
        from pymodbus.constants import ExcCodes

        table = _FUNCTION_TABLE.get(function_code)
        if table is None:
            return ExcCodes.ILLEGAL_FUNCTION
        if set_values is not None:
            code = self.store.write(table, address, [int(v) for v in set_values])
            return ExcCodes(code) if code else None
        if function_code == 6:  # read-back after a single write: the reply echoes the request
            return None
        values = self.store.read(table, address, count)
        if isinstance(values, int):
            return ExcCodes(values)
        offset = address - start_address
        registers[offset : offset + count] = values
        return None

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        """pymodbus packet hook (server thread): swallow or drop replies on request."""
        if not sending:
            return data
        action = self.store.reply_action()
        if action == "reply":
            return data
        if action == "drop":
            if self._hang_up is not None:
                self._hang_up()
            elif self._loop is not None:
                self._loop.call_soon(self._drop_tcp_connections)
        return b""

    def _drop_tcp_connections(self) -> None:
        connections = getattr(self._server, "active_connections", {})
        for connection in list(connections.values()):
            connection.close()
