"""Built-in plugin: device drivers for the workcell, real or simulated.

* robot ``grbl`` — a GRBL 1.1 gantry over any pyserial URL (``labauto.drivers.grbl``);
* analyzer ``modbus`` — a Modbus TCP/RTU analyzer with a YAML register map
  (``labauto.drivers.analyzer``);
* camera ``folder`` (image files or a folder; ``samples`` for the bundled plates) and
  ``simulated`` (freshly generated synthetic plates).

Each factory takes its validated config section and returns an unconnected device typed by
the Protocols of :mod:`labauto.devices` (``Robot``, ``Analyzer``, ``Camera``).

With ``simulate: true`` in its config section, a robot or analyzer factory first starts the
simulated device (a GRBL gantry behind a pseudo-terminal or TCP socket, a pymodbus server on
127.0.0.1 or an RTU server on a pseudo-terminal) and points the real driver at it: only the
transport's far end is simulated, never the driver. The device returned is the real driver
class extended by one thing, :class:`SimulatedGrblRobot` / :class:`SimulatedModbusAnalyzer`:
it owns the simulator (``simulator``), and ``close()`` stops it (``reconnect()`` does not).
The simulated gantry's machine space follows the configured limits: limits starting at 0 model
a GRBL build with ``HOMING_FORCE_SET_ORIGIN`` (X/Y homing to their minimum), limits ending at
0 a stock build.
"""

from __future__ import annotations

from typing import Any

from labauto.devices import Analyzer, Camera, Robot
from labauto.drivers.analyzer import Analyzer as ModbusAnalyzer
from labauto.drivers.analyzer_sim import SimulatedAnalyzer
from labauto.drivers.camera import FolderCamera
from labauto.drivers.grbl import GrblRobot
from labauto.drivers.grbl_protocol import TravelLimits
from labauto.drivers.grbl_sim import SimulatedGantry
from labauto.hookspecs import hookimpl
from labauto.synthetic.camera import SimulatedCamera


class SimulatedGrblRobot(GrblRobot):
    """The GRBL driver talking to a :class:`SimulatedGantry` it owns; ``close()`` stops both."""

    def __init__(self, url: str, simulator: SimulatedGantry, **options: Any) -> None:
        super().__init__(url, **options)
        self.simulator = simulator

    def close(self) -> None:
        """Close the link, then stop the simulator (idempotent)."""
        try:
            super().close()
        finally:
            self.simulator.stop()


class SimulatedModbusAnalyzer(ModbusAnalyzer):
    """The Modbus driver talking to a :class:`SimulatedAnalyzer` it owns; ``close()`` stops both."""

    def __init__(self, simulator: SimulatedAnalyzer, *args: Any, **options: Any) -> None:
        super().__init__(*args, **options)
        self.simulator = simulator

    def close(self) -> None:
        """Close the link, then stop the simulator (idempotent)."""
        try:
            super().close()
        finally:
            self.simulator.stop()


def make_grbl_robot(section: Any) -> Robot:
    """A ``GrblRobot`` from a ``robot`` config section (with its simulator if simulated)."""
    limits = TravelLimits(x=section.limits_x_mm, y=section.limits_y_mm, z=section.limits_z_mm)
    options: dict[str, Any] = dict(
        baudrate=section.baudrate,
        timeout=section.timeout_s,
        limits=limits,
        safe_z=section.safe_z_mm,
        travel_feed=section.travel_feed,
        z_feed=section.z_feed,
        motion_timeout=section.motion_timeout_s,
        tool_timeout=section.tool_timeout_s,
    )
    if not section.simulate:
        return GrblRobot(section.port, **options)
    sim = section.simulator
    gantry = SimulatedGantry(limits, speed_factor=sim.speed_factor, faults=sim.faults)
    try:
        url = gantry.start_pty() if sim.transport == "pty" else gantry.start_tcp()
        return SimulatedGrblRobot(url, gantry, **options)
    except BaseException:
        gantry.stop()
        raise


def make_modbus_analyzer(section: Any) -> Analyzer:
    """An ``Analyzer`` from an ``analyzer`` config section (with its simulator if simulated)."""
    options: dict[str, Any] = dict(
        register_map=section.register_map,
        timeout=section.timeout_s,
        unit_id=section.unit,
        baudrate=section.baudrate,
        parity=section.parity,  # RTU framing; 8E1 is Modbus's default
        stopbits=section.stopbits,
    )
    if not section.simulate:
        return ModbusAnalyzer(
            section.transport,
            host=section.host,
            port=section.port,
            serial_port=section.serial_port,
            **options,
        )
    sim = section.simulator
    server = SimulatedAnalyzer(
        section.register_map,
        analysis_seconds=sim.analysis_seconds,
        speed_factor=sim.speed_factor,
        faults=sim.faults,
        scan_cycle_s=sim.scan_cycle_s,
    )
    try:
        if sim.transport == "tcp":
            host, port = server.start_tcp("127.0.0.1")
            return SimulatedModbusAnalyzer(server, "tcp", host=host, port=port, **options)
        # A Linux pty refuses even parity (EINVAL) and carries no parity bits anyway.
        options["parity"] = "N"
        return SimulatedModbusAnalyzer(server, "rtu", serial_port=server.start_rtu(), **options)
    except BaseException:
        server.stop()
        raise


def make_folder_camera(section: Any) -> Camera:
    """A ``FolderCamera`` from a ``camera`` config section."""
    return FolderCamera(section.path, section.pattern)


def make_simulated_camera(section: Any) -> Camera:
    """A camera of freshly generated synthetic plates (``camera.count`` of them)."""
    return SimulatedCamera(count=section.count)


@hookimpl
def labauto_register_drivers(register: Any) -> None:
    register("robot", "grbl", make_grbl_robot)
    register("analyzer", "modbus", make_modbus_analyzer)
    register("camera", "folder", make_folder_camera)
    register("camera", "simulated", make_simulated_camera)
