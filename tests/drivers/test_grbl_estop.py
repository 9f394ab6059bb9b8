"""E-stop latch, critical-alarm recovery, coordinates and start-up on the simulated gantry.

The same behaviours are proven against the real firmware in ``tests/firmware``; here they run
fast and with faults the firmware cannot produce (a controller that restarts by itself).
"""

from __future__ import annotations

import threading
import time

import pytest
from grbl_fixtures import (
    DECK,
    MOTION_TIMEOUT_S,
    SLOW_SPEED,
    TRANSPORTS,
    ExchangeLog,
    gantry,
    make_robot,
    rig,
    wait_for,
)

from labauto.drivers.grbl import (
    GrblAlarm,
    GrblNotArmed,
    GrblReset,
    TravelLimits,
    TravelMismatch,
)

pytestmark = pytest.mark.timeout(30)


@pytest.fixture(params=TRANSPORTS)
def transport(request: pytest.FixtureRequest) -> str:
    return request.param


def in_thread(call: object) -> tuple[threading.Thread, list[BaseException]]:
    failures: list[BaseException] = []

    def run() -> None:
        try:
            call()  # type: ignore[operator]
        except BaseException as exc:  # handed to the test thread
            failures.append(exc)

    thread = threading.Thread(target=run)
    thread.start()
    return thread, failures


def lines_after_reset(log: ExchangeLog) -> list[str]:
    sent = log.sent()
    last = len(sent) - 1 - sent[::-1].index("^X")
    return [line for line in sent[last + 1 :] if line != "?"]


# --------------------------------------------------------------------------- e-stop latch


@pytest.mark.parametrize("run", range(6))
def test_estop_during_a_picks_dwell_over_a_slow_link_fails_the_pick(run: int) -> None:
    """The issue's measurement: 60 ms of output latency, reset during the dwell, 6 runs."""
    log = ExchangeLog()
    sim_options = {"speed_factor": SLOW_SPEED, "latency_s": 0.06, "homing_lock": False}
    with rig("pty", sim_options, on_exchange=log, timeout=1.0) as (sim, robot):
        thread, failures = in_thread(lambda: robot.pick(20.0, 20.0, -10.0, dwell_s=2.0))
        assert wait_for(lambda: "G4 P2.000" in sim.received, 5.0)
        robot.soft_reset()
        thread.join(timeout=MOTION_TIMEOUT_S)
        assert len(failures) == 1 and isinstance(failures[0], GrblReset), failures
        assert lines_after_reset(log) == []  # no M9, no G1 Z0, no G1 X Y after the reset
        assert sim.received[-1] == "G4 P2.000"
        assert not robot.armed and robot.disarmed_reason == "soft reset (e-stop)"
        with pytest.raises(GrblNotArmed):
            robot.deposit(10.0, 10.0, -5.0)


def test_every_motion_command_is_refused_until_rearmed(transport: str) -> None:
    log = ExchangeLog()
    with rig(transport, on_exchange=log) as (sim, robot):
        robot.home()
        robot.soft_reset()
        received = list(sim.received)
        for call in (
            lambda: robot.move_to(10.0, 10.0),
            lambda: robot.pick(10.0, 10.0, -5.0),
            lambda: robot.deposit(10.0, 10.0, -5.0),
            lambda: robot.dwell(0.1),
            robot.tool_on,
            robot.wait_idle,
            lambda: robot.execute("G0 X1"),
        ):
            with pytest.raises(GrblNotArmed, match=r"refused: not armed since the soft reset"):
                call()
        assert sim.received == received  # nothing was sent
        robot.tool_off()  # switching the tool off stays allowed
        assert robot.settings()[22] == "1"  # and so do $ commands
        robot.home()
        assert robot.armed and robot.move_to(10.0, 10.0).state == "Idle"


def test_a_controller_that_restarts_by_itself_latches_the_driver(transport: str) -> None:
    with rig(transport) as (sim, robot):
        robot.home()
        robot.move_to(50.0, 50.0)
        sim.inject("restart")
        with pytest.raises(GrblReset, match="controller restarted"):
            robot.move_to(60.0, 60.0)
        assert not robot.armed
        assert robot.disarmed_reason == "unexpected start-up banner (the controller restarted)"
        with pytest.raises(GrblNotArmed, match="unexpected start-up banner"):
            robot.move_to(60.0, 60.0)
        assert robot.status().state == "Alarm"  # the homing lock of a fresh start
        robot.home()
        assert robot.move_to(60.0, 60.0).position == (60.0, 60.0, 0.0)


def test_estop_mid_move_fails_the_pick_with_alarm_3(transport: str) -> None:
    with rig(transport, {"speed_factor": SLOW_SPEED}) as (sim, robot):
        robot.home()
        thread, failures = in_thread(lambda: robot.pick(250.0, 150.0, -10.0, dwell_s=0.1))
        assert wait_for(lambda: sim.state == "Run", 5.0)
        robot.soft_reset()
        thread.join(timeout=MOTION_TIMEOUT_S)
        # Either the awaited line's ALARM:3 or an ok that came after the reset byte: both fail it.
        assert len(failures) == 1, failures
        failure = failures[0]
        assert (isinstance(failure, GrblAlarm) and failure.code == 3) or isinstance(
            failure, GrblReset
        )
        assert robot.last_alarm == 3 and not robot.armed
        robot.unlock()
        assert robot.armed


