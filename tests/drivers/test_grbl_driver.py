"""The GRBL driver against the simulated gantry over a real pty and a real TCP socket."""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator

import pytest
from grbl_fixtures import (
    MOTION_TIMEOUT_S,
    SLOW_SPEED,
    TRANSPORTS,
    ExchangeLog,
    gantry,
    make_robot,
    rig,
    serve,
    wait_for,
)

from labauto.drivers.errors import DeviceDisconnected, DeviceRefused, DeviceTimeout
from labauto.drivers.grbl import (
    GrblAlarm,
    GrblError,
    GrblNotArmed,
    GrblReset,
    GrblRobot,
    TravelLimits,
)
from labauto.drivers.grbl_sim import SimulatedGantry

pytestmark = pytest.mark.timeout(15)


@pytest.fixture(params=TRANSPORTS)
def transport(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture
def log() -> ExchangeLog:
    return ExchangeLog()


@pytest.fixture
def sim_and_robot(transport: str, log: ExchangeLog) -> Iterator[tuple[SimulatedGantry, GrblRobot]]:
    with rig(transport, on_exchange=log) as pair:
        yield pair


@pytest.fixture
def slow_rig(transport: str) -> Iterator[tuple[SimulatedGantry, GrblRobot]]:
    """Moves last long enough (0.4 s for 200 mm) to act on them while they run."""
    with rig(transport, {"speed_factor": SLOW_SPEED}) as (sim, robot):
        robot.home()
        yield sim, robot


def close_to(a: tuple[float, ...] | None, b: tuple[float, ...]) -> bool:
    return a is not None and all(
        math.isclose(p, q, abs_tol=1e-3) for p, q in zip(a, b, strict=True)
    )


# --------------------------------------------------------------------------- connection


def test_connect_reads_firmware_and_starts_in_homing_alarm(
    sim_and_robot: tuple[SimulatedGantry, GrblRobot], log: ExchangeLog
) -> None:
    _, robot = sim_and_robot
    assert robot.is_connected
    assert robot.firmware == "1.1h"
    assert log[:2] == [("tx", "$I"), ("rx", "[VER:1.1h.20190830:]")]
    status = robot.status()
    assert status.state == "Alarm"  # homing lock, like GRBL with $22=1
    assert status.position == (0.0, 0.0, 0.0)
    with pytest.raises(GrblAlarm) as alarm:
        robot.wait_idle()
    assert alarm.value.code is None and "home() or unlock()" in str(alarm.value)


@pytest.mark.parametrize("firmware", ["1.1f", "1.1h"])
def test_firmware_version_is_whatever_the_controller_reports(transport: str, firmware: str) -> None:
    with rig(transport, {"firmware": firmware}) as (_, robot):
        assert robot.firmware == firmware


def test_check_reports_identity_and_state(transport: str) -> None:
    with gantry() as sim:
        robot = make_robot(serve(sim, transport), name="picker")
        report = robot.check()  # connects and closes by itself
        assert not robot.is_connected
        assert report == {
            "device": "picker",
            "kind": "grbl",
            "url": robot.url,
            "firmware": "1.1h",
            "state": "Alarm",
            "substate": None,
            "position": [0.0, 0.0, 0.0],
            "last_alarm": None,
            "reset_required": False,
            "build_options": "VZ",
            "armed": True,
            "startup_errors": [],
        }
        with robot:
            robot.home()
            assert robot.identify()["state"] == "Idle"
            assert robot.is_connected  # stays open when it was open


def test_context_manager_closes_and_commands_need_a_connection(transport: str) -> None:
    with gantry() as sim:
        with make_robot(serve(sim, transport)) as robot:
            assert robot.is_connected
        assert not robot.is_connected
        with pytest.raises(DeviceDisconnected, match="not connected"):
            robot.status()


def test_unopenable_port_is_a_disconnect_naming_the_url() -> None:
    robot = make_robot("/nonexistent/ttyGRBL")
    with pytest.raises(DeviceDisconnected, match="/nonexistent/ttyGRBL"):
        robot.connect()
    assert not robot.is_connected


def test_settings_are_read(sim_and_robot: tuple[SimulatedGantry, GrblRobot]) -> None:
    _, robot = sim_and_robot
    settings = robot.settings()
    assert settings[22] == "1"  # homing enabled
    assert float(settings[130]) == 300.0 and float(settings[132]) == 50.0


# --------------------------------------------------------------------------- pick cycle


def test_full_pick_cycle(
    sim_and_robot: tuple[SimulatedGantry, GrblRobot], log: ExchangeLog
) -> None:
    sim, robot = sim_and_robot
    assert robot.home().state == "Idle"
    assert sim.homed

    colony, well = (120.0, 80.0), (250.0, 150.0)
    picked = robot.pick(*colony, z_pick=-42.0, dwell_s=0.2)
    assert picked.state == "Idle"
    assert close_to(picked.position, (*colony, 0.0))
    assert not sim.tool_on

    robot.move_to(*well)
    assert close_to(robot.status().position, (*well, 0.0))
    delivered = robot.deposit(*well, z_deposit=-10.0, dwell_s=0.1)
    assert close_to(delivered.position, (*well, 0.0))
    assert not sim.tool_on

    pick_lines = log.sent()[log.sent().index("G21 G90 G53 G1 Z0.000 F600.000") :]
    assert pick_lines[:9] == [
        "G21 G90 G53 G1 Z0.000 F600.000",  # rise to safe height
        "G21 G90 G53 G1 X120.000 Y80.000 F3000.000",  # travel
        "G21 G90 G53 G1 Z-42.000 F600.000",  # descend
        "G4 P0",  # wait for the motion
        "?",  # confirm Idle
        "M8",  # tool on
        "G4 P0.200",  # dwell
        "M9",  # tool off
        "G21 G90 G53 G1 Z0.000 F600.000",  # rise
    ]
    # Every line the simulator got was logged as sent, in the same order.
    lines_sent = [line for line in log.sent() if line not in ("?", "!", "~", "^X")]
    assert sim.received == lines_sent
    assert all(direction in ("tx", "rx") for direction, _ in log)


def test_tool_output_follows_commands(sim_and_robot: tuple[SimulatedGantry, GrblRobot]) -> None:
    sim, robot = sim_and_robot
    robot.home()
    robot.tool_on()
    assert sim.tool_on
    assert robot.status().accessories == "F"
    robot.tool_off()
    assert not sim.tool_on
    assert robot.status().accessories == ""


def test_custom_tool_commands(transport: str) -> None:
    with rig(transport, tool_on_command="M3 S1000", tool_off_command="M5") as (sim, robot):
        robot.home()
        robot.tool_on()
        assert robot.status().accessories == "S"
        robot.tool_off()
        assert robot.status().accessories == ""
        assert "M3 S1000" in sim.received and "M5" in sim.received


# --------------------------------------------------------------------------- limits


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda r: r.move_to(310.0, 10.0), "x=310.0 is outside"),
        (lambda r: r.move_to(10.0, -1.0), "y=-1.0 is outside"),
        (lambda r: r.move_to(10.0, 10.0, 5.0), "z=5.0 is outside"),
        (lambda r: r.move_to(math.nan, 10.0), "x=nan is not a finite"),
        (lambda r: r.pick(10.0, 10.0, -60.0), "z=-60.0 is outside"),
        (lambda r: r.deposit(10.0, 250.0, -5.0), "y=250.0 is outside"),
        (lambda r: r.pick(10.0, 10.0, -5.0, dwell_s=-1.0), "dwell_s=-1.0"),
    ],
)
def test_targets_outside_limits_are_refused_before_sending(
    sim_and_robot: tuple[SimulatedGantry, GrblRobot], log: ExchangeLog, call, message: str
) -> None:
    sim, robot = sim_and_robot
    robot.home()
    lines, realtime, exchanges = sim.received, sim.realtime_received, len(log)
    with pytest.raises(DeviceRefused, match=message):
        call(robot)
    assert sim.received == lines  # the simulator got nothing at all
    assert sim.realtime_received == realtime
    assert len(log) == exchanges
    robot.move_to(300.0, 200.0, -50.0)  # the limits themselves are allowed
    assert close_to(sim.position, (300.0, 200.0, -50.0))


