"""The simulated gantry's protocol, byte for byte, through raw pyserial (no driver)."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator

import pytest
import serial
from grbl_fixtures import REPLY_TIMEOUT_S, SLOW_SPEED, TRANSPORTS, gantry, serve, wait_for

from labauto.drivers.grbl_protocol import ReplyKind, TravelLimits, classify_reply, parse_status
from labauto.drivers.grbl_sim import SimulatedGantry
from labauto.drivers.line_link import _close_quickly

pytestmark = pytest.mark.timeout(15)


class RawLink:
    """A bare pyserial connection that sends bytes and collects reply lines."""

    def __init__(self, url: str) -> None:
        self.port = serial.serial_for_url(url, baudrate=115200, timeout=0.01)
        self.buffer = b""

    def send(self, data: bytes) -> None:
        self.port.write(data)

    def lines(self, count: int, timeout: float = 2.0) -> list[str]:
        """Read exactly ``count`` lines (fails on timeout)."""
        deadline = time.monotonic() + timeout
        while self.buffer.count(b"\r\n") < count:
            assert time.monotonic() < deadline, f"got only {self.buffer!r}"
            self.buffer += self.port.read(self.port.in_waiting or 1)
        *found, self.buffer = self.buffer.split(b"\r\n", count)
        return [line.decode("ascii", errors="replace") for line in found]

    def silent_for(self, seconds: float) -> bool:
        """True if nothing at all arrives within ``seconds``."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.buffer += self.port.read(self.port.in_waiting or 1)
        return self.buffer == b""

    def ask(self, line: str, replies: int = 1) -> list[str]:
        self.send(line.encode() + b"\n")
        return self.lines(replies)

    def status(self) -> str:
        self.send(b"?")
        return self.lines(1)[0]

    def wait_for_state(self, state: str, timeout: float = 2.0) -> None:
        """Poll ``?`` until the status report shows ``state``."""
        deadline = time.monotonic() + timeout
        while parse_status(self.status()).state != state:
            assert time.monotonic() < deadline, f"never reached {state}"

    def close(self) -> None:
        _close_quickly(self.port)  # pyserial's socket close() would sleep 0.3 s


