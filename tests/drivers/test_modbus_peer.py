"""Modbus against an implementation we did not write: modbus-tk (PyPI), TCP and RTU.

* Our analyzer driver against a modbus-tk server: an instrument whose protocol stack is
  modbus-tk's, with a small control loop of its own that acts on commands at a 20 ms scan and
  encodes its results with ``struct`` (nothing of labauto's encoding code).
* Our simulated analyzer against modbus-tk's client (``TcpMaster`` / ``RtuMaster``), decoding
  with ``struct`` too.
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
from collections.abc import Iterator

import modbus_tk.defines as cst  # modbus-tk is in the test extras (pyproject.toml)
import pytest
import serial
from analyzer_fixtures import SimPool, sim_pool
from modbus_tk import modbus, modbus_rtu, modbus_tcp

from labauto.drivers.analyzer import Analyzer
from labauto.drivers.errors import ModbusIllegalDataAddress
from labauto.drivers.pty_link import PtyLink

pytestmark = [
    pytest.mark.timeout(30),
    pytest.mark.filterwarnings("ignore:isSet\\(\\) is deprecated:DeprecationWarning"),  # theirs
]

UNIT = 1
LOAD, START, RESET = 1, 2, 4
IDLE, BUSY, DONE = 0, 1, 2


def words_of_text(text: str, registers: int) -> list[int]:
    raw = text.encode("ascii").ljust(2 * registers, b"\0")
    return list(struct.unpack(f">{registers}H", raw))


def text_of_words(words: list[int] | tuple[int, ...]) -> str:
    return struct.pack(f">{len(words)}H", *words).rstrip(b"\0").decode("ascii")


def float_words(value: float) -> list[int]:
    return list(struct.unpack(">2H", struct.pack(">f", value)))


def as_float32(value: float) -> float:
    return struct.unpack(">f", struct.pack(">f", value))[0]


def instrument_result(sample: str) -> dict[str, float | int]:
    """What the modbus-tk instrument measures for ``sample`` (as float32 / integers)."""
    size = len(sample)
    return {
        "od600": as_float32(0.25 + size / 100),
        "ph": as_float32(6.5 + size / 50),
        "cell_count": 1_000_000 + 37 * size,
        "temperature_c": 36.6,
    }


class TkInstrument:
    """A Modbus instrument on a modbus-tk slave, following the default map's layout."""

    def __init__(self, slave: object, analysis_s: float = 0.1) -> None:
        self.slave = slave
        self.analysis_s = analysis_s
        self.counter = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._scan, name="tk-instrument", daemon=True)
        slave.add_block("holding", cst.HOLDING_REGISTERS, 0, 20)  # type: ignore[attr-defined]
        slave.add_block("input", cst.ANALOG_INPUTS, 0, 120)  # type: ignore[attr-defined]
        slave.set_values("input", 100, words_of_text("TK-INSTRUMENT", 8))  # type: ignore[attr-defined]
        slave.set_values("input", 108, [0, 77])  # type: ignore[attr-defined]
        slave.set_values("input", 110, [7])  # type: ignore[attr-defined]
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)

    def _scan(self) -> None:
        busy_until = None
        sample = ""
        while not self._stop.wait(0.02):  # a 20 ms PLC scan
            slave = self.slave
            (command,) = slave.get_values("holding", 0, 1)  # type: ignore[attr-defined]
            if command:
                if command == LOAD:
                    sample = text_of_words(slave.get_values("holding", 1, 8))  # type: ignore[attr-defined]
                    slave.set_values("input", 20, words_of_text(sample, 8))  # type: ignore[attr-defined]
                    slave.set_values("input", 0, [IDLE])  # type: ignore[attr-defined]
                elif command == START and sample:
                    slave.set_values("input", 0, [BUSY])  # type: ignore[attr-defined]
                    busy_until = time.monotonic() + self.analysis_s
                elif command == RESET:
                    sample, busy_until = "", None
                    slave.set_values("input", 0, [IDLE])  # type: ignore[attr-defined]
                slave.set_values("holding", 0, [0])  # type: ignore[attr-defined]
            if busy_until is not None and time.monotonic() >= busy_until:
                busy_until = None
                result = instrument_result(sample)
                words = [
                    *float_words(result["od600"]),
                    *float_words(result["ph"]),
                    *struct.unpack(">2H", struct.pack(">I", result["cell_count"])),
                    round(36.6 * 10),
                ]
                slave.set_values("input", 10, words)  # type: ignore[attr-defined]
                self.counter += 1
                slave.set_values("input", 30, [self.counter])  # type: ignore[attr-defined]
                slave.set_values("input", 0, [DONE])  # type: ignore[attr-defined]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture
def tk_tcp() -> Iterator[tuple[int, TkInstrument]]:
    port = free_port()
    server = modbus_tcp.TcpServer(port=port, address="127.0.0.1")
    server.start()
    instrument = TkInstrument(server.add_slave(UNIT))
    try:
        yield port, instrument
    finally:
        instrument.stop()
        server.stop()


