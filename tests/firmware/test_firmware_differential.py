"""Differential test: the same bytes to the real GRBL 1.1h firmware and to our simulated gantry.

Each step sends a byte sequence to both over a pty, collects the reply lines, and the two
transcripts must be equal after :func:`normalise` (which drops what cannot match: grbl-sim's
``Pn:`` field, and the momentary position and feed in reports taken while the machine moves).
Both peers restart when their port is opened, as an Arduino does.

Known and kept differences (not compared): grbl-sim has no limit switches, so its homing
fails with ALARM:8 where the simulator homes; motion timing (grbl-sim accelerates and runs
at about a fifth of real time on a busy host; the simulator moves at constant speed).
"""

from __future__ import annotations

import re
import threading
import time
from pathlib import Path

import pytest
import serial
from firmware_bridge import FirmwareBridge

from labauto.drivers.grbl import TravelLimits
from labauto.drivers.grbl_sim import SimulatedGantry
from labauto.drivers.line_link import _close_quickly

pytestmark = pytest.mark.timeout(240)  # only a starved grbl-sim takes long

SPACE = TravelLimits(x=(-200.0, 0.0), y=(-200.0, 0.0), z=(-50.0, 0.0))


class Peer:
    """A raw serial connection that records what each step earned."""

    def __init__(self, path: str) -> None:
        self.port = serial.serial_for_url(path, baudrate=115200, timeout=0.01)
        self.buffer = b""

    def step(self, data: bytes, *, quiet: float = 0.25, at_least: float = 0.0) -> list[str]:
        """Send ``data``; return the lines that came until none came for ``quiet`` seconds.

        Reads for ``at_least`` seconds in any case (for replies that come after a delay).
        """
        if data:
            self.port.write(data)
        start = last = time.monotonic()
        while True:
            chunk = self.port.read(self.port.in_waiting or 1)
            now = time.monotonic()
            if chunk:
                self.buffer += chunk
                last = now
            if now - last >= quiet and now - start >= at_least:
                break
            if now - start > 15:
                break
        *lines, self.buffer = self.buffer.split(b"\r\n")
        return [line.decode("ascii", errors="replace") for line in lines]

    def states(self, seconds: float, every: float = 0.02) -> list[str]:
        """Poll ``?`` for ``seconds``; return the distinct states in the order seen."""
        seen: list[str] = []
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            for line in self.step(b"?", quiet=every):
                match = re.match(r"<([A-Za-z]+(?::\d)?)\|", line)
                if match and (not seen or seen[-1] != match.group(1)):
                    seen.append(match.group(1))
        return seen

    def close(self) -> None:
        _close_quickly(self.port)


def normalise(line: str, *, blank: bool = False) -> str:
    """Drop grbl-sim's ``Pn:`` field; blank the numbers of reports taken in motion.

    ``blank`` blanks positions in any report (where they are a matter of motion timing).
    """
    line = re.sub(r"\|Pn:[A-Z]*", "", line)
    if blank or re.match(r"<(Run|Hold:1|Home|Jog)\|", line):
        line = re.sub(r"(MPos|WPos):[-\d.,]+", r"\1:*", line)
        line = re.sub(r"\|FS:\d+,", "|FS:*,", line)
    return line


#: (label, bytes, read options). Run in this order on one connection per peer.
SCRIPT: list[tuple[str, bytes, dict[str, float]]] = [
    ("boot banner", b"", {"at_least": 2.5, "quiet": 0.3}),
    ("build info", b"$I\n", {}),
    ("status after power-up", b"?", {}),
    ("g-code locked in the homing alarm", b"G0 X-1\n", {}),
    ("unlock", b"$X\n", {}),
    ("status: overrides one report after WCO", b"?", {}),
    ("status: plain", b"?", {}),
    ("work position reports", b"$10=0\n", {}),
    ("work offset", b"G10 L2 P1 X-5 Y-6 Z0\n", {}),
    *[(f"WPos report {i}", b"?", {"quiet": 0.1}) for i in range(11)],
    ("machine position reports again", b"$10=1\nG10 L2 P1 X0 Y0 Z0\n", {}),
    ("status after the offset change", b"?", {}),
    ("a dwell", b"G4 P1.5\n", {"quiet": 0.3}),
    ("reset during the dwell: the dwell is answered ok", b"\x18", {"at_least": 0.8}),
    ("unlock when not locked", b"$X\n", {}),
    ("soft limit", b"G53 G1 X1 F1000\n", {"quiet": 0.1}),
    # the message comes when the alarm delay is over: up to ~2x later when the machine is loaded
    ("reset inside the alarm delay is lost", b"\x18", {"at_least": 2.5}),
    ("status is not answered when locked", b"?", {"quiet": 0.4}),
    ("reset: the stopped line is answered ok", b"\x18", {"at_least": 0.6}),
    ("unlock after the soft limit", b"$X\n", {}),
    (
        "a move (slow enough for both to be moving at the reset)",
        b"G53 G1 X-20 F300\n",
        {"quiet": 0.3},
    ),
    ("wait for it", b"G4 P0\n", {"quiet": 0.1, "at_least": 0.2}),
    # quiet 0.3 s: a loaded host delays either peer's report by more than 0.05 s (seen under
    # two busy loops on 2 cores), and the move lasts 4 s, so both still move at the reset
    ("status while moving", b"?", {"quiet": 0.3}),
    # grbl-sim prints the two in either order (its reset "interrupt" is a second host thread);
    # GRBL's code and the simulator say ALARM:3 first. Compared as a set.
    ("reset during the move: ALARM:3 and the wait's ok", b"\x18", {"at_least": 1.2, "sort": 1}),
    ("status after (position: a matter of timing)", b"?", {"blank": 1}),
]


