"""Workcell configuration: YAML files validated when loaded.

A config file has one section per part of the workcell (see ``configs/colony-picking.yaml``).
Every section is validated on load: an unknown key, a wrong type or an out-of-range value fails
with one line naming the file, the dotted key path and what was expected, for example::

    configs/x.yaml: robot.port: expected a string, got 3

A config file is read with the guards of :mod:`labauto.safeyaml` (a regular file of at most
1 MiB, no YAML aliases, bounded nesting); numbers must be finite (no ``.nan`` or ``.inf``).

Relative paths in a config are taken relative to the current directory, as a shell would. The
database URL and the device ports can be overridden from the environment (see ``ENV_OVERRIDES``);
an override is validated like the file and its errors name the variable.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    create_model,
    model_validator,
)

from labauto.errors import ConfigError
from labauto.safeyaml import YamlRefused, load_yaml, read_text_limited, read_yaml_file
from labauto.vision.detector import DetectorParams
from labauto.vision.plate import PlateParams

#: Environment variables that override one config key each.
ENV_OVERRIDES: dict[str, str] = {
    "LABAUTO_DATABASE_URL": "database.url",
    "LABAUTO_ROBOT_PORT": "robot.port",
    "LABAUTO_ANALYZER_HOST": "analyzer.host",
    "LABAUTO_ANALYZER_PORT": "analyzer.port",
    "LABAUTO_ANALYZER_SERIAL_PORT": "analyzer.serial_port",
}

Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]
Range = tuple[float, float]
Range3 = tuple[float, float, float]


class Section(BaseModel):
    """Base of every config section: unknown keys are errors."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class DatabaseConfig(Section):
    url: str = "sqlite:///labauto.db"


class PluginsConfig(Section):
    enabled: list[str] | None = None
    disabled: list[str] = []


class CameraConfig(Section):
    driver: str = "folder"
    #: A folder or a single image file; ``samples`` means the plates bundled with labauto.
    path: str = "samples"
    pattern: str = "*.png"
    #: Number of plates the ``simulated`` camera generates.
    count: Annotated[int, Field(ge=1)] = 3


class GantryFault(Section):
    """One fault armed in the simulated gantry (``labauto.drivers.grbl_sim``)."""

    kind: str
    count: Annotated[int, Field(ge=1)] = 1
    seconds: NonNegative = 0.5
    code: Annotated[int, Field(ge=1)] = 1
    fraction: Annotated[float, Field(gt=0, lt=1)] = 0.5
    #: ``lost_steps``: the axis and the travel (mm) each affected move loses.
    axis: Literal["x", "y", "z"] = "x"
    mm: Positive = 1.0

    @model_validator(mode="before")
    @classmethod
    def _fault_is_kind(cls, data: Any) -> Any:
        if isinstance(data, dict) and "fault" in data and "kind" not in data:
            data = {("kind" if key == "fault" else key): value for key, value in data.items()}
        return data

    @model_validator(mode="after")
    def _known_kind(self) -> GantryFault:
        from labauto.drivers.grbl_sim import FAULT_KINDS

        if self.kind not in FAULT_KINDS:
            known = ", ".join(FAULT_KINDS)
            raise ValueError(f"unknown fault {self.kind!r}; expected one of {known}")
        return self