def test_bad_constructor_arguments_name_the_parameter() -> None:
    with pytest.raises(ValueError, match=r"safe_z: z=5\.0 is outside"):
        GrblRobot("socket://127.0.0.1:1", safe_z=5.0)
    with pytest.raises(ValueError, match="travel_feed must be a positive number"):
        GrblRobot("socket://127.0.0.1:1", travel_feed=0)
    with pytest.raises(ValueError, match="tool_on_command"):
        GrblRobot("socket://127.0.0.1:1", tool_on_command="M8\nM9")


def test_controller_soft_limit_alarm_and_recovery(transport: str) -> None:
    # The driver allows the default 300 x 200 bed; the machine itself only 100 x 100 (and
    # the check at connect, which would say so, is off).
    narrow = TravelLimits(x=(0.0, 100.0), y=(0.0, 100.0), z=(-50.0, 0.0))
    with rig(transport, {"limits": narrow}, check_travel=False) as (sim, robot):
        robot.home()
        with pytest.raises(GrblAlarm) as alarm:
            robot.move_to(150.0, 50.0)
        assert alarm.value.code == 2 and alarm.value.requires_reset
        assert "exceeds machine travel" in str(alarm.value)
        assert sim.state == "Alarm"
        # GRBL ignores everything but a reset now; the driver says so instead of timing out.
        with pytest.raises(GrblAlarm, match="ALARM:2 locks the controller"):
            robot.status()
        assert robot.check()["reset_required"] is True
        robot.home()  # soft reset + $H
        assert robot.status().state == "Idle"
        assert robot.move_to(90.0, 90.0).position == (90.0, 90.0, 0.0)


def test_error_reply_carries_code_and_meaning(
    sim_and_robot: tuple[SimulatedGantry, GrblRobot],
) -> None:
    _, robot = sim_and_robot  # still in the homing alarm
    with pytest.raises(GrblError) as error:
        robot.move_to(10.0, 10.0)
    assert error.value.code == 9
    assert error.value.command == "G21 G90 G53 G1 Z0.000 F600.000"
    assert "error:9" in str(error.value) and "locked out during alarm" in str(error.value)
    robot.unlock()
    assert robot.move_to(10.0, 10.0).state == "Idle"


