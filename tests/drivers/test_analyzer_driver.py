"""The real Analyzer driver against the real simulated analyzer, over TCP and over RTU (pty).

Tests taking the ``rig`` or ``transport`` fixture run once per transport. Every injected fault
must give its own error, and the driver must work again after ``reconnect()``.
"""

from __future__ import annotations

import socket
import struct
from collections.abc import Iterator
from pathlib import Path

import pytest
from analyzer_fixtures import (
    REPLY_TIMEOUT_S,
    TRANSPORTS,
    SimPool,
    connected_rig,
    default_map_data,
    sim_pool,
    write_map,
)

from labauto.drivers.analyzer import Analyzer, exchange_logger
from labauto.drivers.analyzer_sim import SimulatedAnalyzer
from labauto.drivers.errors import (
    AnalyzerError,
    DeviceDisconnected,
    DeviceFault,
    DeviceRefused,
    DeviceTimeout,
    ModbusExceptionReply,
    ModbusIllegalDataAddress,
    ModbusIllegalDataValue,
    ModbusServerDeviceBusy,
    ModbusServerDeviceFailure,
)
from labauto.drivers.modbus_adapter import ModbusClientLink

pytestmark = pytest.mark.timeout(20)

Rig = tuple[SimulatedAnalyzer, Analyzer]


@pytest.fixture
def make_sim() -> Iterator[SimPool]:
    """``make_sim(transport, **sim_kwargs) -> (sim, where)``; all stopped after the test."""
    with sim_pool() as pool:
        yield pool


@pytest.fixture(params=TRANSPORTS)
def transport(request: pytest.FixtureRequest) -> str:
    """Run the test once over Modbus TCP and once over Modbus RTU on a pty."""
    return request.param


@pytest.fixture
def rig(make_sim: SimPool, transport: str) -> Iterator[Rig]:
    """A running simulator and a connected driver (poll interval 10 ms)."""
    with connected_rig(make_sim, transport) as pair:
        yield pair


def _recovers(sim: SimulatedAnalyzer, analyzer: Analyzer, sample_id: str = "AFTER-1") -> None:
    """Clear the faults, reconnect, reset, and run a whole analysis correctly."""
    sim.clear_fault()
    analyzer.reconnect()
    analyzer.reset()
    assert analyzer.state() == "idle"
    assert analyzer.analyze(sample_id, timeout=5) == sim.expected_result(sample_id)


