"""The analyzer driver confirms each command before it trusts ``done`` (PLC scan cycles).

An analyzer behind a PLC front-end acts on a command only at its next scan. Without confirming,
``analyze(B)`` right after ``analyze(A)`` can see A's ``done`` and read A's result as B's.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from analyzer_fixtures import TRANSPORTS, SimPool, default_map_data, sim_pool, write_map

from labauto.drivers.analyzer import Analyzer
from labauto.drivers.analyzer_map import load_map
from labauto.drivers.errors import DeviceTimeout

pytestmark = pytest.mark.timeout(30)

SCAN_S = 0.1


@pytest.fixture
def make_sim() -> Iterator[SimPool]:
    with sim_pool() as pool:
        yield pool


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_each_sample_gets_its_own_result_from_an_analyzer_with_a_100_ms_scan(
    make_sim: SimPool, transport: str
) -> None:
    sim, where = make_sim(transport, scan_cycle_s=SCAN_S)
    with Analyzer(**where, timeout=1.0, poll_interval=0.01) as analyzer:
        for sample in ("A-0001", "B-0002", "C-0003", "B-0002"):
            assert analyzer.analyze(sample, timeout=5) == sim.expected_result(sample)


def test_the_scan_cycle_holds_the_command_until_the_next_scan(make_sim: SimPool) -> None:
    sim, _ = make_sim("tcp", scan_cycle_s=SCAN_S)
    command = sim.map.command
    sim.write("holding", sim.map.sample_id.address, [0x4131, 0])  # "A1"
    sim.write("holding", command.field.address, [command.code("load")])
    assert sim.read("holding", command.field.address, 1) == [command.code("load")]
    time.sleep(SCAN_S * 1.2)
    assert sim.read("holding", command.field.address, 1) == [0]  # taken at the scan


def short_timeout_map(tmp_path: Path, bare: bool = False) -> object:
    data = default_map_data()
    data["timing"]["command_timeout_s"] = 0.3
    if bare:
        data["command"]["clears"] = False
        del data["confirmation"]
    return load_map(write_map(tmp_path, data))


def test_without_any_confirmation_the_driver_fails_clearly_instead_of_trusting_the_state(
    make_sim: SimPool, tmp_path: Path
) -> None:
    """A map that offers nothing to confirm a load with: the lost load is reported."""
    bare = short_timeout_map(tmp_path, bare=True)
    _, where = make_sim("tcp", scan_cycle_s=SCAN_S, register_map=bare)
    analyzer = Analyzer(**where, register_map=bare, timeout=1.0, poll_interval=0.01)
    with (
        analyzer,
        pytest.raises(DeviceTimeout, match=r"did not take the start within 0.3 s: .*idle"),
    ):
        analyzer.analyze("A-0001", timeout=5)  # load and start land in one scan: start is lost


def test_a_load_the_analyzer_dropped_is_named_by_the_sample_echo(
    make_sim: SimPool, tmp_path: Path
) -> None:
    short = short_timeout_map(tmp_path)
    sim, where = make_sim("tcp", scan_cycle_s=SCAN_S, register_map=short)
    with Analyzer(**where, register_map=short, timeout=1.0, poll_interval=0.01) as analyzer:
        assert analyzer.analyze("A-0001", timeout=5) == sim.expected_result("A-0001")
        sim.inject_fault("busy")  # at the scan the load is dropped, without an exception
        with pytest.raises(DeviceTimeout, match=r"load of sample 'B-0002'.*echo reads 'A-0001'"):
            analyzer.load_sample("B-0002")
        sim.clear_fault()
        assert analyzer.analyze("B-0002", timeout=5) == sim.expected_result("B-0002")


def test_unit_id_parity_and_stop_bits_are_checked() -> None:
    for bad in (0, 248, 255, -1, True):
        with pytest.raises(ValueError, match=r"unit_id must be 1..247"):
            Analyzer("tcp", unit_id=bad)  # type: ignore[arg-type]
    assert Analyzer("tcp", unit_id=247).unit_id == 247
    with pytest.raises(ValueError, match="parity must be"):
        Analyzer("rtu", serial_port="/dev/null", parity="X")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="stopbits must be 1 or 2"):
        Analyzer("rtu", serial_port="/dev/null", stopbits=3)  # type: ignore[arg-type]
    assert Analyzer("rtu", serial_port="/dev/ttyS9").endpoint.endswith(
        "19200 8E1"
    )  # Modbus default
