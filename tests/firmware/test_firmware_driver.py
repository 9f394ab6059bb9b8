"""The GRBL driver against the real GRBL 1.1h firmware (grbl-sim) through our pty bridge.

The firmware stores 200 x 200 x 50 mm of travel with homing and soft limits enabled
(``firmware_bridge.TEST_SETTINGS``) and is a stock build: no ``HOMING_FORCE_SET_ORIGIN``, so the
machine space is negative. grbl-sim has no limit switches, so homing cannot succeed here: the
driver re-arms with ``unlock()`` in these tests (homing itself is proven on the simulator).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from firmware_bridge import FirmwareBridge, wait_until

from labauto.drivers.errors import DeviceRefused, DeviceTimeout, UnexpectedReply
from labauto.drivers.grbl import (
    GrblAlarm,
    GrblNotArmed,
    GrblReset,
    GrblRobot,
    GrblStatus,
    TravelLimits,
    TravelMismatch,
)

pytestmark = pytest.mark.timeout(180)  # only a starved grbl-sim takes long

#: The firmware's machine space: $130-$132 below the home corner.
SPACE = TravelLimits(x=(-200.0, 0.0), y=(-200.0, 0.0), z=(-50.0, 0.0))


class Log(list[tuple[str, str]]):
    """An ``on_exchange`` callback that records ``(time, direction, line)``."""

    def __call__(self, direction: str, line: str) -> None:
        self.append((direction, line))

    def sent_after(self, line: str) -> list[str]:
        """Lines and real-time bytes sent after the last time ``line`` was sent."""
        sent = [text for direction, text in self if direction == "tx"]
        last = len(sent) - 1 - sent[::-1].index(line)
        return sent[last + 1 :]


def make_robot(path: str, log: Log | None = None, **options: object) -> GrblRobot:
    options.setdefault("limits", SPACE)
    # Generous: grbl-sim needs a whole core and runs slower than real time on a busy host.
    options.setdefault("timeout", 5.0)
    options.setdefault("motion_timeout", 60.0)
    options.setdefault("travel_feed", 6000.0)
    options.setdefault("z_feed", 3000.0)
    options.setdefault("poll_interval", 0.005)
    options.setdefault("boot_timeout", 8.0)
    return GrblRobot(path, on_exchange=log, **options)  # type: ignore[arg-type]


@pytest.fixture
def log() -> Log:
    return Log()


def still_steps(robot: GrblRobot) -> bool:
    """Whether the firmware still carries out motion: 0.1 mm along X and back, within 10 s.

    grbl-sim runs GRBL's stepper "interrupt" in a host thread without the AVR's atomicity; now
    and then (seen after a feed hold, and mid-move, on a loaded host) it stops stepping, and
    every later move waits for an ``ok`` to ``G4 P0`` that never comes. A soft reset cures it
    only sometimes. Real GRBL has no such state, so a test that finds it power-cycles the
    firmware.
    """
    try:
        position = robot.status().position or (0.0, 0.0, 0.0)
        step = -0.1 if position[0] > -100.0 else 0.1  # away from the nearer end of travel
        robot.execute(f"G91 G1 X{step:.1f} F6000")
        robot.execute(f"G1 X{-step:.1f}")
        robot.execute("G90")
        return robot.wait_idle(timeout=10.0).state == "Idle"
    except (DeviceTimeout, UnexpectedReply, GrblAlarm, GrblReset):
        return False


def power_cycle(robot: GrblRobot, firmware: FirmwareBridge) -> None:
    """Restart the firmware from its EEPROM and reconnect: unlocked and armed at machine zero."""
    firmware.restart()
    robot.reconnect()
    robot.soft_reset()
    robot.unlock()


@pytest.fixture
def robot(firmware: FirmwareBridge, log: Log) -> Iterator[GrblRobot]:
    """A connected driver, the machine unlocked where the last test left it, the driver armed
    (the firmware power-cycled first if it no longer steps, see :func:`still_steps`)."""
    assert firmware.alive()
    driver = make_robot(firmware.path, log)
    driver.connect()
    try:
        driver.soft_reset()  # whatever the last test left: a clean, latched start
        driver.unlock()
        if not still_steps(driver):
            power_cycle(driver, firmware)
        yield driver
    finally:
        with contextlib.suppress(Exception):
            driver.soft_reset()  # stop whatever still moves, so the next connect is answered
        driver.close()


def poll_status(robot: GrblRobot) -> GrblStatus:
    """``robot.status()``, asked again once if the report came garbled or not at all.

    grbl-sim runs GRBL's serial interrupt and main loop in two host threads without the AVR's
    atomicity, so under load a report can come mangled or not at all (seen with an optimised
    build: ``MPos:-7..52,...``; see ``build_grbl_sim``). The driver rightly raises for it; tests
    that poll many times ask again.
    """
    try:
        return robot.status()
    except (UnexpectedReply, DeviceTimeout):
        return robot.status()


def in_thread(call: object) -> tuple[threading.Thread, list[BaseException]]:
    """Run ``call()`` in a thread; the exception it raises (if any) lands in the list."""
    failures: list[BaseException] = []

    def run() -> None:
        try:
            call()  # type: ignore[operator]
        except BaseException as exc:  # handed to the test thread
            failures.append(exc)

    thread = threading.Thread(target=run)
    thread.start()
    return thread, failures


# --------------------------------------------------------------------------- connection


def test_connect_reads_version_build_options_and_settings(robot: GrblRobot) -> None:
    assert robot.firmware == "1.1h"
    assert robot.build_options is not None and robot.build_options.codes == "V"
    assert not robot.build_options.homing_force_origin
    settings = robot.controller_settings
    assert (settings[20], settings[22], settings[130], settings[132]) == (
        "1",
        "1",
        "200.000",
        "50.000",
    )
    report = robot.check()
    assert report["state"] == "Idle" and report["armed"] is True and report["build_options"] == "V"


def test_positive_deck_limits_are_refused_at_connect(firmware: FirmwareBridge) -> None:
    deck = TravelLimits(x=(0.0, 300.0), y=(0.0, 200.0), z=(-50.0, 0.0))
    robot = make_robot(firmware.path, limits=deck)
    with pytest.raises(TravelMismatch) as mismatch:
        robot.connect()
    assert not robot.is_connected
    assert mismatch.value.problems == [
        "x limits [0, 300] mm leave the controller's travel [-200, 0] mm ($130=200.000, $23=0, "
        "no HOMING_FORCE_SET_ORIGIN: the home corner is 0 and the travel is negative)",
        "y limits [0, 200] mm leave the controller's travel [-200, 0] mm ($131=200.000, $23=0, "
        "no HOMING_FORCE_SET_ORIGIN: the home corner is 0 and the travel is negative)",
    ]
    too_long = TravelLimits(x=(-250.0, 0.0), y=(-200.0, 0.0), z=(-50.0, 0.0))
    with pytest.raises(TravelMismatch, match=r"x limits \[-250, 0\] mm leave"):
        make_robot(firmware.path, limits=too_long).connect()


# --------------------------------------------------------------------------- motion, status


def test_moves_in_the_negative_machine_space(robot: GrblRobot, log: Log) -> None:
    report = robot.move_to(-8.0, -6.0, -5.0)
    assert report is not None and report.state == "Idle"
    assert report.position == (-8.0, -6.0, -5.0)
    sent = len(log)
    with pytest.raises(DeviceRefused, match=r"x=5.0 is outside the travel limits \[-200.0, 0.0\]"):
        robot.move_to(5.0, -10.0)
    assert len(log) == sent  # nothing reached the firmware


def test_status_in_both_report_modes(robot: GrblRobot) -> None:
    robot.move_to(-12.0, -8.0, -3.0)
    robot.execute("G10 L2 P1 X-5 Y-6 Z-1")  # a work offset, so WPos differs from MPos
    robot.execute("$10=0")  # report WPos; GRBL sends WCO only every 10-30 reports
    try:
        reports = [poll_status(robot) for _ in range(12)]
    finally:
        robot.execute("$10=1")
        robot.execute("G10 L2 P1 X0 Y0 Z0")
    assert all("WPos:-7.000,-2.000,-2.000" in r.raw for r in reports)
    with_offset = [r for r in reports if "WCO:" in r.raw]
    assert 1 <= len(with_offset) <= 2  # the firmware really leaves WCO out of most reports
    assert all(r.position == pytest.approx((-12.0, -8.0, -3.0)) for r in reports)
    machine = poll_status(robot)
    assert "MPos:-12.000,-8.000,-3.000" in machine.raw and machine.work_position is None


def test_soft_limit_alarm_waits_for_the_reset_message_then_recovers(
    firmware: FirmwareBridge, log: Log
) -> None:
    # The driver believes in a bigger machine (and does not check): the firmware says ALARM:2.
    wide = TravelLimits(x=(-200.0, 50.0), y=(-200.0, 0.0), z=(-50.0, 0.0))
    robot = make_robot(firmware.path, log, limits=wide, check_travel=False)
    with robot:
        robot.soft_reset()
        robot.unlock()
        robot.move_to(-10.0, -10.0)
        with pytest.raises(GrblAlarm) as alarm:
            robot.move_to(10.0, -10.0)
        assert alarm.value.code == 2 and alarm.value.requires_reset
        with pytest.raises(GrblAlarm, match="ALARM:2 locks the controller"):
            robot.status()  # GRBL answers no ? now; the driver says so at once
        started = time.monotonic()
        robot.unlock()  # waits for [MSG:Reset to continue], resets, $X
        assert time.monotonic() - started < 5.0  # no reply timeout on the way (5 s)
        received = [line for direction, line in log if direction == "rx"]
        sent = [line for direction, line in log if direction == "tx"]
        assert "[MSG:Reset to continue]" in received
        # Exactly one reset after the alarm, and it came after the message (one before is lost).
        assert sent[sent.index("G21 G90 G53 G1 X10.000 Y-10.000 F6000.000") :].count("^X") == 1
        events = [line for _, line in log]
        assert events.index("^X", events.index("[MSG:Reset to continue]")) > 0
        report = robot.status()
        assert report.state == "Idle" and report.position == (-10.0, -10.0, 0.0)
        assert robot.armed


def _hold_once(robot: GrblRobot, target: float) -> tuple[list[int | None], GrblStatus]:
    """Move towards ``target``, hold, poll until Hold:0 (10 s); return the substates seen."""
    robot.move_to(target, 0.0, wait=False)  # grbl-sim moves at ~1/5 of real time
    assert wait_until(lambda: poll_status(robot).state == "Run", 10.0)
    time.sleep(0.05)
    robot.feed_hold()
    substates: list[int | None] = []
    deadline = time.monotonic() + 10.0
    report = poll_status(robot)
    while time.monotonic() < deadline:
        time.sleep(0.02)  # GRBL needs its main loop, not only status reports
        report = poll_status(robot)
        if report.state == "Run" and not substates:
            continue  # the hold has not been taken up yet
        assert report.state == "Hold"
        substates.append(report.substate)
        if report.substate == 0:
            break
    return substates, report


def _moved_on(robot: GrblRobot, held: tuple[float, float, float], need: float) -> bool:
    return abs((poll_status(robot).position or held)[0] - held[0]) >= need


def _reset_for_next_try(robot: GrblRobot, firmware: FirmwareBridge) -> None:
    """Soft reset and unlock; power-cycle a grbl-sim that no longer steps (its fault, not the
    driver's: a hold never completes and a resume never moves without a stepping firmware)."""
    robot.soft_reset()
    robot.unlock()
    if not still_steps(robot):
        power_cycle(robot, firmware)


def test_feed_hold_goes_hold_1_then_hold_0_and_resumes(
    robot: GrblRobot, firmware: FirmwareBridge
) -> None:
    # grbl-sim sometimes never completes a hold, or never steps again after the resume (its
    # stepper "interrupt" is a host thread, not an AVR interrupt): up to three tries, each after
    # a reset (a power cycle when it no longer steps).
    for attempt, target in enumerate((-30.0, -5.0, -30.0)):
        tries = attempt + 1
        substates, report = _hold_once(robot, target)
        position = report.position or (target, 0.0, 0.0)
        if not (substates and substates[-1] == 0 and abs(target - position[0]) > 0.02):
            # not held, or only at the end of the move (an idle host may finish it first), or a
            # hold stuck at Hold:1 because the stepper thread stopped (seen in CI: [1, 1, 1])
            _reset_for_next_try(robot, firmware)
            continue
        assert substates[0] == 1, (tries, substates[-3:], report.raw)
        held = robot.status().position
        time.sleep(0.2)
        assert robot.status().position == held  # stays put
        assert held is not None
        robot.resume()
        # Resumed: it moves on from where it was held, by half of what was left (at most 0.5
        # mm: a hold near the end of the move leaves less than that). (Not waited to the end,
        # for the same grbl-sim reason; the fixture resets afterwards.)
        need = min(0.5, abs(target - held[0]) / 2)
        if wait_until(lambda h=held, n=need: _moved_on(robot, h, n), 10.0):
            return
        _reset_for_next_try(robot, firmware)
    pytest.fail(f"no hold and resume in {tries} tries; last substates {substates[-3:]}")


# --------------------------------------------------------------------------- e-stop


def _estop_during_dwell(robot: GrblRobot, log: Log, firmware: FirmwareBridge) -> None:
    for _try in range(3):
        dwells = log.count(("tx", "G4 P1.500"))
        thread, failures = in_thread(lambda: robot.pick(-10.0, -10.0, -4.0, dwell_s=1.5))
        if wait_until(lambda d=dwells: log.count(("tx", "G4 P1.500")) > d, 30.0):
            break
        # The pick never reached its dwell: the driver must be waiting for the answer to its
        # last line (G4 P0 after the moves), which only a grbl-sim that stalled mid-move leaves
        # unanswered (see still_steps; seen under load, and a soft reset may or may not cure it).
        lines = [i for i, (direction, text) in enumerate(log) if direction == "tx" and text != "?"]
        answers = [text for direction, text in log[lines[-1] + 1 :] if direction == "rx"]
        assert all(text.startswith("<") for text in answers), log[lines[-1] :]  # reports only
        with contextlib.suppress(DeviceTimeout, UnexpectedReply, GrblAlarm, GrblReset):
            robot.soft_reset()
            robot.unlock()
        thread.join(timeout=20)
        if not still_steps(robot):
            power_cycle(robot, firmware)
    else:
        pytest.fail("the pick's dwell was not sent in 3 tries")
    time.sleep(0.3)
    robot.soft_reset()
    thread.join(timeout=20)
    assert not thread.is_alive()
    assert len(failures) == 1 and isinstance(failures[0], GrblReset), failures
    assert "was cut short by a soft reset" in str(failures[0])
    # The firmware acknowledged the aborted dwell with "ok": the driver sent nothing after it.
    assert [line for line in log.sent_after("^X") if line != "?"] == []
    assert robot.status().state == "Idle"  # the firmware itself would move again ...
    assert not robot.armed  # ... the driver does not
    with pytest.raises(GrblNotArmed, match="soft reset"):
        robot.move_to(-5.0, -5.0)
    with pytest.raises(GrblNotArmed):
        robot.pick(-5.0, -5.0, -1.0)


def test_estop_during_a_picks_dwell_fails_the_pick_and_latches(
    robot: GrblRobot, log: Log, firmware: FirmwareBridge
) -> None:
    _estop_during_dwell(robot, log, firmware)
    robot.unlock()
    assert robot.armed
    assert robot.move_to(-5.0, -5.0).position == (-5.0, -5.0, 0.0)


def test_estop_during_a_dwell_over_a_slow_usb_link(
    grbl_sim_exe: Path, eeprom: Path, log: Log
) -> None:
    """The issue's case: 60 ms of output latency, so the aborted line's ok comes late."""
    with FirmwareBridge(grbl_sim_exe, eeprom, latency_s=0.06) as slow:
        robot = make_robot(slow.path, log)
        with robot:
            robot.unlock()
            for _ in range(2):
                _estop_during_dwell(robot, log, slow)
                robot.unlock()


def test_estop_during_a_move_fails_the_wait_with_alarm_3_and_latches(
    robot: GrblRobot, log: Log
) -> None:
    robot.move_to(-60.0, -10.0, -4.0, wait=False)  # as pick() does, but observable
    assert wait_until(lambda: (poll_status(robot).position or (0.0,))[0] < -5.0, 20.0)
    waits = log.count(("tx", "G4 P0"))
    thread, failures = in_thread(robot.wait_idle)
    assert wait_until(lambda: log.count(("tx", "G4 P0")) > waits, 10.0)
    robot.soft_reset()
    thread.join(timeout=20)
    # grbl-sim prints ALARM:3 and the aborted G4 P0's ok in either order (its reset
    # "interrupt" is a host thread): the wait fails either way, as an alarm or as a reset.
    assert len(failures) == 1, failures
    failure = failures[0]
    assert (isinstance(failure, GrblAlarm) and failure.code == 3) or isinstance(failure, GrblReset)
    assert robot.last_alarm == 3  # noted by the time the reset's banner came
    assert [line for line in log.sent_after("^X") if line != "?"] == []
    stopped = robot.status()
    assert stopped.state == "Alarm"
    assert stopped.position is not None and -60.0 < stopped.position[0] < -5.0
    with pytest.raises(GrblNotArmed):
        robot.tool_on()
    robot.unlock()
    assert robot.move_to(-10.0, -10.0).state == "Idle"


def test_startup_block_errors_are_reported_not_taken_for_garbage(robot: GrblRobot) -> None:
    robot.move_to(-10.0, -10.0)
    robot.execute("G53 G1 X-9 F6000")  # a feed rate, so GRBL accepts the block when storing it
    robot.wait_idle()  # $ commands need Idle
    robot.execute("$N0=G1X-9")  # GRBL runs it to check it: no move, it is there already
    try:
        robot.soft_reset()  # after a reset the feed rate is gone: the block fails
        assert wait_until(lambda: poll_status(robot) and robot.startup_errors, 10.0)
        assert robot.startup_errors == [">G1X-9:error:22"]
    finally:
        robot.execute("$N0=")
    robot.unlock()


# --------------------------------------------------------------------------- reconnect


def test_reconnect_to_a_board_that_restarts_on_open(
    grbl_sim_exe: Path, eeprom: Path, log: Log
) -> None:
    with FirmwareBridge(grbl_sim_exe, eeprom, restart_on_open=True) as board:
        robot = make_robot(board.path, log)
        started = time.monotonic()
        robot.connect()  # $I is lost while the board boots; the banner comes ~1 s later
        assert time.monotonic() - started > 0.5
        assert board.starts == 1 and robot.firmware == "1.1h" and robot.armed
        robot.unlock()
        robot.move_to(-3.0, -2.0)
        robot.close()
        time.sleep(0.05)  # the bridge sees an open only after the port was closed a moment
        robot.connect()  # the open restarts the firmware: position and homing are lost
        assert board.starts == 2
        assert not robot.armed
        assert "unexpected start-up banner" in (robot.disarmed_reason or "")
        report = robot.status()
        assert report.state == "Alarm" and report.position == (0.0, 0.0, 0.0)
        with pytest.raises(GrblNotArmed):
            robot.move_to(-1.0, -1.0)
        robot.unlock()
        assert robot.move_to(-1.0, -1.0).position == (-1.0, -1.0, 0.0)
        robot.close()