@pytest.fixture
def tk_rtu() -> Iterator[tuple[str, TkInstrument]]:
    with PtyLink("tk-rtu") as link:
        line = serial.Serial(link.server_path, baudrate=19200, timeout=0.05)
        server = modbus_rtu.RtuServer(line)
        server.start()
        instrument = TkInstrument(server.add_slave(UNIT))
        try:
            yield link.client_path, instrument
        finally:
            instrument.stop()
            server.stop()
            with contextlib.suppress(Exception):
                line.close()


def check_driver(analyzer: Analyzer, instrument: TkInstrument) -> None:
    info = analyzer.identify()
    assert info["model"] == "TK-INSTRUMENT" and info["serial_number"] == 77
    for sample in ("S-1", "SAMPLE-0002", "S-1"):
        result = analyzer.analyze(sample, timeout=5)
        expected = instrument_result(sample)
        assert result == {**expected, "temperature_c": pytest.approx(36.6)}
    assert instrument.counter == 3


def test_our_driver_against_a_modbus_tk_tcp_server(tk_tcp: tuple[int, TkInstrument]) -> None:
    port, instrument = tk_tcp
    with Analyzer("tcp", host="127.0.0.1", port=port, timeout=1.0, poll_interval=0.01) as analyzer:
        check_driver(analyzer, instrument)
        with pytest.raises(ModbusIllegalDataAddress, match="ILLEGAL_DATA_ADDRESS"):
            analyzer._link.read_registers("input", 500, 2, UNIT, label="beyond the blocks")


def test_our_driver_against_a_modbus_tk_rtu_server(tk_rtu: tuple[str, TkInstrument]) -> None:
    path, instrument = tk_rtu
    analyzer = Analyzer("rtu", serial_port=path, parity="N", timeout=1.0, poll_interval=0.01)
    with analyzer:
        check_driver(analyzer, instrument)


# --------------------------------------------------------------------------- their client


@pytest.fixture
def make_sim() -> Iterator[SimPool]:
    with sim_pool() as pool:
        yield pool


def run_with_client(master: modbus.Master, sim: object) -> None:
    """A whole analysis driven by modbus-tk's client; values decoded with struct."""
    sample = "TK-42"
    master.execute(UNIT, cst.WRITE_MULTIPLE_REGISTERS, 1, output_value=words_of_text(sample, 8))
    master.execute(UNIT, cst.WRITE_SINGLE_REGISTER, 0, output_value=LOAD)
    assert text_of_words(master.execute(UNIT, cst.READ_INPUT_REGISTERS, 20, 8)) == sample
    master.execute(UNIT, cst.WRITE_SINGLE_REGISTER, 0, output_value=START)
    assert master.execute(UNIT, cst.READ_INPUT_REGISTERS, 0, 1) == (BUSY,)
    with pytest.raises(modbus.ModbusError) as busy:
        master.execute(UNIT, cst.WRITE_SINGLE_REGISTER, 0, output_value=START)
    assert busy.value.get_exception_code() == 6  # SERVER_DEVICE_BUSY
    deadline = time.monotonic() + 5
    while master.execute(UNIT, cst.READ_INPUT_REGISTERS, 0, 1) != (DONE,):
        assert time.monotonic() < deadline
        time.sleep(0.01)
    words = master.execute(UNIT, cst.READ_INPUT_REGISTERS, 10, 7)
    od600, ph = struct.unpack(">ff", struct.pack(">4H", *words[:4]))
    (cells,) = struct.unpack(">I", struct.pack(">2H", *words[4:6]))
    (temperature,) = struct.unpack(">h", struct.pack(">H", words[6]))
    expected = sim.expected_result(sample)  # type: ignore[attr-defined]
    assert (od600, ph, cells) == (expected["od600"], expected["ph"], expected["cell_count"])
    assert temperature / 10 == pytest.approx(expected["temperature_c"])
    assert master.execute(UNIT, cst.READ_INPUT_REGISTERS, 30, 1) == (1,)  # result counter
    with pytest.raises(modbus.ModbusError) as missing:
        master.execute(UNIT, cst.READ_HOLDING_REGISTERS, 900, 1)
    assert missing.value.get_exception_code() == 2  # ILLEGAL_DATA_ADDRESS


def test_our_simulator_against_modbus_tks_tcp_client(make_sim: SimPool) -> None:
    sim, where = make_sim("tcp")
    master = modbus_tcp.TcpMaster(host=where["host"], port=where["port"], timeout_in_sec=1.0)
    try:
        run_with_client(master, sim)
    finally:
        master.close()


def test_our_simulator_against_modbus_tks_rtu_client(make_sim: SimPool) -> None:
    sim, where = make_sim("rtu")
    master = modbus_rtu.RtuMaster(serial.Serial(where["serial_port"], baudrate=19200))
    master.set_timeout(1.0)
    try:
        run_with_client(master, sim)
    finally:
        master.close()
