"""The simulated analyzer and its plumbing, seen through a raw Modbus client (no driver logic).

State-machine timing uses an injected clock, so nothing here sleeps to wait for an analysis.
"""

from __future__ import annotations

import os
import select
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest
from analyzer_fixtures import (
    SimPool,
    assert_no_leaked_threads,
    default_map_data,
    sim_pool,
    write_map,
)

from labauto.drivers.analyzer_map import encode_value, load_map
from labauto.drivers.analyzer_sim import SimulatedAnalyzer, result_for
from labauto.drivers.errors import (
    DeviceDisconnected,
    ModbusIllegalDataAddress,
    ModbusIllegalDataValue,
    ModbusServerDeviceBusy,
)
from labauto.drivers.modbus_adapter import ModbusClientLink, ModbusServerThread
from labauto.drivers.pty_link import PtyLink

pytestmark = pytest.mark.timeout(20)

MAP = load_map()
LOAD, START, ABORT, RESET = (MAP.command.code(n) for n in ("load", "start", "abort", "reset"))
IDLE, BUSY, DONE, ERROR = (MAP.state.code(n) for n in ("idle", "busy", "done", "error"))


class ManualClock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def make_sim() -> Iterator[SimPool]:
    with sim_pool() as pool:
        yield pool


@pytest.fixture
def clocked(make_sim: SimPool) -> Iterator[tuple[SimulatedAnalyzer, ModbusClientLink, ManualClock]]:
    """A TCP simulator on a manual clock (analysis 2 s at speed 4 = 0.5 s) and a raw client."""
    clock = ManualClock()
    sim, where = make_sim("tcp", analysis_seconds=2.0, speed_factor=4.0, clock=clock)
    link = ModbusClientLink("tcp", host=where["host"], port=where["port"], timeout=1.0)
    link.connect()
    yield sim, link, clock
    link.close()


def _state(link: ModbusClientLink) -> int:
    return link.read_registers("input", MAP.state.field.address, 1, unit=1)[0]


def _load(link: ModbusClientLink, sample_id: str) -> None:
    link.write_registers(MAP.sample_id.address, encode_value(MAP.sample_id, sample_id), unit=1)
    link.write_registers(MAP.command.field.address, [LOAD], unit=1)


def test_analysis_takes_analysis_seconds_divided_by_speed_factor(clocked) -> None:
    sim, link, clock = clocked
    _load(link, "S-77")
    link.write_registers(0, [START], unit=1)
    assert _state(link) == BUSY
    clock.now += 0.375  # binary-exact steps: 0.375 + 0.125 = 0.5 s exactly
    assert _state(link) == BUSY
    assert link.read_registers("input", 10, 7, unit=1) == [0] * 7  # no result while busy
    clock.now += 0.125
    assert _state(link) == DONE
    result = sim.expected_result("S-77")
    expected = [r for f in MAP.results for r in encode_value(f, result[f.name])]
    assert link.read_registers("input", 10, 7, unit=1) == expected


def test_command_register_reads_back_zero_and_sample_id_is_kept(clocked) -> None:
    _, link, _ = clocked
    _load(link, "AB")
    assert link.read_registers("holding", 0, 1, unit=1) == [0]
    assert link.read_registers("holding", 1, 2, unit=1) == [0x4142, 0]


@pytest.mark.parametrize(
    ("setup", "command", "error_type"),
    [
        ([], START, ModbusIllegalDataValue),  # start with no sample loaded
        ([], 99, ModbusIllegalDataValue),  # unknown command code
        (["load", "start"], LOAD, ModbusServerDeviceBusy),  # load while busy
        (["load", "start"], START, ModbusServerDeviceBusy),  # start while busy
        (["load", "start", "finish"], START, ModbusIllegalDataValue),  # one run per load
    ],
)
def test_commands_refused_in_the_wrong_state(clocked, setup, command, error_type) -> None:
    _, link, clock = clocked
    for step in setup:
        if step == "load":
            _load(link, "S-1")
        elif step == "start":
            link.write_registers(0, [START], unit=1)
        else:
            clock.now += 10
    with pytest.raises(error_type):
        link.write_registers(0, [command], unit=1)


def test_empty_sample_id_cannot_be_loaded(clocked) -> None:
    _, link, _ = clocked
    with pytest.raises(ModbusIllegalDataValue):
        link.write_registers(0, [LOAD], unit=1)


def test_error_state_then_reset(clocked) -> None:
    sim, link, clock = clocked
    sim.inject_fault("error_state", code=513)
    _load(link, "S-1")
    link.write_registers(0, [START], unit=1)
    clock.now += 1
    assert link.read_registers("input", 0, 2, unit=1) == [ERROR, 513]
    link.write_registers(0, [ABORT], unit=1)  # abort does not leave the error state
    assert _state(link) == ERROR
    link.write_registers(0, [RESET], unit=1)
    assert link.read_registers("input", 0, 2, unit=1) == [IDLE, 0]