def _gantry_faults(faults: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Check each gantry fault; keep them as plain mappings (what the simulator takes)."""
    return [GantryFault.model_validate(fault).model_dump() for fault in faults]


def _analyzer_faults(faults: dict[str, int | None]) -> dict[str, int | None]:
    """Check the names and codes of the simulated analyzer's faults."""
    from labauto.drivers.analyzer_sim import FAULTS

    for name, code in faults.items():
        if name not in FAULTS:
            raise ValueError(f"unknown fault {name!r}; expected one of {', '.join(FAULTS)}")
        if code is not None and name not in ("error_state", "exception"):
            raise ValueError(f"fault {name!r} takes no code, got {code!r}")
        if code is not None and not 0 < code < 65536:
            raise ValueError(f"fault {name!r}: code must be 1-65535, got {code!r}")
    return faults


class RobotSimulatorConfig(Section):
    """The simulated gantry used when ``robot.simulate`` is true."""

    speed_factor: Positive = 20.0
    transport: Literal["pty", "tcp"] = "pty"
    #: Faults armed from the start, e.g. ``[{kind: no_reply, count: 1}]`` (see grbl_sim).
    faults: Annotated[list[dict[str, Any]], AfterValidator(_gantry_faults)] = []


class AnalyzerSimulatorConfig(Section):
    """The simulated analyzer used when ``analyzer.simulate`` is true."""

    speed_factor: Positive = 20.0
    transport: Literal["tcp", "rtu"] = "tcp"
    analysis_seconds: NonNegative = 2.0
    #: Commands take effect at the next scan of this period (s), as on a PLC front-end; 0: at once.
    scan_cycle_s: NonNegative = 0.0
    #: Faults active from the start, e.g. ``{error_state: 7}`` (see analyzer_sim).
    faults: Annotated[dict[str, int | None], AfterValidator(_analyzer_faults)] = {}


class DeckPoint(Section):
    x: float
    y: float
    z: float = 0.0


class RobotConfig(Section):
    driver: str = "grbl"
    simulate: bool = True
    simulator: RobotSimulatorConfig = RobotSimulatorConfig()
    port: str = "/dev/ttyUSB0"
    baudrate: Annotated[int, Field(gt=0)] = 115200
    timeout_s: Positive = 2.0
    motion_timeout_s: Positive = 60.0
    #: Reply timeout of a tool command (M8/M9), sent once the motion before it has finished.
    tool_timeout_s: Positive = 5.0
    limits_x_mm: Range = (0.0, 300.0)
    limits_y_mm: Range = (0.0, 200.0)
    limits_z_mm: Range = (-50.0, 0.0)
    safe_z_mm: float = -5.0
    pick_z_mm: float = -30.0
    dwell_s: NonNegative = 0.2
    travel_feed: Positive = 3000.0
    z_feed: Positive = 1000.0
    home_on_start: bool = True
    deposit: DeckPoint = DeckPoint(x=280.0, y=180.0, z=-20.0)

    @model_validator(mode="after")
    def _check_ranges(self) -> RobotConfig:
        for axis in ("x", "y", "z"):
            low, high = getattr(self, f"limits_{axis}_mm")
            if low >= high:
                raise ValueError(f"limits_{axis}_mm: expected [min, max] with min < max")
        for problem in self.position_problems():
            raise ValueError(problem)
        return self

    def position_problems(self) -> list[str]:
        """Every configured position (safe height, pick height, deposit) outside the limits."""
        (x0, x1), (y0, y1), (z0, z1) = self.limits_x_mm, self.limits_y_mm, self.limits_z_mm
        checks = [
            ("safe_z_mm", self.safe_z_mm, z0, z1),
            ("pick_z_mm", self.pick_z_mm, z0, z1),
            ("deposit.x", self.deposit.x, x0, x1),
            ("deposit.y", self.deposit.y, y0, y1),
            ("deposit.z", self.deposit.z, z0, z1),
        ]
        return [
            f"{name}: {value:g} mm is outside the travel limits [{low:g}, {high:g}] mm"
            for name, value, low, high in checks
            if not low <= value <= high
        ]


def _short(text: str, limit: int = 200) -> str:
    """One line of at most ``limit`` characters (an error must not print a whole file)."""
    line = " ".join(text.split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


def _check_register_map(path: str | None) -> str | None:
    """Read and check a register map file with the config's guards (see ``safeyaml``).

    A file that does not exist (yet) is left to the analyzer driver, which reports it when it
    connects: an example config may name the map of a machine it is not on.
    """
    if path is None or not os.path.lexists(path):
        return path
    from labauto.drivers.analyzer_map import parse_map

    try:
        data = read_yaml_file(path, what="register map")
    except YamlRefused as exc:
        raise ValueError(str(exc)) from None
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the register map ({exc.strerror})") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: register map is not valid YAML{_yaml_where(exc)}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a register map (a mapping), got {type(data).__name__}")
    try:
        parse_map(data, path)
    except Exception as exc:
        raise ValueError(_short(str(exc))) from None
    return path


class RetryConfig(Section):
    """How a device that failed is brought back: tries with a growing delay between them."""

    attempts: Annotated[int, Field(ge=1, le=100)] = 5
    initial_delay_s: NonNegative = 1.0
    factor: Annotated[float, Field(ge=1)] = 2.0
    max_delay_s: NonNegative = 15.0

    def delays(self) -> list[float]:
        """The wait before each try after the first (``attempts - 1`` values)."""
        return [
            min(self.max_delay_s, self.initial_delay_s * self.factor**i)
            for i in range(self.attempts - 1)
        ]


class RunSection(Section):
    """How a run is owned and recovered."""

    #: A run's owner that has not shown it is alive for this long may be taken over.
    lease_timeout_s: Positive = 30.0
    #: How often the owner shows it is alive.
    heartbeat_s: Positive = 5.0
    #: Where the advisory locks of real devices live (default: the system's temp folder).
    lock_dir: str | None = None
    retry: RetryConfig = RetryConfig()

    @model_validator(mode="after")
    def _heartbeat_within_timeout(self) -> RunSection:
        if self.heartbeat_s >= self.lease_timeout_s:
            raise ValueError(
                f"heartbeat_s ({self.heartbeat_s:g}) must be less than lease_timeout_s "
                f"({self.lease_timeout_s:g})"
            )
        return self


class AnalyzerConfig(Section):
    driver: str = "modbus"
    simulate: bool = True
    simulator: AnalyzerSimulatorConfig = AnalyzerSimulatorConfig()
    transport: Literal["tcp", "rtu"] = "tcp"
    host: str = "127.0.0.1"
    port: Annotated[int, Field(ge=0, le=65535)] = 502
    serial_port: str = "/dev/ttyUSB1"
    baudrate: Annotated[int, Field(gt=0)] = 19200
    unit: Annotated[int, Field(ge=1, le=247)] = 1
    #: RTU framing (Modbus's default is 8E1: even parity, one stop bit).
    parity: Literal["N", "E", "O"] = "E"
    stopbits: Literal[1, 2] = 1
    #: A YAML register map; ``None`` uses the map shipped with labauto.
    register_map: Annotated[str | None, AfterValidator(_check_register_map)] = None
    timeout_s: Positive = 2.0
    analysis_timeout_s: Positive = 120.0


class CalibrationPoint(Section):
    pixel: tuple[float, float]
    deck: tuple[float, float]


class HeadMarkerConfig(Section):
    """The coded marker carried by the tool head (issue 14.5)."""

    id: Annotated[int, Field(ge=0)] = 300
    radius_mm: Positive = 1.5
    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)