#: (step label, the lines it earned), in the order of :data:`SCRIPT`.
Transcript = list[tuple[str, list[str]]]


def transcript(peer: Peer) -> Transcript:
    """Run :data:`SCRIPT`, then the homing check, on ``peer``."""
    record = []
    for label, data, options in SCRIPT:
        read = {key: value for key, value in options.items() if key not in ("blank", "sort")}
        lines = [normalise(x, blank="blank" in options) for x in peer.step(data, **read)]
        record.append((label, sorted(lines) if "sort" in options else lines))
    peer.step(b"$X\nG53 G1 X-10 F3000\n")
    wait_idle(peer)
    peer.step(b"$H\n", quiet=0.1)
    reports = [x for x in peer.step(b"?", quiet=0.5) if x.startswith("<")]
    record.append(("homing: ? is not answered", reports))  # grbl-sim may fail homing meanwhile
    # The feed hold (Hold:1 then Hold:0) is compared in neither direction here: in this
    # sequence grbl-sim's hold stayed at Hold:1 in some runs (its stepper "interrupt" is a host
    # thread). tests/firmware/test_firmware_driver.py checks it on the firmware (with retries),
    # tests/drivers on the simulator.
    return record


def wait_idle(peer: Peer) -> None:
    """Poll until the machine reports Idle (grbl-sim may take a while)."""
    deadline = time.monotonic() + 90
    while (states := peer.states(0.05)) != ["Idle"]:
        assert time.monotonic() < deadline, f"never Idle: {states}"
        time.sleep(0.1)


def simulator_transcript(result: list[Transcript]) -> None:
    """The transcript of our simulated gantry, set up like the firmware's test settings."""
    with SimulatedGantry(
        SPACE,
        speed_factor=1.0,
        reset_on_open=True,
        boot_delay=1.0,
        hold_decel=0.3,  # grbl-sim decelerates slowly at a fifth of real time
        homing_feed=500.0,  # slow enough to ask ? during homing
    ) as sim:
        peer = Peer(sim.start_pty())
        try:
            result.append(transcript(peer))
        finally:
            peer.close()


def both_transcripts(grbl_sim_exe: Path, eeprom: Path) -> tuple[Transcript, Transcript]:
    """The firmware's and the simulator's transcripts, taken at the same time."""
    ours: list[Transcript] = []
    beside = threading.Thread(target=simulator_transcript, args=(ours,))  # both at once
    beside.start()
    try:
        with FirmwareBridge(grbl_sim_exe, eeprom, restart_on_open=True) as board:
            peer = Peer(board.path)
            try:
                firmware_transcript = transcript(peer)
            finally:
                peer.close()
    finally:
        beside.join(timeout=60)
    assert len(ours) == 1, "the simulator's transcript did not finish"
    return firmware_transcript, ours[0]


def test_simulator_answers_like_the_firmware(grbl_sim_exe: Path, eeprom: Path) -> None:
    # Up to two runs: on a loaded host grbl-sim now and then drops a report or lets a move end
    # before the reset meant to stop it (each seen once in 10 runs under two busy loops). A real
    # difference of the simulator's protocol shows in every run; timing shows in one.
    for _run in range(2):
        firmware_transcript, simulated = both_transcripts(grbl_sim_exe, eeprom)
        differences = [
            f"{label}:\n  firmware  {real}\n  simulator {ours}"
            for (label, real), (_, ours) in zip(firmware_transcript, simulated, strict=True)
            if real != ours
        ]
        if not differences:
            break
    assert not differences, "\n".join(differences)
    steps = dict(firmware_transcript)  # what was compared, as the firmware said it
    assert steps["boot banner"] == ["", "Grbl 1.1h ['$' for help]", "[MSG:'$H'|'$X' to unlock]"]
    assert steps["reset during the dwell: the dwell is answered ok"][0] == "ok"
    assert steps["soft limit"] == ["ALARM:2"]
    assert steps["reset inside the alarm delay is lost"] == ["[MSG:Reset to continue]"]
    assert steps["status is not answered when locked"] == []
    assert {"ALARM:3", "ok"} <= set(steps["reset during the move: ALARM:3 and the wait's ok"])
    assert steps["homing: ? is not answered"] == []