@pytest.fixture(params=TRANSPORTS)
def transport(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture
def sim() -> Iterator[SimulatedGantry]:
    with gantry() as simulator:
        yield simulator


@pytest.fixture
def link(sim: SimulatedGantry, transport: str) -> Iterator[RawLink]:
    raw = RawLink(serve(sim, transport))
    yield raw
    raw.close()


@pytest.fixture
def unlocked(link: RawLink) -> RawLink:
    assert link.ask("$X", 2) == ["[MSG:Caution: Unlocked]", "ok"]
    return link


def test_every_line_ending_ends_a_line_like_grbl(unlocked: RawLink) -> None:
    unlocked.send(b"G21\r\n")  # \r and \n each end a line: two answers
    assert unlocked.lines(2) == ["ok", "ok"]
    unlocked.send(b"G90\n")
    assert unlocked.lines(1) == ["ok"]
    assert unlocked.silent_for(0.05)  # nothing echoed back: the pty is raw


def test_pty_path_is_a_stable_link_to_a_real_pty(sim: SimulatedGantry) -> None:
    path = sim.start_pty()
    assert os.path.islink(path)
    assert os.path.realpath(path) == sim.pty_device
    assert sim.pty_device is not None and sim.pty_device.startswith("/dev/pts/")


@pytest.mark.parametrize(
    ("line", "answer"),
    [
        ("G2 X10 Y10 I5", "error:20"),  # arcs are not simulated
        ("M30", "error:20"),
        ("G1 X10", "error:22"),  # no feed rate yet
        ("G1 X1 X2 F100", "error:25"),
        ("G0 G1 X1", "error:21"),
        ("G1 Xabc F100", "error:2"),
        ("1G0", "error:1"),
        ("G4", "error:28"),
        ("G4 P-1", "error:4"),
        ("G53 G80", "error:30"),
        ("G4 P1 X3", "error:31"),
        ("$Q", "error:3"),
        ("G1 X1 F-5", "error:4"),
        ("G0 X1 (comment) ; more", "ok"),
        ("g0 x2 y1", "ok"),
        ("", "ok"),
        ("G0 X" + "1" * 80, "error:11"),
    ],
)
def test_gcode_answers(unlocked: RawLink, line: str, answer: str) -> None:
    assert unlocked.ask(line) == [answer]


def test_alarm_locks_gcode_but_not_system_commands(link: RawLink) -> None:
    assert link.ask("G0 X10") == ["error:9"]
    assert link.ask("$I", 3) == ["[VER:1.1h.20190830:]", "[OPT:VZ,15,128]", "ok"]
    assert link.ask("$G", 2)[0].startswith("[GC:G0 G54 G17 G21 G90 G94 M5 M9")
    assert parse_status(link.status()).state == "Alarm"


def test_moves_take_time_and_report_interpolated_positions(transport: str) -> None:
    with gantry(speed_factor=SLOW_SPEED, homing_lock=False) as sim:
        link = RawLink(serve(sim, transport))
        try:
            assert link.ask("G1 X200 F3000") == ["ok"]  # queued at once
            moving = parse_status(link.status())
            assert moving.state == "Run" and moving.feed == 3000
            assert moving.position is not None and 0 < moving.position[0] < 200
            assert link.ask("G4 P0") == ["ok"]  # only once the planner is empty
            assert parse_status(link.status()).position == (200.0, 0.0, 0.0)
        finally:
            link.close()


def test_relative_inch_and_machine_coordinate_moves(
    unlocked: RawLink, sim: SimulatedGantry
) -> None:
    assert unlocked.ask("G0 X10 Y10 Z-10") == ["ok"]
    assert unlocked.ask("G91 G0 X5 Y-2.5") == ["ok"]
    assert unlocked.ask("G20 G91 G1 Z-1 F10") == ["ok"]  # one inch down at 10 in/min
    assert unlocked.ask("G21 G90 G53 G0 Y20") == ["ok"]  # G53 ignores G91
    assert unlocked.ask("G4 P0") == ["ok"]
    assert sim.position == pytest.approx((15.0, 20.0, -35.4))


def test_homing_reports_home_state_then_unlocks(transport: str) -> None:
    with gantry(speed_factor=SLOW_SPEED, homing_lock=False) as sim:
        link = RawLink(serve(sim, transport))
        try:
            link.ask("G0 X100")
            link.ask("G4 P0")
            link.send(b"$H\n")  # the ok waits for the end of homing
            assert wait_for(lambda: sim.state == "Home")
            link.send(b"?")  # not answered during homing: the report comes when it ends
            assert link.silent_for(0.05)
            home, ok = link.lines(2)
            assert parse_status(home).state == "Home" and ok == "ok"
            assert parse_status(link.status()).state == "Idle"
            assert sim.homed and sim.position == (0.0, 0.0, 0.0)
        finally:
            link.close()


def test_reset_during_homing_is_alarm_6(transport: str) -> None:
    with gantry(speed_factor=SLOW_SPEED, homing_lock=False) as sim:
        link = RawLink(serve(sim, transport))
        try:
            link.ask("G0 X100")
            link.ask("G4 P0")
            link.send(b"$H\n")
            assert wait_for(lambda: sim.state == "Home")
            link.send(b"\x18")
            assert link.lines(5) == [
                "ALARM:6",
                "ok",  # the aborted $H is answered, after GRBL's 500 ms alarm delay
                "",
                "Grbl 1.1h ['$' for help]",
                "[MSG:'$H'|'$X' to unlock]",
            ]
            assert not sim.homed
        finally:
            link.close()


def test_soft_limit_locks_until_reset(transport: str) -> None:
    with gantry(limits=TravelLimits(x=(0, 100), y=(0, 100), z=(-10, 0)), homing_lock=False) as sim:
        link = RawLink(serve(sim, transport))
        try:
            assert link.ask("G0 X101") == ["ALARM:2"]
            link.send(b"\x18")  # inside GRBL's 500 ms alarm delay: lost
            assert link.lines(1) == ["[MSG:Reset to continue]"]
            link.send(b"?G0 X1\n")
            assert link.silent_for(REPLY_TIMEOUT_S)  # neither status nor lines are answered
            link.send(b"\x18")
            assert link.lines(4) == [
                "ok",  # the line the soft limit stopped
                "",
                "Grbl 1.1h ['$' for help]",
                "[MSG:'$H'|'$X' to unlock]",
            ]
            assert link.ask("$X", 2)[1] == "ok"
            assert sim.received[-2:] == ["G0 X1", "$X"]
        finally:
            link.close()


def test_feed_hold_from_idle_and_resume(unlocked: RawLink) -> None:
    unlocked.send(b"!")
    held = parse_status(unlocked.status())
    assert (held.state, held.substate) == ("Hold", 0)
    unlocked.send(b"~")
    assert parse_status(unlocked.status()).state == "Idle"


def test_check_mode_parses_without_moving(unlocked: RawLink, sim: SimulatedGantry) -> None:
    assert unlocked.ask("$C", 2) == ["[MSG:Enabled]", "ok"]
    assert parse_status(unlocked.status()).state == "Check"
    assert unlocked.ask("G0 X50") == ["ok"]
    assert unlocked.ask("G5") == ["error:20"]
    assert sim.position == (0.0, 0.0, 0.0)
    assert unlocked.ask("$C", 4) == ["[MSG:Disabled]", "ok", "", "Grbl 1.1h ['$' for help]"]
    assert parse_status(unlocked.status()).state == "Idle"


def test_sleep_ignores_lines_until_reset(unlocked: RawLink) -> None:
    assert unlocked.ask("$SLP", 2) == ["ok", "[MSG:Sleeping]"]
    assert parse_status(unlocked.status()).state == "Sleep"
    unlocked.send(b"G0 X1\n")
    assert unlocked.silent_for(0.05)
    unlocked.send(b"\x18")
    assert unlocked.lines(3)[2] == "[MSG:'$H'|'$X' to unlock]"  # sleep wakes up in Alarm


def test_outputs_show_in_status_and_parser_state(unlocked: RawLink, sim: SimulatedGantry) -> None:
    first = parse_status(unlocked.status())  # GRBL: WCO first after start-up, Ov one later
    assert first.work_offset == (0.0, 0.0, 0.0) and first.overrides is None
    assert unlocked.ask("M8") == ["ok"]
    assert parse_status(unlocked.status()).accessories == "F"
    assert " M8 " in unlocked.ask("$G", 2)[0]
    assert unlocked.ask("M3 S500 M7") == ["ok"]
    assert parse_status(unlocked.status()).accessories == "SFM"
    assert unlocked.ask("M5 M9") == ["ok"]
    assert parse_status(unlocked.status()).accessories == ""
    assert not sim.tool_on


def test_garbled_fault_sends_noise(unlocked: RawLink, sim: SimulatedGantry) -> None:
    sim.inject("garbled")
    noise = unlocked.ask("G0 X1")[0]
    assert classify_reply(noise).kind is ReplyKind.UNKNOWN
    assert unlocked.ask("G0 X2") == ["ok"]  # used up


def test_received_lines_are_recorded(unlocked: RawLink, sim: SimulatedGantry) -> None:
    unlocked.ask("G0 X3")
    unlocked.status()
    assert sim.received == ["$X", "G0 X3"]
    assert sim.realtime_received == ["?"]