class DeckGridConfig(Section):
    """Head positions of the automatic deck calibration: a grid at one or more heights."""

    x_mm: Range = (44.0, 124.0)
    y_mm: Range = (40.0, 102.0)
    counts: tuple[Annotated[int, Field(ge=2)], Annotated[int, Field(ge=2)]] = (4, 3)
    z_mm: Annotated[list[float], Field(min_length=1)] = [-5.0, -20.0]


class DeckBoardConfig(Section):
    """A coded board lying face up on the deck at a known place."""

    path: str
    origin_mm: tuple[float, float, float]
    angle_deg: float = 0.0
    image: str | None = None


class SimulatedDeckCameraConfig(Section):
    """The simulated camera over the deck (used when the robot is simulated)."""

    camera_matrix: tuple[Range3, Range3, Range3] = ((1400.0, 0.0, 640.0), (0.0, 1400.0, 512.0),
                                                    (0.0, 0.0, 1.0))  # fmt: skip
    dist_coeffs: list[float] = [-0.1, 0.03, 0.0, 0.0, 0.0]
    position_mm: tuple[float, float, float] = (84.0, 71.0, 140.0)
    tilt_deg: Range = (2.0, -3.0)
    image_size: tuple[Annotated[int, Field(gt=0)], Annotated[int, Field(gt=0)]] = (1280, 1024)


