"""Point 7 of issue 12: a lost reply to a tool command costs its own timeout, not 60 s.

The real GRBL driver talks to the simulated gantry over a real pseudo-terminal; the gantry
drops the reply to the next line (``no_reply``) just before ``M8`` is sent.
"""

from __future__ import annotations

import time

import pytest

from labauto.drivers.errors import DeviceTimeout
from labauto.drivers.grbl import GrblRobot
from labauto.drivers.grbl_sim import SimulatedGantry

pytestmark = pytest.mark.timeout(60)

MOTION_TIMEOUT_S = 30.0  # long, like the real 60 s: the test fails if M8 waits for it


@pytest.fixture()
def robot():
    sim = SimulatedGantry(speed_factor=200.0)
    url = sim.start_pty()
    device = GrblRobot(
        url, timeout=0.5, motion_timeout=MOTION_TIMEOUT_S, tool_timeout=0.5, poll_interval=0.005
    )
    try:
        device.connect()
        device.home()
        yield device, sim
    finally:
        device.close()
        sim.stop()


@pytest.mark.parametrize("command", ["tool_on", "tool_off"])
def test_lost_reply_to_a_tool_command_times_out_after_the_tool_timeout(robot, command):
    device, sim = robot
    device.move_to(-50.0, -50.0, -10.0)  # machine space of a stock GRBL build is negative
    sim.inject("no_reply", count=1)
    started = time.monotonic()
    with pytest.raises(DeviceTimeout):
        getattr(device, command)()
    elapsed = time.monotonic() - started
    assert elapsed < 3.0, f"{command} waited {elapsed:.1f} s for a lost reply"
    device.reconnect()  # and the driver comes back, as after any timeout
    device.home()
    device.tool_on()
    device.tool_off()


def test_tool_command_after_queued_motion_still_waits_for_the_motion(robot):
    device, _sim = robot
    device.move_to(-250.0, -150.0, wait=False)  # queued: GRBL answers M8 once it is done
    device.tool_on()  # waits for the motion first, then the short tool timeout applies
    assert device.status().state == "Idle"
    device.tool_off()