# --------------------------------------------------------------------------- real-time commands


def test_feed_hold_and_resume_during_a_move(
    slow_rig: tuple[SimulatedGantry, GrblRobot],
) -> None:
    sim, robot = slow_rig
    robot.move_to(200.0, 0.0, wait=False)
    running = robot.status()
    assert running.state == "Run" and running.feed == 3000.0
    robot.feed_hold()
    assert wait_for(lambda: robot.status().substate == 0)  # Hold:1 while decelerating
    held = robot.status()
    assert (held.state, held.substate) == ("Hold", 0)
    assert held.position is not None and 0.0 < held.position[0] < 200.0
    assert robot.status().position == held.position  # stays put while held
    robot.resume()
    done = robot.wait_idle()
    assert done.state == "Idle" and done.position == (200.0, 0.0, 0.0)
    assert sim.realtime_received.count("!") == 1 and sim.realtime_received.count("~") == 1


def test_soft_reset_stops_motion_and_requires_homing(
    slow_rig: tuple[SimulatedGantry, GrblRobot],
) -> None:
    sim, robot = slow_rig
    robot.tool_on()
    robot.move_to(200.0, 100.0, wait=False)
    robot.soft_reset()
    assert robot.last_alarm == 3  # reset while in motion
    stopped = robot.status()
    assert stopped.state == "Alarm"
    assert stopped.position is not None and stopped.position != (200.0, 100.0, 0.0)
    assert not sim.tool_on  # outputs off after a reset
    sent = len(sim.received)
    with pytest.raises(GrblNotArmed, match="soft reset"):
        robot.move_to(10.0, 10.0)
    assert len(sim.received) == sent  # refused before sending
    robot.home()
    assert robot.move_to(10.0, 10.0).position == (10.0, 10.0, 0.0)


def test_soft_reset_while_idle_keeps_position(
    sim_and_robot: tuple[SimulatedGantry, GrblRobot],
) -> None:
    _, robot = sim_and_robot
    robot.home()
    robot.move_to(30.0, 40.0, -5.0)
    robot.soft_reset()
    status = robot.status()
    assert status.state == "Idle" and status.position == (30.0, 40.0, -5.0)
    assert robot.last_alarm is None


def test_emergency_stop_from_another_thread_interrupts_wait(
    slow_rig: tuple[SimulatedGantry, GrblRobot],
) -> None:
    sim, robot = slow_rig
    robot.move_to(200.0, 150.0, wait=False)
    outcome: list[BaseException] = []

    def wait() -> None:
        try:
            robot.wait_idle()
        except BaseException as exc:  # handed to the test thread
            outcome.append(exc)

    waiter = threading.Thread(target=wait)
    waiter.start()
    assert wait_for(lambda: "G4 P0" in sim.received)
    robot.soft_reset()  # the e-stop does not wait for the lock the waiter holds
    waiter.join(timeout=MOTION_TIMEOUT_S)
    assert not waiter.is_alive()
    assert len(outcome) == 1 and isinstance(outcome[0], GrblAlarm)
    assert outcome[0].code == 3
    assert robot.status().state == "Alarm"
    robot.home()
    assert robot.status().state == "Idle"


def test_wait_idle_times_out_while_held(slow_rig: tuple[SimulatedGantry, GrblRobot]) -> None:
    _, robot = slow_rig
    robot.move_to(200.0, 0.0, wait=False)
    robot.feed_hold()
    with pytest.raises(DeviceTimeout, match="G4 P0"):
        robot.wait_idle(timeout=0.2)
    robot.resume()
    # The late ok of the timed-out G4 P0 is taken for the new one; the status poll still waits.
    assert robot.wait_idle().position == (200.0, 0.0, 0.0)


def test_reset_while_a_line_waits_is_reported_as_a_restart(
    slow_rig: tuple[SimulatedGantry, GrblRobot],
) -> None:
    sim, robot = slow_rig
    outcome: list[BaseException] = []

    def dwell() -> None:
        try:
            robot.dwell(3.0)  # 0.3 s at this speed; no motion, so a reset raises no alarm
        except BaseException as exc:  # handed to the test thread
            outcome.append(exc)

    waiter = threading.Thread(target=dwell)
    waiter.start()
    assert wait_for(lambda: "G4 P3.000" in sim.received)
    robot.soft_reset()
    waiter.join(timeout=MOTION_TIMEOUT_S)
    assert len(outcome) == 1 and isinstance(outcome[0], GrblReset)
    # GRBL answers the aborted dwell "ok" before its banner; that ok is not success.
    assert "'G4 P3.000' was cut short by a soft reset" in str(outcome[0])
    assert robot.last_alarm is None
    assert robot.status().state == "Idle"  # GRBL itself would move again: the driver not
    assert not robot.armed
    with pytest.raises(GrblNotArmed):
        robot.dwell(0.1)
    robot.unlock()
    assert robot.armed