class DeckCalibrationConfig(Section):
    """``labauto calibrate deck``: the camera's pose over the deck (issue 14.5)."""

    name: str = "deck"
    camera: str | None = None
    source: Literal["head", "board"] = "head"
    surface_z_mm: float | None = None
    head_marker: HeadMarkerConfig = HeadMarkerConfig()
    grid: DeckGridConfig = DeckGridConfig()
    board: DeckBoardConfig | None = None
    simulated_camera: SimulatedDeckCameraConfig = SimulatedDeckCameraConfig()


class CalibrationConfig(Section):
    """Pixel-to-deck calibration: the stored deck calibration named ``deck.name`` when one
    exists and ``use_stored`` is on, else a homography from at least four point pairs."""

    use_stored: bool = True
    deck: DeckCalibrationConfig = DeckCalibrationConfig()

    points: Annotated[list[CalibrationPoint], Field(min_length=4)] = [
        CalibrationPoint(pixel=(0.0, 0.0), deck=(20.0, 20.0)),
        CalibrationPoint(pixel=(1279.0, 0.0), deck=(148.0, 20.0)),
        CalibrationPoint(pixel=(1279.0, 1023.0), deck=(148.0, 122.3)),
        CalibrationPoint(pixel=(0.0, 1023.0), deck=(20.0, 122.3)),
    ]
    max_residual_mm: Positive = 0.5


class PickingConfig(Section):
    max_picks: Annotated[int, Field(ge=0)] = 8
    min_neighbor_distance_px: NonNegative = 12.0
    min_rim_distance_px: NonNegative = 20.0
    order: Literal["largest", "smallest", "roundest", "scan"] = "largest"
    classes: list[Literal["authentic"]] = ["authentic"]


class OutputConfig(Section):
    dir: str = "out"
    annotate: bool = True


class HeadCheckConfig(Section):
    """The camera watching the picking head (:mod:`labauto.orchestrator.head_check`)."""

    enabled: bool = False
    #: Id of the coded marker on the head; ``null``: ``calibration.deck.head_marker.id``.
    marker_id: Annotated[int, Field(ge=0)] | None = None
    #: Largest distance (mm) between the seen and the commanded head position.
    tolerance_mm: Positive = 0.5
    #: ``simulated``: rendered where the simulated gantry really is (needs ``robot.simulate``);
    #: ``camera``: the camera driver's ``capture()``.
    camera: Literal["simulated", "camera"] = "simulated"
    #: Centre-circle radius (mm) of the marker the simulated camera draws with the config's
    #: homography; ``null``: ``calibration.deck.head_marker.radius_mm``.
    marker_radius_mm: Positive | None = None

    @model_validator(mode="after")
    def _known_marker(self) -> HeadCheckConfig:
        from labauto.vision.marker_codes import n_codes

        if self.marker_id is not None and self.marker_id >= n_codes():
            raise ValueError(f"marker_id: {self.marker_id} is no marker id (0-{n_codes() - 1})")
        return self


