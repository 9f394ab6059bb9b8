"""The lost-steps fault: the head really stops short while the controller reports the target."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from grbl_fixtures import gantry, rig

from labauto.config import parse_config
from labauto.drivers.grbl import GrblRobot
from labauto.drivers.grbl_sim import SimulatedGantry

pytestmark = pytest.mark.timeout(15)


@pytest.fixture
def homed() -> Iterator[tuple[SimulatedGantry, GrblRobot]]:
    with rig("pty") as (sim, robot):
        robot.home()
        yield sim, robot


def test_lost_steps_move_the_real_head_not_the_report(homed):
    sim, robot = homed
    sim.inject("lost_steps", axis="x", mm=2.5)
    reported = robot.move_to(100.0, 50.0)
    assert reported.position == (100.0, 50.0, 0.0)  # the controller believes the target
    assert sim.reported_position == pytest.approx((100.0, 50.0, 0.0))
    assert sim.position == pytest.approx((97.5, 50.0, 0.0))  # short by the steps lost
    assert sim.faults == []  # used up by the one move
    # later moves keep the offset (the controller does not know), Y moves do not lose more
    robot.move_to(100.0, 120.0)
    assert sim.position == pytest.approx((97.5, 120.0, 0.0))
    # moving back the other way: the carriage is still 2.5 mm off
    robot.move_to(40.0, 120.0)
    assert sim.position == pytest.approx((37.5, 120.0, 0.0))


def test_lost_steps_add_up_over_moves_and_stop_short_in_the_direction_of_travel(homed):
    sim, robot = homed
    sim.inject("lost_steps", axis="y", mm=1.0, count=2)
    robot.move_to(10.0, 100.0)  # +y: 1 mm short
    robot.move_to(10.0, 20.0)  # -y: 1 mm short the other way
    assert sim.position == pytest.approx((10.0, 20.0, 0.0))  # lost +1 then -1... back on
    sim.inject("lost_steps", axis="y", mm=0.7, count=2)
    robot.move_to(10.0, 60.0)
    robot.move_to(10.0, 150.0)
    assert sim.position[1] == pytest.approx(150.0 - 1.4)


def test_lost_steps_never_exceed_the_move_and_homing_finds_the_real_position(homed):
    sim, robot = homed
    robot.move_to(50.0, 50.0)
    sim.inject("lost_steps", axis="x", mm=5.0)
    robot.move_to(52.0, 50.0)  # a 2 mm move can lose at most 2 mm
    assert sim.position[0] == pytest.approx(50.0)
    robot.home()
    robot.move_to(30.0, 30.0)
    assert sim.position == pytest.approx(sim.reported_position)


def test_bad_lost_steps_options_are_named():
    with gantry() as sim:
        with pytest.raises(ValueError, match="axis must be x, y or z"):
            sim.inject("lost_steps", axis="w")
        with pytest.raises(ValueError, match="mm must be > 0"):
            sim.inject("lost_steps", mm=0)


def test_lost_steps_can_be_armed_from_a_config():
    config = parse_config(
        {"robot": {"simulator": {"faults": [{"kind": "lost_steps", "axis": "y", "mm": 3.0}]}}},
        environ={},
    )
    (fault,) = config.robot.simulator.faults
    assert fault["kind"] == "lost_steps" and fault["axis"] == "y" and fault["mm"] == 3.0
    with pytest.raises(Exception, match=r"robot\.simulator\.faults"):
        parse_config(
            {"robot": {"simulator": {"faults": [{"kind": "lost_steps", "axis": "q"}]}}},
            environ={},
        )