# --------------------------------------------------------------------------- critical alarms


def test_recovery_waits_for_the_reset_message_of_a_critical_alarm(transport: str) -> None:
    log = ExchangeLog()
    narrow = TravelLimits(x=(0.0, 100.0), y=(0.0, 100.0), z=(-50.0, 0.0))
    with rig(transport, {"limits": narrow}, on_exchange=log, check_travel=False) as (sim, robot):
        robot.home()
        with pytest.raises(GrblAlarm) as alarm:
            robot.move_to(150.0, 50.0)
        assert alarm.value.code == 2
        robot.unlock()  # at once: the driver must wait out GRBL's 500 ms window itself
        events = [line for _, line in log]
        message = events.index("[MSG:Reset to continue]")
        assert "^X" in events[message:] and "^X" not in events[events.index("ALARM:2") : message]
        assert sim.realtime_received.count("^X") == 1  # one reset, and it was heard
        assert robot.status().state == "Idle" and robot.armed


def test_a_reset_lost_in_the_alarm_window_is_sent_again(transport: str) -> None:
    narrow = TravelLimits(x=(0.0, 100.0), y=(0.0, 100.0), z=(-50.0, 0.0))
    with rig(transport, {"limits": narrow}, check_travel=False) as (sim, robot):
        robot.home()
        with pytest.raises(GrblAlarm):
            robot.move_to(150.0, 50.0)
        robot.soft_reset()  # an e-stop right away, inside the window: GRBL does not hear it
        assert sim.realtime_received.count("^X") == 2  # sent again after the message
        assert robot.last_alarm == 2 and not robot.check()["reset_required"]
        robot.unlock()
        assert robot.status().state == "Idle"


# --------------------------------------------------------------------------- coordinates


def test_work_position_reports_get_the_cached_offset(transport: str) -> None:
    with rig(transport) as (_, robot):
        robot.home()
        robot.move_to(40.0, 30.0, -5.0)
        robot.execute("G10 L2 P1 X10 Y20 Z-1")
        robot.execute("$10=0")
        reports = [robot.status() for _ in range(12)]
        assert all(r.machine_position is None for r in reports)
        assert sum(1 for r in reports if "WCO:" in r.raw) == 2  # the first, then every 10th
        assert all(r.work_position == (30.0, 10.0, -4.0) for r in reports)
        assert all(r.position == (40.0, 30.0, -5.0) for r in reports)


def test_negative_space_of_a_stock_build_fits_the_default_limits(transport: str) -> None:
    with gantry(limits=TravelLimits()) as sim:
        url = sim.start_pty() if transport == "pty" else sim.start_tcp()
        robot = make_robot(url, limits=TravelLimits())
        with robot:
            assert robot.build_options is not None and robot.build_options.codes == "V"
            assert robot.home().position == (-1.0, -1.0, -1.0)  # the pull-off below the switches
            assert robot.move_to(-120.0, -80.0, -20.0).position == (-120.0, -80.0, -20.0)
        with pytest.raises(TravelMismatch, match=r"x limits \[0, 300\] mm leave .* \[-300, 0\]"):
            make_robot(url, limits=DECK).connect()


# --------------------------------------------------------------------------- start-up


def test_startup_block_errors_are_kept_not_taken_for_garbage(transport: str) -> None:
    options = {"homing_lock": False, "startup_blocks": ["G21", "G1 X5"]}
    with rig(transport, options) as (_, robot):
        robot.soft_reset()
        robot.unlock()
        assert robot.startup_errors == [">G1 X5:error:22"]
        assert robot.check()["startup_errors"] == [">G1 X5:error:22"]


def test_a_board_that_resets_on_open_is_waited_for() -> None:
    """A DTR reset happens on serial ports only: pty."""
    with gantry(reset_on_open=True, boot_delay=0.4) as sim:
        robot = make_robot(sim.start_pty(), boot_timeout=2.0)
        robot.connect()  # $I is lost while the board boots; the banner brings a new one
        assert robot.firmware == "1.1h" and robot.armed
        robot.home()
        robot.close()
        time.sleep(0.05)  # the pty relay sees the open only after the port was closed a moment
        robot.connect()
        assert not robot.armed  # a restart nobody asked for: position is lost
        assert robot.status().state == "Alarm"


def test_no_answer_at_all_still_fails_after_the_boot_wait() -> None:
    with gantry(faults=[{"fault": "no_reply", "count": 5}]) as sim:
        robot = make_robot(sim.start_pty(), boot_timeout=0.2)
        with pytest.raises(Exception, match=r"no answer to '\$I'"):
            robot.connect()