# -- full cycle -------------------------------------------------------------------------------
class ManualClock:
    """A clock the test moves by hand, so "still busy" does not depend on machine speed."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_full_cycle_step_by_step(make_sim: SimPool, transport: str) -> None:
    clock = ManualClock()
    sim, where = make_sim(transport, clock=clock)  # analysis: 1 s / speed 20 = 50 ms
    analyzer = Analyzer(**where, timeout=REPLY_TIMEOUT_S, poll_interval=0.01)
    analyzer.connect()
    assert analyzer.state() == "idle"
    analyzer.load_sample("S-0001")
    assert analyzer.state() == "idle"
    analyzer.start()
    assert analyzer.state() == "busy"
    with pytest.raises(DeviceTimeout, match=r"not done after 0\.05 s \(state busy\)"):
        analyzer.wait_done(timeout=0.05)
    clock.now += 0.05
    analyzer.wait_done(timeout=5)
    assert analyzer.state() == "done"
    result = analyzer.read_result()
    assert result == sim.expected_result("S-0001")
    assert list(result) == ["od600", "ph", "cell_count", "temperature_c"]
    assert isinstance(result["cell_count"], int) and isinstance(result["od600"], float)
    assert 0.05 <= result["od600"] <= 2.5 and 5.5 <= result["ph"] <= 8.5
    analyzer.close()


def test_analyze_gives_each_sample_its_own_deterministic_result(rig: Rig) -> None:
    sim, analyzer = rig
    first = analyzer.analyze("S-0001", timeout=5)
    second = analyzer.analyze("S-0002", timeout=5)
    again = analyzer.analyze("S-0001", timeout=5)
    assert first == again == sim.expected_result("S-0001")
    assert second == sim.expected_result("S-0002")
    assert first != second


def test_identify_reports_state_and_identification_registers(rig: Rig) -> None:
    _, analyzer = rig
    info = analyzer.identify()
    assert info["state"] == "idle" and info["error_code"] == 0
    assert info["model"] == "labauto AZ-1 sim"  # read from the identification registers
    assert (info["serial_number"], info["firmware_version"]) == (4242, 102)
    assert info["unit_id"] == 1 and info["endpoint"] == analyzer.endpoint


def test_context_manager_connects_and_closes(make_sim: SimPool) -> None:
    _, where = make_sim("tcp")
    with Analyzer(**where, timeout=REPLY_TIMEOUT_S) as analyzer:
        assert analyzer.state() == "idle"
    assert not analyzer._link.connected


def test_abort_returns_a_running_analysis_to_idle(rig: Rig) -> None:
    sim, analyzer = rig
    sim.analysis_seconds = 100.0  # 5 s at speed 20: abort long before the end
    analyzer.load_sample("S-9")
    analyzer.start()
    assert analyzer.state() == "busy"
    analyzer.abort()
    assert analyzer.state() == "idle"
    with pytest.raises(ModbusIllegalDataValue, match="ILLEGAL_DATA_VALUE"):
        analyzer.start()  # the sample was unloaded by the abort


# -- injected faults ----------------------------------------------------------------------------
def test_busy_refuses_load_and_wait_done_times_out(rig: Rig) -> None:
    sim, analyzer = rig
    sim.inject_fault("busy")
    assert analyzer.state() == "busy"
    with pytest.raises(ModbusServerDeviceBusy) as info:
        analyzer.load_sample("S-1")
    error = info.value
    assert (error.code, error.exception_name) == (6, "SERVER_DEVICE_BUSY")
    assert str(error) == (
        "analyzer: command load: write holding 0 = [1] unit 1: "
        "Modbus exception SERVER_DEVICE_BUSY (code 6)"
    )
    with pytest.raises(DeviceTimeout, match=r"not done after 0\.2 s \(state busy\)"):
        analyzer.wait_done(timeout=0.2)
    _recovers(sim, analyzer)


def test_busy_during_an_analysis_keeps_it_from_finishing(rig: Rig) -> None:
    sim, analyzer = rig
    analyzer.load_sample("S-1")
    analyzer.start()
    sim.inject_fault("busy")
    with pytest.raises(DeviceTimeout):
        analyzer.wait_done(timeout=0.2)  # 4x the analysis time
    sim.clear_fault("busy")
    analyzer.wait_done(timeout=5)
    assert analyzer.read_result() == sim.expected_result("S-1")


def test_error_state_raises_the_analyzers_error_code(rig: Rig) -> None:
    sim, analyzer = rig
    sim.inject_fault("error_state", code=42)
    with pytest.raises(AnalyzerError) as info:
        analyzer.analyze("S-1", timeout=5)
    assert info.value.code == 42 and "error code 42" in str(info.value)
    assert analyzer.state() == "error" and analyzer.error_code() == 42
    with pytest.raises(ModbusIllegalDataValue):
        analyzer.load_sample("S-2")  # the analyzer wants a reset first
    _recovers(sim, analyzer)
    assert analyzer.error_code() == 0


@pytest.mark.parametrize(
    ("code", "error_type", "name"),
    [
        (2, ModbusIllegalDataAddress, "ILLEGAL_DATA_ADDRESS"),
        (4, ModbusServerDeviceFailure, "SERVER_DEVICE_FAILURE"),
        (6, ModbusServerDeviceBusy, "SERVER_DEVICE_BUSY"),
    ],
)
def test_exception_replies_map_to_their_own_errors(
    rig: Rig, code: int, error_type: type[ModbusExceptionReply], name: str
) -> None:
    sim, analyzer = rig
    sim.inject_fault("exception", code=code)
    with pytest.raises(error_type) as info:
        analyzer.state()
    assert isinstance(info.value, DeviceFault)
    assert (info.value.exception_code, info.value.exception_name) == (code, name)
    assert f"state: read input 0 unit 1: Modbus exception {name} (code {code})" in str(info.value)
    with pytest.raises(error_type):
        analyzer.load_sample("S-1")  # writes are refused too
    _recovers(sim, analyzer)


def test_no_reply_is_a_timeout_and_the_request_is_ignored(rig: Rig) -> None:
    sim, analyzer = rig
    analyzer.load_sample("S-1")
    sim.inject_fault("no_reply")
    # start() reads the state first (to see the command taken afterwards): that read times out.
    no_reply = rf"state: .* no reply within {REPLY_TIMEOUT_S:g} s"
    with pytest.raises(DeviceTimeout, match=no_reply):
        analyzer.start()
    with pytest.raises(DeviceTimeout):
        analyzer.state()
    sim.clear_fault()
    analyzer.reconnect()
    assert analyzer.state() == "idle"  # the start sent during no_reply never happened
    _recovers(sim, analyzer)


def test_dropped_connection_is_reported_and_reconnect_works(rig: Rig) -> None:
    sim, analyzer = rig
    sim.inject_fault("drop_connection")
    with pytest.raises(DeviceDisconnected, match=r"lost or refused|hung up"):
        analyzer.state()
    _recovers(sim, analyzer)


def test_reconnect_while_the_fault_lasts_fails_clearly_then_succeeds(rig: Rig) -> None:
    sim, analyzer = rig
    sim.inject_fault("no_reply")
    with pytest.raises(DeviceTimeout):
        analyzer.reconnect()  # connect() checks that the analyzer answers
    _recovers(sim, analyzer)


def test_faults_given_at_construction(make_sim: SimPool, transport: str) -> None:
    sim, where = make_sim(transport, faults={"exception": 2})
    analyzer = Analyzer(**where, timeout=REPLY_TIMEOUT_S)
    with pytest.raises(ModbusIllegalDataAddress):
        analyzer.connect()
    assert not analyzer._link.connected
    _recovers(sim, analyzer)
    analyzer.close()


# -- connection problems ----------------------------------------------------------------------
def test_nothing_listening_is_a_clear_disconnect(tmp_path: Path) -> None:
    with socket.socket() as probe:  # a port that was free a moment ago
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(DeviceDisconnected, match=f"cannot connect to tcp 127.0.0.1:{port}"):
        Analyzer("tcp", port=port, timeout=REPLY_TIMEOUT_S).connect()
    missing = tmp_path / "ttyNOPE"
    with pytest.raises(DeviceDisconnected, match=r"cannot connect to rtu .*ttyNOPE"):
        Analyzer("rtu", serial_port=str(missing), timeout=REPLY_TIMEOUT_S).connect()


def test_simulator_stopped_under_the_driver(make_sim: SimPool) -> None:
    sim, where = make_sim("tcp")
    analyzer = Analyzer(**where, timeout=REPLY_TIMEOUT_S)
    analyzer.connect()
    sim.stop()
    with pytest.raises(DeviceDisconnected):
        analyzer.state()
    with pytest.raises(DeviceDisconnected):
        analyzer.reconnect()  # the port is closed now
    assert sim.start_tcp(port=where["port"])[1] == where["port"]  # back on the same port
    analyzer.reconnect()
    assert analyzer.analyze("S-5", timeout=5) == sim.expected_result("S-5")
    analyzer.close()


# -- driver-side checks and logging -------------------------------------------------------------
def test_sample_id_that_does_not_fit_is_refused_before_sending(make_sim: SimPool) -> None:
    _, where = make_sim("tcp")
    lines: list[str] = []
    analyzer = Analyzer(**where, timeout=REPLY_TIMEOUT_S, on_exchange=exchange_logger(lines.append))
    analyzer.connect()
    sent_before = len(lines)
    with pytest.raises(DeviceRefused, match="has 17 characters; the map allows 16"):
        analyzer.load_sample("S" * 17)
    with pytest.raises(DeviceRefused, match="unknown code name 'calibrate'"):
        analyzer.command("calibrate")
    assert len(lines) == sent_before
    analyzer.close()


def test_on_exchange_sees_every_request_and_outcome(make_sim: SimPool) -> None:
    sim, where = make_sim("tcp")
    log: list[tuple[str, str]] = []

    def record(direction: str, text: str) -> None:
        log.append((direction, text))

    with Analyzer(**where, timeout=REPLY_TIMEOUT_S, on_exchange=record) as a:
        a.load_sample("AB")
        sim.inject_fault("exception", code=6)
        with pytest.raises(ModbusServerDeviceBusy):
            a.state()
    assert log[:6] == [
        ("tx", "state: read input 0 unit 1"),  # connect() checks the state
        ("rx", "[0]"),
        ("tx", "sample id 'AB': write holding 1..8 = [16706, 0, 0, 0, 0, 0, 0, 0] unit 1"),
        ("rx", "ok"),
        ("tx", "command load: write holding 0 = [1] unit 1"),
        ("rx", "ok"),
    ]
    assert log[-1] == ("rx", "exception SERVER_DEVICE_BUSY (6)")


# -- word order -----------------------------------------------------------------------------------
def test_float32_word_order_big_and_little_over_the_wire(make_sim: SimPool, tmp_path: Path) -> None:
    little_data = default_map_data()
    little_data["word_order"] = "little"
    little_map = write_map(tmp_path, little_data, "little.yaml")
    raw: dict[str, list[int]] = {}
    for order, map_path in (("big", None), ("little", little_map)):
        sim, where = make_sim("tcp", register_map=map_path)
        with Analyzer(**where, register_map=map_path, timeout=REPLY_TIMEOUT_S) as analyzer:
            result = analyzer.analyze("S-WORD", timeout=5)
        assert result == sim.expected_result("S-WORD")
        link = ModbusClientLink("tcp", host=where["host"], port=where["port"], timeout=1)
        link.connect()
        raw[order] = link.read_registers("input", 10, 2, unit=1)  # od600, float32
        link.close()
    od600 = result["od600"]
    high, low = struct.unpack(">HH", struct.pack(">f", od600))
    assert raw["big"] == [high, low]
    assert raw["little"] == [low, high]
    assert high != low