class Config(Section):
    """A whole workcell configuration."""

    name: str = "colony-picking"
    database: DatabaseConfig = DatabaseConfig()
    plugins: PluginsConfig = PluginsConfig()
    segmenter: str = "canny"
    detector: dict[str, Any] = {}
    plate: dict[str, Any] = {}
    camera: CameraConfig = CameraConfig()
    robot: RobotConfig = RobotConfig()
    analyzer: AnalyzerConfig = AnalyzerConfig()
    calibration: CalibrationConfig = CalibrationConfig()
    picking: PickingConfig = PickingConfig()
    output: OutputConfig = OutputConfig()
    run: RunSection = RunSection()
    head_check: HeadCheckConfig = HeadCheckConfig()


_EXPECTED = {
    "string_type": "a string",
    "int_type": "an integer",
    "int_parsing": "an integer",
    "int_from_float": "an integer",
    "float_type": "a number",
    "float_parsing": "a number",
    "bool_type": "true or false",
    "bool_parsing": "true or false",
    "list_type": "a list",
    "tuple_type": "a list",
    "dict_type": "a mapping",
    "model_type": "a mapping",
    "model_attributes_type": "a mapping",
    "finite_number": "a finite number",
}


def _describe(error: dict[str, Any]) -> str:
    """Turn one pydantic error into ``expected ..., got ...``."""
    kind = error["type"]
    got = error.get("input")
    ctx = error.get("ctx") or {}
    if kind in ("extra_forbidden", "unexpected_keyword_argument"):
        return "unknown key"
    if kind == "missing":
        return "missing required key"
    if kind in _EXPECTED:
        return f"expected {_EXPECTED[kind]}, got {got!r}"
    bounds = {
        "greater_than": ">",
        "greater_than_equal": ">=",
        "less_than": "<",
        "less_than_equal": "<=",
    }
    if kind in bounds:
        limit = next(iter(ctx.values()))
        limit = f"{limit:g}" if isinstance(limit, float) else limit
        return f"expected a value {bounds[kind]} {limit}, got {got!r}"
    if kind == "literal_error":
        return f"expected {ctx.get('expected')}, got {got!r}"
    if kind == "too_short":
        return f"expected at least {ctx.get('min_length')} items, got {len(got)}"
    if kind == "too_long":
        return f"expected at most {ctx.get('max_length')} items, got {len(got)}"
    message = str(error["msg"])
    message = message.removeprefix("Value error, ")
    return message


def _is_type_tag(part: Any) -> bool:
    """True for the loc parts pydantic adds to name a union member, e.g. ``tuple[float, ...]``."""
    return isinstance(part, str) and ("[" in part or part[:1].isupper())


def _format(source: str, exc: ValidationError, prefix: str = "") -> str:
    """One line per problem: ``source: dotted.key: what was expected, got what``.

    Errors under a union (a key that takes one of several forms) are folded into one line per
    key that names the forms allowed.
    """
    lines: list[str] = []
    unions: dict[str, list[str]] = {}
    for error in exc.errors():
        loc = [part for part in (prefix, *error["loc"]) if part != ""]
        tags = [i for i, part in enumerate(loc) if _is_type_tag(part)]
        if tags:
            path = ".".join(str(part) for part in loc[: tags[0]])
            form = str(loc[tags[0]])
            if form not in unions.setdefault(path, []):
                unions[path].append(form)
            continue
        path = ".".join(str(part) for part in loc)
        lines.append(
            f"{source}: {path}: {_describe(error)}" if path else f"{source}: {_describe(error)}"
        )
    for path, forms in unions.items():
        lines.append(f"{source}: {path}: expected one of: {'; '.join(forms)}")
    return "\n".join(lines)


def _set_dotted(data: dict[str, Any], dotted: str, value: Any) -> None:
    node = data
    *parents, leaf = dotted.split(".")
    for key in parents:
        child = node.get(key)
        if not isinstance(child, dict):
            child = {}
            node[key] = child
        node = child
    node[leaf] = value


