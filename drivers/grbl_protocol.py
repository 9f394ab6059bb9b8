"""GRBL 1.1 protocol: codes, their meanings, and parsing of the controller's replies.

Pure functions and value types only (no I/O), shared by the driver (:mod:`labauto.drivers.grbl`)
and the simulated gantry (:mod:`labauto.drivers.grbl_sim`).

GRBL 1.1 speaks in lines. Every line the host sends gets exactly one *response* (``ok`` or
``error:N``); everything else the controller prints is a *push message* that may arrive at any
time: ``ALARM:N``, the start-up banner ``Grbl 1.1h ['$' for help]``, ``[MSG:...]`` and other
bracketed feedback, ``$N=value`` setting lines and ``<...>`` real-time status reports (the answer to
the single-byte ``?`` command). The texts of the error and alarm tables are those of the GRBL 1.1
documentation (``doc/csv/error_codes_en_US.csv`` and ``alarm_codes_en_US.csv``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import Enum

__all__ = [
    "ALARM_MEANINGS",
    "CRITICAL_ALARMS",
    "CYCLE_START",
    "ERROR_MEANINGS",
    "FEED_HOLD",
    "KNOWN_STATES",
    "MAX_LINE_LENGTH",
    "SOFT_RESET",
    "STATUS_QUERY",
    "BuildOptions",
    "GrblStatus",
    "Reply",
    "ReplyKind",
    "TravelLimits",
    "alarm_meaning",
    "classify_reply",
    "error_meaning",
    "format_axis_words",
    "machine_space",
    "parse_banner",
    "parse_build_options",
    "parse_status",
    "parse_version_feedback",
    "startup_block",
    "travel_problems",
]

# Real-time commands: single bytes GRBL acts on immediately, outside the line protocol.
STATUS_QUERY = b"?"
FEED_HOLD = b"!"
CYCLE_START = b"~"
SOFT_RESET = b"\x18"

#: GRBL's serial line buffer holds 80 bytes including the terminator.
MAX_LINE_LENGTH = 79

ERROR_MEANINGS: dict[int, str] = {
    1: "G-code words consist of a letter and a value. Letter was not found.",
    2: "Missing the expected G-code word value or numeric value format is not valid.",
    3: "Grbl '$' system command was not recognized or supported.",
    4: "Negative value received for an expected positive value.",
    5: "Homing cycle failure. Homing is not enabled via settings.",
    6: "Minimum step pulse time must be greater than 3usec.",
    7: "An EEPROM read failed. Auto-restoring affected EEPROM to default values.",
    8: "Grbl '$' command cannot be used unless Grbl is IDLE. "
    "Ensures smooth operation during a job.",
    9: "G-code commands are locked out during alarm or jog state.",
    10: "Soft limits cannot be enabled without homing also enabled.",
    11: "Max characters per line exceeded. Received command line was not executed.",
    12: "Grbl '$' setting value cause the step rate to exceed the maximum supported.",
    13: "Safety door detected as opened and door state initiated.",
    14: "Build info or startup line exceeded EEPROM line length limit. Line not stored.",
    15: "Jog target exceeds machine travel. Jog command has been ignored.",
    16: "Jog command has no '=' or contains prohibited g-code.",
    17: "Laser mode requires PWM output.",
    20: "Unsupported or invalid g-code command found in block.",
    21: "More than one g-code command from same modal group found in block.",
    22: "Feed rate has not yet been set or is undefined.",
    23: "G-code command in block requires an integer value.",
    24: "More than one g-code command that requires axis words found in block.",
    25: "Repeated g-code word found in block.",
    26: "No axis words found in block for g-code command or current modal state "
    "which requires them.",
    27: "Line number value is invalid.",
    28: "G-code command is missing a required value word.",
    29: "G59.x work coordinate systems are not supported.",
    30: "G53 only allowed with G0 and G1 motion modes.",
    31: "Axis words found in block when no command or current modal state uses them.",
    32: "G2 and G3 arcs require at least one in-plane axis word.",
    33: "Motion command target is invalid.",
    34: "Arc radius value is invalid.",
    35: "G2 and G3 arcs require at least one in-plane offset word.",
    36: "Unused value words found in block.",
    37: "G43.1 dynamic tool length offset is not assigned to configured tool length axis.",
    38: "Tool number greater than max supported value.",
}

ALARM_MEANINGS: dict[int, str] = {
    1: "Hard limit has been triggered. Machine position is likely lost due to sudden halt. "
    "Re-homing is highly recommended.",
    2: "Soft limit alarm. G-code motion target exceeds machine travel. Machine position "
    "retained. Alarm may be safely unlocked.",
    3: "Reset while in motion. Machine position is likely lost due to sudden halt. "
    "Re-homing is highly recommended.",
    4: "Probe fail. Probe is not in the expected initial state before starting probe cycle "
    "when G38.2 and G38.3 is not triggered and G38.4 and G38.5 is triggered.",
    5: "Probe fail. Probe did not contact the workpiece within the programmed travel for "
    "G38.2 and G38.4.",
    6: "Homing fail. The active homing cycle was reset.",
    7: "Homing fail. Safety door was opened during homing cycle.",
    8: "Homing fail. Pull off travel failed to clear limit switch. Try increasing pull-off "
    "setting or check wiring.",
    9: "Homing fail. Could not find limit switch within search distances. Try increasing max "
    "travel, decreasing pull-off distance, or check wiring.",
    10: "Homing fail. Second dual axis limit switch failed to trigger within configured search "
    "distance after first. Try increasing trigger fail distance or check wiring.",
}

#: Alarms after which GRBL 1.1 ignores everything but a soft reset ("[MSG:Reset to continue]").
CRITICAL_ALARMS = frozenset({1, 2})

#: Machine states of GRBL 1.1 status reports. ``Hold`` and ``Door`` carry a sub-state number.
KNOWN_STATES = frozenset({"Idle", "Run", "Hold", "Jog", "Alarm", "Door", "Check", "Home", "Sleep"})


def error_meaning(code: int) -> str:
    """Return the GRBL 1.1 meaning of ``error:code`` (a placeholder text for unknown codes)."""
    return ERROR_MEANINGS.get(code, f"unknown GRBL error code {code}")


def alarm_meaning(code: int) -> str:
    """Return the GRBL 1.1 meaning of ``ALARM:code`` (a placeholder text for unknown codes)."""
    return ALARM_MEANINGS.get(code, f"unknown GRBL alarm code {code}")


# --------------------------------------------------------------------------------------------
# Travel limits
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TravelLimits:
    """Allowed machine-coordinate range per axis, in millimetres, bounds included.

    The defaults describe a 300 x 200 mm bed with 50 mm of Z travel in the machine space of a
    stock GRBL 1.1 build: every axis homes to its maximum (``$23=0``) and, without the build
    option ``HOMING_FORCE_SET_ORIGIN``, the home corner is the machine origin, so the whole
    travel is negative (``[-$130, 0]`` on X and so on). A build with that option and X/Y homing
    to their minimum (``$23=3``) has X in ``[0, $130]`` instead; see :func:`machine_space`.
    """

    x: tuple[float, float] = (-300.0, 0.0)
    y: tuple[float, float] = (-200.0, 0.0)
    z: tuple[float, float] = (-50.0, 0.0)

    def __post_init__(self) -> None:
        for axis in "xyz":
            low, high = getattr(self, axis)
            if not (math.isfinite(low) and math.isfinite(high)) or low >= high:
                raise ValueError(
                    f"TravelLimits.{axis}: expected finite (min, max) with min < max, "
                    f"got ({low!r}, {high!r})"
                )

    def violation(self, **targets: float | None) -> str | None:
        """Describe the first target outside the limits, or return ``None`` if all are inside.

        Parameters
        ----------
        **targets
            Axis name (``x``, ``y`` or ``z``) to target in mm; ``None`` values are skipped.

        Returns
        -------
        str or None
            E.g. ``"x=310.0 is outside the travel limits [0.0, 300.0] mm"``.
        """
        for axis, value in targets.items():
            if value is None:
                continue
            low, high = getattr(self, axis)
            if not isinstance(value, int | float) or not math.isfinite(value):
                return f"{axis}={value!r} is not a finite number of millimetres"
            if not low <= value <= high:
                return f"{axis}={value} is outside the travel limits [{low}, {high}] mm"
        return None

    def contains(self, x: float, y: float, z: float) -> bool:
        """Return whether the point (x, y, z) lies inside the limits."""
        return self.violation(x=x, y=y, z=z) is None


def format_axis_words(**words: float | None) -> str:
    """Format G-code words with 3 decimals, skipping ``None`` values.

    >>> format_axis_words(X=1, Y=None, Z=-2.5, F=600)
    'X1.000 Z-2.500 F600.000'
    """
    return " ".join(f"{letter}{value:.3f}" for letter, value in words.items() if value is not None)


# --------------------------------------------------------------------------------------------
# Reply classification
# --------------------------------------------------------------------------------------------


class ReplyKind(Enum):
    """What a line from the controller is."""

    OK = "ok"
    ERROR = "error"
    ALARM = "alarm"
    STATUS = "status"
    BANNER = "banner"
    PUSH = "push"  # [MSG:...], [VER:...], [GC:...], ...
    STARTUP = "startup"  # >G21 G90:ok or >G1X5:error:22, the result of a $N start-up block
    SETTING = "setting"  # $N=value
    EMPTY = "empty"
    UNKNOWN = "unknown"


@dataclass(frozen=True)
class Reply:
    """One classified controller line.

    Attributes
    ----------
    kind
        The :class:`ReplyKind`.
    text
        The line without its terminator and surrounding blanks.
    code
        N of ``error:N`` / ``ALARM:N`` and of a start-up block's ``>line:error:N``; ``None``
        otherwise.
    version
        Firmware version from a banner (``"1.1h"``); ``None`` otherwise.
    """

    kind: ReplyKind
    text: str
    code: int | None = None
    version: str | None = None


_STARTUP = re.compile(r"^>(.*):(?:ok|error:(\d+))$")
_BANNER = re.compile(r"^Grbl(?:HAL)?\s+(\S+)\s+\[.*\]\s*$", re.IGNORECASE)
_CODED = re.compile(r"^(error|ALARM):(\d+)$")
_SETTING = re.compile(r"^\$\d+=\S*$")
_VERSION_FEEDBACK = re.compile(r"^\[VER:([^:\]]*)")


def parse_banner(line: str) -> str | None:
    """Return the firmware version of a start-up banner (``"1.1h"``), or ``None`` if not one.

    GRBL prints ``Grbl 1.1h ['$' for help]`` after power-up and every soft reset; grblHAL prints
    ``GrblHAL 1.1f ['$' or '$HELP' for help]``.
    """
    match = _BANNER.match(line.strip())
    return match.group(1) if match else None


def parse_version_feedback(line: str) -> str | None:
    """Return the version of a ``$I`` build-info line ``[VER:1.1h.20190830:]`` as ``"1.1h"``.

    The build date after the last dot is dropped; ``None`` if the line is not a ``[VER:`` line.
    """
    match = _VERSION_FEEDBACK.match(line.strip())
    if not match:
        return None
    version = match.group(1)
    head, _, tail = version.rpartition(".")
    return head if head and tail.isdigit() and len(tail) == 8 else version


def classify_reply(line: str) -> Reply:
    """Classify one line received from a GRBL 1.1 controller.

    Parameters
    ----------
    line
        The line, with or without its ``\\r\\n`` terminator.

    Returns
    -------
    Reply
        Anything that fits no GRBL 1.1 line form (noise, a different protocol) is
        :attr:`ReplyKind.UNKNOWN`; the caller decides whether that is an error.
    """
    text = line.strip()
    if not text:
        return Reply(ReplyKind.EMPTY, text)
    if text == "ok":
        return Reply(ReplyKind.OK, text)
    coded = _CODED.match(text)
    if coded:
        kind = ReplyKind.ERROR if coded.group(1) == "error" else ReplyKind.ALARM
        return Reply(kind, text, code=int(coded.group(2)))
    if text.startswith("<") and text.endswith(">"):
        return Reply(ReplyKind.STATUS, text)
    startup = _STARTUP.match(text)
    if startup:
        code = startup.group(2)
        return Reply(ReplyKind.STARTUP, text, code=int(code) if code is not None else None)
    if text.startswith("[") and text.endswith("]"):
        return Reply(ReplyKind.PUSH, text)
    if _SETTING.match(text):
        return Reply(ReplyKind.SETTING, text)
    version = parse_banner(text)
    if version is not None:
        return Reply(ReplyKind.BANNER, text, version=version)
    return Reply(ReplyKind.UNKNOWN, text)


# --------------------------------------------------------------------------------------------
# Status reports
# --------------------------------------------------------------------------------------------

Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class GrblStatus:
    """A parsed GRBL 1.1 real-time status report ``<State|MPos:...|FS:...|...>``.

    Attributes
    ----------
    state
        Machine state name: one of :data:`KNOWN_STATES` for GRBL 1.1 (other names, e.g.
        grblHAL's ``Tool``, are kept as sent).
    substate
        The number after ``Hold:``/``Door:`` (``Hold:0`` = hold complete, ready to resume;
        ``Hold:1`` = hold in progress); ``None`` when absent.
    machine_position, work_position
        ``MPos`` / ``WPos`` in mm; GRBL sends one of them (``$10``), the other is ``None``.
    work_offset
        ``WCO`` (sent every 10-30 reports, or ``None``).
    feed, spindle
        Current feed rate (mm/min) and spindle speed from ``FS:`` (or ``F:``; spindle ``None``).
    planner_blocks_free, rx_bytes_free
        ``Bf:`` buffer state, when enabled.
    line_number
        ``Ln:``, when enabled.
    pins
        ``Pn:`` letters of triggered input pins (``""`` when none).
    overrides
        ``Ov:`` feed, rapid and spindle override percentages.
    accessories
        ``A:`` letters of active outputs (``S``/``C`` spindle, ``F`` flood, ``M`` mist); ``""``
        when none are on *or* the report did not include them (GRBL sends ``A:`` only with
        ``Ov:``).
    extra
        Any other ``name:value`` field, as text.
    raw
        The report as received.
    """

    state: str
    substate: int | None = None
    machine_position: Vector3 | None = None
    work_position: Vector3 | None = None
    work_offset: Vector3 | None = None
    feed: float | None = None
    spindle: float | None = None
    planner_blocks_free: int | None = None
    rx_bytes_free: int | None = None
    line_number: int | None = None
    pins: str = ""
    overrides: tuple[int, int, int] | None = None
    accessories: str = ""
    extra: tuple[tuple[str, str], ...] = ()
    raw: str = ""

    @property
    def position(self) -> Vector3 | None:
        """Machine position: ``MPos``, or ``WPos + WCO`` when only ``WPos`` was sent and ``WCO``
        is known (``None`` otherwise)."""
        if self.machine_position is not None:
            return self.machine_position
        if self.work_position is not None and self.work_offset is not None:
            return tuple(  # type: ignore[return-value]
                w + o for w, o in zip(self.work_position, self.work_offset, strict=True)
            )
        return None

    @property
    def is_idle(self) -> bool:
        """True in state ``Idle``."""
        return self.state == "Idle"

    @property
    def is_alarm(self) -> bool:
        """True in state ``Alarm``."""
        return self.state == "Alarm"

    @property
    def is_moving(self) -> bool:
        """True while axes may move on their own: ``Run``, ``Jog``, ``Home``, or ``Hold:1``."""
        return self.state in ("Run", "Jog", "Home") or (self.state == "Hold" and self.substate == 1)


def _numbers(field: str, text: str, count: int | None, kind: type = float) -> tuple:
    parts = text.split(",")
    if count is not None and len(parts) != count:
        raise ValueError(f"status field {field}: expected {count} values, got {text!r}")
    try:
        return tuple(kind(part) for part in parts)
    except ValueError:
        raise ValueError(f"status field {field}: not a number list: {text!r}") from None


_STATE = re.compile(r"^([A-Za-z]+)(?::(\d+))?$")


def parse_status(line: str) -> GrblStatus:
    """Parse a GRBL 1.1 status report.

    Parameters
    ----------
    line
        E.g. ``<Hold:0|MPos:10.000,20.000,-1.000|FS:0,0|WCO:0.000,0.000,0.000>``.

    Returns
    -------
    GrblStatus

    Raises
    ------
    ValueError
        If the line is not a ``<...>`` report, the state field is malformed, or a known numeric
        field (``MPos``, ``WPos``, ``WCO``, ``FS``, ``F``, ``Bf``, ``Ln``, ``Ov``) does not hold the
        expected numbers. Unknown fields are kept in :attr:`GrblStatus.extra`.
    """
    text = line.strip()
    if not (text.startswith("<") and text.endswith(">")) or len(text) < 3:
        raise ValueError(f"not a GRBL status report: {line!r}")
    state_field, *fields = text[1:-1].split("|")
    state_match = _STATE.match(state_field)
    if not state_match:
        raise ValueError(f"status report has a malformed state {state_field!r}: {line!r}")
    values: dict[str, object] = {
        "state": state_match.group(1),
        "substate": int(state_match.group(2)) if state_match.group(2) is not None else None,
        "raw": text,
    }
    extra: list[tuple[str, str]] = []
    for field in fields:
        name, sep, body = field.partition(":")
        if not sep:
            raise ValueError(f"status field {field!r} has no ':' in {line!r}")
        match name:
            case "MPos":
                values["machine_position"] = _numbers(name, body, 3)
            case "WPos":
                values["work_position"] = _numbers(name, body, 3)
            case "WCO":
                values["work_offset"] = _numbers(name, body, 3)
            case "FS":
                values["feed"], values["spindle"] = _numbers(name, body, 2)
            case "F":
                (values["feed"],) = _numbers(name, body, 1)
            case "Bf":
                values["planner_blocks_free"], values["rx_bytes_free"] = _numbers(
                    name, body, 2, int
                )
            case "Ln":
                (values["line_number"],) = _numbers(name, body, 1, int)
            case "Ov":
                values["overrides"] = _numbers(name, body, 3, int)
            case "Pn":
                values["pins"] = body
            case "A":
                values["accessories"] = body
            case _:
                extra.append((name, body))
    values["extra"] = tuple(extra)
    return GrblStatus(**values)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------
# Build options and machine space
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BuildOptions:
    """The ``[OPT:...]`` line of ``$I``: compile-time options of the firmware.

    Attributes
    ----------
    codes
        The option letters (``"VZ"``...; see GRBL's ``build_option_codes_en_US.csv``).
    planner_blocks, rx_buffer
        Planner buffer blocks and serial receive buffer bytes (``None`` if not sent).
    """

    codes: str = ""
    planner_blocks: int | None = None
    rx_buffer: int | None = None

    @property
    def homing_force_origin(self) -> bool:
        """Built with ``HOMING_FORCE_SET_ORIGIN`` (code ``Z``): homing sets the origin there."""
        return "Z" in self.codes


def parse_build_options(line: str) -> BuildOptions | None:
    """Parse ``[OPT:VZ,15,128]``; ``None`` if the line is not an ``[OPT:`` line."""
    text = line.strip()
    if not (text.startswith("[OPT:") and text.endswith("]")):
        return None
    codes, *numbers = text[5:-1].split(",")
    counts = [int(n) if n.isdigit() else None for n in numbers[:2]] + [None, None]
    return BuildOptions(codes, counts[0], counts[1])


def startup_block(line: str) -> tuple[str, int | None] | None:
    """Split a start-up block result ``>G1X5:error:22`` into ``("G1X5", 22)``.

    ``>G21:ok`` gives ``("G21", None)``; a line that is not such a result gives ``None``.
    """
    match = _STARTUP.match(line.strip())
    if not match:
        return None
    return match.group(1), int(match.group(2)) if match.group(2) is not None else None


Range = tuple[float, float]


def machine_space(settings: dict[int, str], options: BuildOptions) -> dict[str, Range] | None:
    """The machine-coordinate range each axis can reach, as the firmware's soft limits see it.

    GRBL 1.1 (``limits.c``, ``system_check_travel_limits``): without ``HOMING_FORCE_SET_ORIGIN``
    an axis spans ``[-$13N, 0]`` whatever ``$23`` says (homing to the maximum, the default, puts
    the switch at 0). With the option, an axis whose ``$23`` bit is set (homing to the minimum)
    spans ``[0, $13N]`` and the others ``[-$13N, 0]``.

    Returns
    -------
    dict or None
        ``{"x": (low, high), "y": ..., "z": ...}``; ``None`` when ``$130``-``$132`` are missing
        or not numbers.
    """
    try:
        travel = [abs(float(settings[130 + i])) for i in range(3)]
        direction_mask = int(float(settings.get(23, "0")))
    except (KeyError, ValueError):
        return None
    space: dict[str, Range] = {}
    for i, axis in enumerate("xyz"):
        to_minimum = options.homing_force_origin and direction_mask & (1 << i)
        space[axis] = (0.0, travel[i]) if to_minimum else (-travel[i], 0.0)
    return space


def travel_problems(
    limits: TravelLimits, settings: dict[int, str], options: BuildOptions
) -> list[str]:
    """Say, axis by axis, where configured ``limits`` leave the firmware's machine space.

    Returns an empty list when everything fits (or the settings are incomplete), else one
    sentence per axis naming the configured range, the firmware's range and why it is so.
    """
    space = machine_space(settings, options)
    if space is None:
        return []
    layout = (
        "built with HOMING_FORCE_SET_ORIGIN"
        if options.homing_force_origin
        else "no HOMING_FORCE_SET_ORIGIN: the home corner is 0 and the travel is negative"
    )
    problems = []
    for i, axis in enumerate("xyz"):
        low, high = getattr(limits, axis)
        space_low, space_high = space[axis]
        if low < space_low - 1e-6 or high > space_high + 1e-6:
            problems.append(
                f"{axis} limits [{low:g}, {high:g}] mm leave the controller's travel "
                f"[{space_low:g}, {space_high:g}] mm (${130 + i}={settings[130 + i]}, "
                f"$23={settings.get(23, '0')}, {layout})"
            )
    return problems
