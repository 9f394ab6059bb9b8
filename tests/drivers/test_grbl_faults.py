"""Injected faults: each gives its own error type, and the driver recovers by reconnecting."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from grbl_fixtures import TRANSPORTS, ExchangeLog, gantry, make_robot, rig, serve

from labauto.drivers.errors import (
    DeviceDisconnected,
    DeviceTimeout,
    UnexpectedReply,
)
from labauto.drivers.grbl import GrblAlarm, GrblRobot
from labauto.drivers.grbl_sim import Fault, SimulatedGantry

pytestmark = pytest.mark.timeout(15)


@pytest.fixture(params=TRANSPORTS)
def transport(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture
def log() -> ExchangeLog:
    return ExchangeLog()


@pytest.fixture
def homed(transport: str, log: ExchangeLog) -> Iterator[tuple[SimulatedGantry, GrblRobot]]:
    with rig(transport, on_exchange=log) as (sim, robot):
        robot.home()
        yield sim, robot


def works_after_reconnect(robot: GrblRobot) -> None:
    """The driver reconnects and completes a full pick."""
    robot.reconnect()
    assert robot.is_connected and robot.firmware == "1.1h"
    robot.home()
    done = robot.pick(50.0, 60.0, -20.0, dwell_s=0.05)
    assert done.state == "Idle" and done.position == (50.0, 60.0, 0.0)


def test_no_reply_is_a_timeout(homed: tuple[SimulatedGantry, GrblRobot]) -> None:
    sim, robot = homed
    robot.move_to(10.0, 20.0)
    sim.inject("no_reply")
    with pytest.raises(DeviceTimeout, match=r"no reply to 'G21 G90 G53 G1 Z0\.000 F600\.000'"):
        robot.move_to(30.0, 40.0, wait=False)
    assert sim.received[-1] == "G21 G90 G53 G1 Z0.000 F600.000"  # swallowed, not executed
    assert sim.position == (10.0, 20.0, 0.0)
    assert sim.faults == []
    works_after_reconnect(robot)


def test_garbled_reply_is_unexpected(homed: tuple[SimulatedGantry, GrblRobot]) -> None:
    sim, robot = homed
    sim.inject("garbled")
    with pytest.raises(UnexpectedReply, match=r"to 'M8' is not GRBL's") as error:
        robot.tool_on()
    assert "\ufffd" in str(error.value)  # the noise is shown as received
    assert sim.tool_on  # executed; only the answer was lost
    works_after_reconnect(robot)


def test_short_delay_is_tolerated(homed: tuple[SimulatedGantry, GrblRobot]) -> None:
    sim, robot = homed
    sim.inject("delay", seconds=0.1, count=2)  # below the 0.3 s reply timeout
    robot.tool_on()
    robot.tool_off()
    assert sim.faults == [] and not sim.tool_on


def test_long_delay_is_a_timeout_and_the_late_ok_is_not_misread(
    homed: tuple[SimulatedGantry, GrblRobot], log: ExchangeLog
) -> None:
    sim, robot = homed
    sim.inject("delay", seconds=0.4)
    with pytest.raises(DeviceTimeout, match=r"no reply to '\$X'"):
        robot.unlock()
    robot.reconnect()  # the late "ok" of $X comes before the answer to $I and is skipped
    tail = log[log.index(("tx", "$I"), 2) :]
    assert [line for _, line in tail[:4]] == ["$I", "ok", "[VER:1.1h.20190830:]", "[OPT:VZ,15,128]"]
    works_after_reconnect(robot)


def test_alarm_mid_move_is_an_alarm_and_needs_reset(
    homed: tuple[SimulatedGantry, GrblRobot],
) -> None:
    sim, robot = homed
    sim.inject("alarm_mid_move", code=1, fraction=0.5)
    with pytest.raises(GrblAlarm) as alarm:
        robot.move_to(200.0, 100.0)
    assert alarm.value.code == 1 and alarm.value.requires_reset
    assert "Hard limit" in str(alarm.value) and "soft_reset(), then home()" in str(alarm.value)
    x, y, z = sim.position  # stopped half-way along the XY travel
    assert (x, y, z) == pytest.approx((100.0, 50.0, 0.0), abs=1e-6)
    assert sim.state == "Alarm"
    with pytest.raises(GrblAlarm, match="ALARM:1 locks the controller"):
        robot.status()
    works_after_reconnect(robot)  # the handshake resets the locked controller first
    assert sim.realtime_received.count("^X") == 1


def test_disconnect_is_detected_and_reconnect_finds_the_device_again(
    homed: tuple[SimulatedGantry, GrblRobot], transport: str
) -> None:
    sim, robot = homed
    sim.inject("disconnect")
    with pytest.raises(DeviceDisconnected, match="lost"):
        robot.tool_on()
    assert not robot.is_connected
    with pytest.raises(DeviceDisconnected, match="not connected"):
        robot.status()
    if transport == "pty":  # a new pty behind the same path, like a re-enumerated USB adapter
        assert os.path.realpath(robot.url) == sim.pty_device
    works_after_reconnect(robot)


@pytest.mark.parametrize(
    ("fault", "error", "message"),
    [
        ({"fault": "no_reply"}, DeviceTimeout, "no answer to '\\$I'"),
        ({"fault": "garbled"}, UnexpectedReply, "answer to '\\$I' is not GRBL's"),
        (Fault("delay", seconds=0.5), DeviceTimeout, "no answer to '\\$I'"),
    ],
)
def test_faults_from_the_constructor_fail_connect_cleanly(
    transport: str, fault: object, error: type[Exception], message: str
) -> None:
    with gantry(faults=[fault]) as sim:
        robot = make_robot(serve(sim, transport))
        with pytest.raises(error, match=message):
            robot.connect()
        assert not robot.is_connected
        works_after_reconnect(robot)
        robot.close()


def test_clear_faults_disarms_them(homed: tuple[SimulatedGantry, GrblRobot]) -> None:
    sim, robot = homed
    sim.inject("no_reply", count=3)
    sim.inject("disconnect")
    assert [f.kind for f in sim.faults] == ["no_reply", "disconnect"]
    sim.clear_faults()
    robot.tool_on()
    assert sim.tool_on and sim.faults == []


@pytest.mark.parametrize(
    ("kind", "options", "message"),
    [
        ("melt", {}, "unknown fault 'melt'"),
        ("no_reply", {"count": 0}, "count must be >= 1"),
        ("delay", {"seconds": -1}, "seconds must be >= 0"),
        ("alarm_mid_move", {"fraction": 1.5}, r"fraction must be in \(0, 1\)"),
        ("garbled", {"colour": "red"}, "colour"),
    ],
)
def test_bad_fault_configs_are_named(kind: str, options: dict[str, object], message: str) -> None:
    with gantry() as sim, pytest.raises(ValueError, match=message):
        sim.inject(kind, **options)
    with pytest.raises(ValueError, match="has no 'fault' key"):
        Fault.from_config({"count": 2})
