"""The built-in drivers and the driver plugin's factories satisfy labauto.devices' Protocols."""

from __future__ import annotations

import threading
from pathlib import Path

from grbl_fixtures import wait_for

from labauto.config import Config, load_config
from labauto.devices import Analyzer, Camera, Robot
from labauto.drivers.analyzer import Analyzer as ModbusAnalyzer
from labauto.drivers.camera import FolderCamera
from labauto.drivers.grbl import GrblRobot, TravelLimits
from labauto.drivers.grbl_sim import SimulatedGantry
from labauto.plugins import devices
from labauto.synthetic.camera import SimulatedCamera


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


def test_the_real_hardware_example_fits_a_stock_grbl_build() -> None:
    """configs/real-hardware.example.yaml: negative machine space, and the driver agrees."""
    example = Path(__file__).resolve().parents[2] / "configs" / "real-hardware.example.yaml"
    config = load_config(example, environ={})
    robot = config.robot
    limits = TravelLimits(x=robot.limits_x_mm, y=robot.limits_y_mm, z=robot.limits_z_mm)
    assert limits.contains(robot.deposit.x, robot.deposit.y, robot.deposit.z)
    assert all(limits.contains(*p.deck, robot.pick_z_mm) for p in config.calibration.points)
    with SimulatedGantry(limits, speed_factor=100) as stock:  # $130=400 ..., no force origin
        driver = GrblRobot(stock.start_pty(), limits=limits, timeout=0.5, boot_timeout=0)
        with driver:
            assert driver.build_options is not None and driver.build_options.codes == "V"
            assert float(driver.controller_settings[130]) == 400.0