def apply_env_overrides(data: dict[str, Any], environ: dict[str, str] | None = None) -> list[str]:
    """Apply ``ENV_OVERRIDES`` found in ``environ`` to ``data``; return the variables used."""
    environ = os.environ if environ is None else environ
    used = []
    for variable, dotted in ENV_OVERRIDES.items():
        if variable in environ:
            raw = environ[variable]
            value: Any = int(raw) if dotted == "analyzer.port" and raw.strip().isdigit() else raw
            _set_dotted(data, dotted, value)
            used.append(variable)
    return used


#: Config sections that hold the parameters of a vision dataclass, and that dataclass.
DATACLASS_SECTIONS: dict[str, type] = {"detector": DetectorParams, "plate": PlateParams}

#: Ranges and choices for fields of those dataclasses, checked when a config is loaded.
SECTION_CONSTRAINTS: dict[str, dict[str, Any]] = {
    "detector": {
        "blur_sigma": Field(ge=0),
        "canny_low": Field(ge=0),
        "canny_high": Field(gt=0),
        "color_threshold": Field(gt=0),
        "min_contour_length": Field(ge=3),
        "max_contour_length": Field(ge=3),
        "des_threshold_deg": Field(gt=0, le=90),
        "statistic": Literal["median", "mean"],
    },
    "plate": {
        "rim_margin_mm": float,  # negative grows the usable area past the dish edge found
    },
}


def _is_number_type(annotation: Any) -> bool:
    return annotation in (int, float)


def _is_pair_type(annotation: Any) -> bool:
    return typing.get_origin(annotation) is tuple and typing.get_args(annotation) in (
        (float, float),
        (int, int),
    )


def _generic_rule(annotation: Any, default: Any) -> Any:
    """A range rule read from a field's type and default (no field names hard-coded).

    A number (or a pair of numbers) whose default is not negative must not be negative; a pair
    (``*_range``) must be ``[low, high]`` with ``low <= high``.
    """
    if _is_number_type(annotation) and isinstance(default, int | float) and default >= 0:
        return Annotated[annotation, Field(ge=0)]
    if _is_pair_type(annotation) and isinstance(default, tuple):
        element = typing.get_args(annotation)[0]
        if all(isinstance(v, int | float) and v >= 0 for v in default):
            element = Annotated[element, Field(ge=0)]
        return Annotated[tuple[element, element], AfterValidator(_ordered_pair)]
    return annotation


def _ordered_pair(pair: tuple[float, float]) -> tuple[float, float]:
    if pair[0] > pair[1]:
        raise ValueError(f"expected [low, high] with low <= high, got [{pair[0]:g}, {pair[1]:g}]")
    return pair


#: Name patterns of a field pair that must hold ``low <= high``: (low prefix/suffix, high).
_PAIR_PATTERNS = (("min_", "max_"), ("_low", "_high"), ("_min", "_max"))


def _bound_pairs(names: list[str]) -> list[tuple[str, str]]:
    """Fields that bound the same quantity from below and above, e.g. canny_low/canny_high."""
    pairs = []
    for name in names:
        for low, high in _PAIR_PATTERNS:
            if low.endswith("_") and name.startswith(low):
                other = high + name.removeprefix(low)
            elif low.startswith("_") and name.endswith(low):
                other = name.removesuffix(low) + high
            else:
                continue
            if other in names:
                pairs.append((name, other))
    return pairs


def _check_bound_pairs(pairs: list[tuple[str, str]]) -> Any:
    def check(model: BaseModel) -> BaseModel:
        for low, high in pairs:
            lo, hi = getattr(model, low), getattr(model, high)
            if isinstance(lo, int | float) and isinstance(hi, int | float) and lo > hi:
                raise ValueError(f"{low} ({lo:g}) must not exceed {high} ({hi:g})")
        return model

    return model_validator(mode="after")(check)


