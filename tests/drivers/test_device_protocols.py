"""The built-in drivers and the driver plugin's factories satisfy labauto.devices' Protocols."""

from __future__ import annotations

import threading

from grbl_fixtures import wait_for

from labauto.config import Config
from labauto.devices import Analyzer, Camera, Robot
from labauto.drivers.analyzer import Analyzer as ModbusAnalyzer
from labauto.drivers.camera import FolderCamera, SimulatedCamera
from labauto.drivers.grbl import GrblRobot
from labauto.plugins import devices


def sim_threads() -> set[str]:
    return {t.name for t in threading.enumerate() if t.name.startswith("labauto-")}


def test_built_in_drivers_satisfy_the_protocols() -> None:
    assert isinstance(GrblRobot("socket://127.0.0.1:1"), Robot)
    assert isinstance(ModbusAnalyzer("tcp"), Analyzer)
    assert isinstance(FolderCamera("samples"), Camera)
    assert isinstance(SimulatedCamera(1), Camera)
    assert not isinstance(ModbusAnalyzer("tcp"), Robot)  # the check means something
    assert not isinstance(GrblRobot("socket://127.0.0.1:1"), Analyzer)


def test_simulated_devices_are_the_real_drivers_and_close_stops_their_simulator() -> None:
    config = Config()
    before = sim_threads()
    robot = devices.make_grbl_robot(config.robot)
    analyzer = devices.make_modbus_analyzer(config.analyzer)
    assert type(robot).__mro__[1] is GrblRobot and isinstance(robot, Robot)
    assert isinstance(analyzer, ModbusAnalyzer) and isinstance(analyzer, Analyzer)
    assert not hasattr(devices, "Simulated")  # no attribute-forwarding wrapper any more
    try:
        robot.connect()
        robot.reconnect()  # renews the link only: the simulator keeps running
        assert robot.identify()["firmware"] == "1.1h"
        analyzer.connect()
        analyzer.reconnect()
        assert analyzer.identify()["state"] == "idle"
        log: list[tuple[str, str]] = []
        robot.on_exchange = lambda direction, text: log.append((direction, text))
        robot.status()
        assert ("tx", "?") in log  # the callback reaches the driver's link
    finally:
        robot.close()
        analyzer.close()
    assert wait_for(lambda: sim_threads() <= before)  # both simulators stopped