def test_unmapped_and_read_only_registers_are_illegal_addresses(
    make_sim: SimPool, tmp_path: Path
) -> None:
    data = default_map_data()
    data["error_code"]["table"] = "holding"
    data["error_code"]["address"] = 20  # a read-only holding register
    map_path = write_map(tmp_path, data)
    _, where = make_sim("tcp", register_map=map_path)
    link = ModbusClientLink("tcp", host=where["host"], port=where["port"], timeout=1.0)
    link.connect()
    assert link.read_registers("holding", 20, 1, unit=1) == [0]
    with pytest.raises(ModbusIllegalDataAddress, match="write holding 20"):
        link.write_registers(20, [5], unit=1)
    with pytest.raises(ModbusIllegalDataAddress, match="read input 17"):
        link.read_registers("input", 17, 1, unit=1)  # the gap after the results
    with pytest.raises(ModbusIllegalDataAddress):
        link.read_registers("input", 10, 8, unit=1)  # reads one register past the results
    link.close()


def test_result_recipe_is_deterministic_and_in_range() -> None:
    first, again, other = result_for(MAP, "S-1"), result_for(MAP, "S-1"), result_for(MAP, "S-2")
    assert first == again and first != other
    values = [result_for(MAP, f"S-{i}") for i in range(200)]
    assert all(0.05 <= v["od600"] <= 2.5 and 5.5 <= v["ph"] <= 8.5 for v in values)
    assert all(30.0 <= v["temperature_c"] <= 37.5 for v in values)
    assert len({v["od600"] for v in values}) == 200


def test_fault_arguments_are_checked() -> None:
    sim = SimulatedAnalyzer(faults={"exception": 2, "busy": None, "error_state": {"code": 9}})
    assert sim.faults == {"exception": 2, "busy": None, "error_state": 9}
    sim.clear_fault("busy")
    assert "busy" not in sim.faults
    with pytest.raises(ValueError, match="unknown fault 'smoke'"):
        sim.inject_fault("smoke")
    with pytest.raises(ValueError, match="exception code must be one of"):
        sim.inject_fault("exception", code=9)
    with pytest.raises(ValueError, match="takes no code"):
        sim.inject_fault("no_reply", code=1)
    with pytest.raises(ValueError, match="speed_factor must be > 0"):
        SimulatedAnalyzer(speed_factor=0)


# -- clean start and stop ---------------------------------------------------------------------
def test_stop_closes_the_port_and_joins_threads_and_can_restart() -> None:
    sim = SimulatedAnalyzer()
    host, port = sim.start_tcp()
    socket.create_connection((host, port), timeout=1).close()
    sim.stop()
    sim.stop()  # idempotent
    assert_no_leaked_threads()
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((host, port), timeout=1)
    with sim:
        path = sim.start_rtu()
        assert os.path.exists(path)
    assert not os.path.exists(path)  # the pty link folder is gone
    assert_no_leaked_threads()


def test_server_on_a_missing_serial_port_fails_at_start(tmp_path: Path) -> None:
    server = ModbusServerThread(SimulatedAnalyzer(), unit_id=1)
    with pytest.raises(Exception, match=r"ttyNOPE|listen"):
        server.start_rtu(str(tmp_path / "ttyNOPE"))
    assert not server.running
    assert_no_leaked_threads()


def test_client_link_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="transport must be 'tcp' or 'rtu'"):
        ModbusClientLink("udp")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="needs serial_port"):
        ModbusClientLink("rtu")
    with pytest.raises(ValueError, match="timeout must be > 0"):
        ModbusClientLink("tcp", timeout=0)


# -- the pty link -----------------------------------------------------------------------------
def _read_exactly(fd: int, size: int, timeout: float = 2.0) -> bytes:
    data = b""
    while len(data) < size:
        ready, _, _ = select.select([fd], [], [], timeout)
        assert ready, f"only {data!r} arrived"
        data += os.read(fd, size - len(data))
    return data


def _open_raw(path: str) -> int:
    import tty

    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    return fd


def test_pty_link_relays_both_ways_and_hang_up_gives_a_fresh_line() -> None:
    with PtyLink() as link:
        client, server = _open_raw(link.client_path), _open_raw(link.server_path)
        payload = bytes(range(256))  # 8-bit clean: no echo, no line editing
        os.write(client, payload)
        assert _read_exactly(server, 256) == payload
        os.write(server, b"\x01\x03\x02\x00\x00")
        assert _read_exactly(client, 5) == b"\x01\x03\x02\x00\x00"
        old_target = os.readlink(link.client_path)
        link.hang_up_client()
        assert os.readlink(link.client_path) != old_target
        with pytest.raises(OSError):
            os.write(client, b"x")  # the old line is hung up
        os.close(client)
        client = _open_raw(link.client_path)
        os.write(client, b"again")
        assert _read_exactly(server, 5) == b"again"
        os.close(client)
        os.close(server)
    assert_no_leaked_threads()


def test_rtu_driver_sees_a_hung_up_port_as_disconnected(make_sim: SimPool) -> None:
    sim, where = make_sim("rtu")
    link = ModbusClientLink("rtu", serial_port=where["serial_port"], timeout=0.25)
    link.connect()
    assert link.read_registers("input", 0, 1, unit=1) == [IDLE]
    sim._link.hang_up_client()  # the adapter is unplugged between two requests
    with pytest.raises(DeviceDisconnected):
        link.read_registers("input", 0, 1, unit=1)
    link.close()
    link.connect()  # plugged back in: same path, new line
    assert link.read_registers("input", 0, 1, unit=1) == [IDLE]
    link.close()