@functools.cache
def section_model(section: str) -> type[BaseModel]:
    """A pydantic model of a dataclass section: its fields, types, defaults and constraints.

    Fields named in ``SECTION_CONSTRAINTS`` get that rule; every other number gets the generic
    rule of :func:`_generic_rule`, and pairs of fields such as ``canny_low``/``canny_high`` or
    ``min_x``/``max_x`` must be ordered. Numbers must be finite (no NaN, no infinity).
    """
    cls = DATACLASS_SECTIONS[section]
    hints = typing.get_type_hints(cls)
    constraints = SECTION_CONSTRAINTS.get(section, {})
    fields: dict[str, Any] = {}
    for item in dataclasses.fields(cls):
        if item.default is not dataclasses.MISSING:
            default = item.default
        elif item.default_factory is not dataclasses.MISSING:
            default = item.default_factory()
        else:
            default = ...
        rule = constraints.get(item.name)
        if rule is None:
            annotation = _generic_rule(hints[item.name], default)
        elif isinstance(rule, type(Field())):
            annotation = Annotated[hints[item.name], rule]
        else:
            annotation = rule
        fields[item.name] = (annotation, default)
    pairs = _bound_pairs(list(fields))
    validators = {"_ordered_bounds": _check_bound_pairs(pairs)} if pairs else None
    return create_model(
        f"{cls.__name__}Section", __base__=Section, __validators__=validators, **fields
    )


def section_params(config: Config, section: str) -> Any:
    """The dataclass (e.g. ``DetectorParams``) of a config's dataclass section."""
    cls = DATACLASS_SECTIONS[section]
    validated = section_model(section).model_validate(getattr(config, section))
    return cls(**{item.name: getattr(validated, item.name) for item in dataclasses.fields(cls)})


def detector_params(config: Config) -> DetectorParams:
    """The ``DetectorParams`` of a config's ``detector`` section."""
    return section_params(config, "detector")


def plate_params(config: Config) -> PlateParams:
    """The ``PlateParams`` of a config's ``plate`` section."""
    return section_params(config, "plate")


def parse_config(
    data: Any, source: str = "<config>", environ: dict[str, str] | None = None
) -> Config:
    """Validate a config mapping (as read from YAML) and apply environment overrides.

    Raises
    ------
    ConfigError
        With one line per problem: ``source: dotted.key: what was expected``.
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping of sections, got {type(data).__name__}")
    data = dict(data)
    used = apply_env_overrides(data, environ)
    if used:
        source = f"{source} (with {', '.join(used)} from the environment)"
    try:
        config = Config.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(_format(source, exc)) from None
    for section, cls in DATACLASS_SECTIONS.items():
        try:
            section_params(config, section)
        except ValidationError as exc:
            raise ConfigError(_format(source, exc, prefix=section)) from None
        except (ValueError, TypeError) as exc:  # the dataclass's own checks
            message = str(exc).replace(f"{cls.__name__}.", f"{section}.")
            raise ConfigError(f"{source}: {message}") from None
    return config


def _yaml_where(exc: yaml.YAMLError) -> str:
    """`` at line N: problem`` for a YAML error, as far as it is known."""
    mark = getattr(exc, "problem_mark", None)
    where = f" at line {mark.line + 1}" if mark is not None else ""
    problem = getattr(exc, "problem", None)
    return where + (f": {problem}" if problem else "")


def load_config(path: str | Path | None, environ: dict[str, str] | None = None) -> Config:
    """Read and validate a YAML config file; ``None`` gives the defaults (a simulated workcell).

    Raises
    ------
    ConfigError
        If the file is missing, is not YAML, or fails validation.
    """
    if path is None:
        return parse_config({}, "<defaults>", environ)
    path = Path(path)
    try:
        text = read_text_limited(path, what="config file")
    except FileNotFoundError:
        raise ConfigError(f"{path}: config file not found") from None
    except YamlRefused as exc:
        raise ConfigError(str(exc)) from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file ({exc.strerror})") from None
    try:
        data = load_yaml(text, str(path))
    except YamlRefused as exc:
        raise ConfigError(str(exc)) from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML{_yaml_where(exc)}") from None
    return parse_config(data, str(path), environ)
