"""Pure tests of the GRBL 1.1 protocol helpers: reply classification, status reports, tables."""

from __future__ import annotations

import math

import pytest

from labauto.drivers.grbl_protocol import (
    ALARM_MEANINGS,
    ERROR_MEANINGS,
    KNOWN_STATES,
    BuildOptions,
    ReplyKind,
    TravelLimits,
    alarm_meaning,
    classify_reply,
    error_meaning,
    format_axis_words,
    machine_space,
    parse_banner,
    parse_build_options,
    parse_status,
    parse_version_feedback,
    startup_block,
    travel_problems,
)

# --------------------------------------------------------------------------- status reports


@pytest.mark.parametrize(
    ("report", "state", "substate"),
    [
        ("<Idle|MPos:0.000,0.000,0.000|FS:0,0>", "Idle", None),
        ("<Run|MPos:12.500,3.000,-1.000|FS:1500,0>", "Run", None),
        ("<Hold:0|MPos:1.000,2.000,3.000|FS:0,0>", "Hold", 0),
        ("<Hold:1|MPos:1.000,2.000,3.000|FS:230,0>", "Hold", 1),
        ("<Jog|MPos:5.000,0.000,0.000|FS:500,0>", "Jog", None),
        ("<Alarm|MPos:0.000,0.000,0.000|FS:0,0>", "Alarm", None),
        ("<Door:0|MPos:0.000,0.000,0.000|FS:0,0>", "Door", 0),
        ("<Door:1|MPos:0.000,0.000,0.000|FS:0,0>", "Door", 1),
        ("<Door:2|MPos:0.000,0.000,0.000|FS:0,0>", "Door", 2),
        ("<Door:3|MPos:0.000,0.000,0.000|FS:0,0>", "Door", 3),
        ("<Check|MPos:0.000,0.000,0.000|FS:0,0>", "Check", None),
        ("<Home|MPos:-3.210,0.000,0.000|FS:3000,0>", "Home", None),
        ("<Sleep|MPos:0.000,0.000,0.000|FS:0,0>", "Sleep", None),
    ],
)
def test_parse_status_every_state(report: str, state: str, substate: int | None) -> None:
    status = parse_status(report)
    assert status.state == state
    assert status.substate == substate
    assert state in KNOWN_STATES
    assert status.raw == report
    assert status.is_idle == (state == "Idle")
    assert status.is_alarm == (state == "Alarm")
    assert status.is_moving == (state in ("Run", "Jog", "Home") or (state, substate) == ("Hold", 1))


def test_parse_status_fields() -> None:
    status = parse_status(
        "<Run|MPos:10.125,-2.500,-30.000|Bf:15,128|Ln:99|FS:1500.5,8000|Pn:XZP"
        "|WCO:1.000,2.000,3.000|Ov:120,50,100|A:SFM|Foo:bar>"
    )
    assert status.machine_position == (10.125, -2.5, -30.0)
    assert status.position == (10.125, -2.5, -30.0)
    assert (status.planner_blocks_free, status.rx_bytes_free) == (15, 128)
    assert status.line_number == 99
    assert (status.feed, status.spindle) == (1500.5, 8000.0)
    assert status.pins == "XZP"
    assert status.work_offset == (1.0, 2.0, 3.0)
    assert status.overrides == (120, 50, 100)
    assert status.accessories == "SFM"
    assert status.extra == (("Foo", "bar"),)


def test_parse_status_work_position_plus_offset_gives_machine_position() -> None:
    status = parse_status("<Idle|WPos:1.000,2.000,-3.000|F:0|WCO:10.000,20.000,-1.000>")
    assert status.machine_position is None
    assert status.work_position == (1.0, 2.0, -3.0)
    assert status.position == (11.0, 22.0, -4.0)
    assert (status.feed, status.spindle) == (0.0, None)
    # WPos without a known offset: the machine position is unknown, not guessed.
    assert parse_status("<Idle|WPos:1.000,2.000,3.000>").position is None


def test_parse_status_keeps_unknown_state_names() -> None:
    assert parse_status("<Tool|MPos:0.000,0.000,0.000>").state == "Tool"  # grblHAL


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("Idle|MPos:0,0,0", "not a GRBL status report"),
        ("<>", "not a GRBL status report"),
        ("<Hold:x|MPos:0,0,0>", "malformed state"),
        ("<Idle|MPos:1.0,2.0>", "MPos: expected 3 values"),
        ("<Idle|MPos:1.0,abc,2.0>", "MPos: not a number"),
        ("<Idle|FS:1>", "FS: expected 2 values"),
        ("<Idle|Bf:1.5,3>", "Bf: not a number"),
        ("<Idle|MPos>", "has no ':'"),
    ],
)
def test_parse_status_rejects_malformed_reports(line: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        parse_status(line)


# --------------------------------------------------------------------------- reply lines


@pytest.mark.parametrize(
    ("line", "kind", "code"),
    [
        ("ok\r\n", ReplyKind.OK, None),
        ("error:9", ReplyKind.ERROR, 9),
        ("error:38\r\n", ReplyKind.ERROR, 38),
        ("ALARM:1", ReplyKind.ALARM, 1),
        ("ALARM:10", ReplyKind.ALARM, 10),
        ("<Idle|MPos:0.000,0.000,0.000|FS:0,0>", ReplyKind.STATUS, None),
        ("[MSG:'$H'|'$X' to unlock]", ReplyKind.PUSH, None),
        ("[MSG:Reset to continue]", ReplyKind.PUSH, None),
        (">G1X5:error:22", ReplyKind.STARTUP, 22),
        ("[VER:1.1h.20190830:]", ReplyKind.PUSH, None),
        ("[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]", ReplyKind.PUSH, None),
        (">G54:ok", ReplyKind.STARTUP, None),
        ("$130=300.000", ReplyKind.SETTING, None),
        ("", ReplyKind.EMPTY, None),
        ("\r\n", ReplyKind.EMPTY, None),
        ("Grbl 1.1h ['$' for help]", ReplyKind.BANNER, None),
        ("o\ufffdk#", ReplyKind.UNKNOWN, None),
        ("OK", ReplyKind.UNKNOWN, None),
        ("error:", ReplyKind.UNKNOWN, None),
        ("ALARM:x", ReplyKind.UNKNOWN, None),
    ],
)
def test_classify_reply(line: str, kind: ReplyKind, code: int | None) -> None:
    reply = classify_reply(line)
    assert reply.kind is kind
    assert reply.code == code
    assert reply.text == line.strip()


@pytest.mark.parametrize(
    ("line", "version"),
    [
        ("Grbl 1.1h ['$' for help]", "1.1h"),
        ("Grbl 1.1f ['$' for help]\r\n", "1.1f"),
        ("Grbl 0.9j ['$' for help]", "0.9j"),
        ("GrblHAL 1.1f ['$' or '$HELP' for help]", "1.1f"),
        ("Marlin 2.0", None),
        ("Grbl", None),
    ],
)
def test_parse_banner(line: str, version: str | None) -> None:
    assert parse_banner(line) == version
    if version is not None:
        assert classify_reply(line).version == version


@pytest.mark.parametrize(
    ("line", "version"),
    [
        ("[VER:1.1h.20190830:]", "1.1h"),
        ("[VER:1.1f.20170801:my machine]", "1.1f"),
        ("[VER:1.1h:]", "1.1h"),
        ("[OPT:V,15,128]", None),
    ],
)
def test_parse_version_feedback(line: str, version: str | None) -> None:
    assert parse_version_feedback(line) == version


# --------------------------------------------------------------------------- tables


def test_error_and_alarm_tables_cover_grbl_1_1() -> None:
    assert set(ERROR_MEANINGS) == set(range(1, 18)) | set(range(20, 39))
    assert set(ALARM_MEANINGS) == set(range(1, 11))
    assert "Second dual axis limit switch" in alarm_meaning(10)
    assert "locked out during alarm" in error_meaning(9)
    assert "Feed rate has not yet been set" in error_meaning(22)
    assert "Hard limit" in alarm_meaning(1)
    assert "exceeds machine travel" in alarm_meaning(2)
    assert "Reset while in motion" in alarm_meaning(3)
    assert error_meaning(99) == "unknown GRBL error code 99"
    assert alarm_meaning(42) == "unknown GRBL alarm code 42"


# --------------------------------------------------------------------------- limits, formatting


def test_default_travel_is_the_negative_space_of_a_stock_grbl_build() -> None:
    limits = TravelLimits()
    assert (limits.x, limits.y, limits.z) == ((-300.0, 0.0), (-200.0, 0.0), (-50.0, 0.0))
    assert limits.violation(x=10.0) == "x=10.0 is outside the travel limits [-300.0, 0.0] mm"


def test_travel_limits_violation_names_axis_value_and_range() -> None:
    limits = TravelLimits(x=(0.0, 300.0), y=(0.0, 200.0), z=(-50.0, 0.0))
    assert limits.violation(x=0, y=200, z=-50) is None  # bounds are inside
    assert limits.violation(x=300.0001) == (
        "x=300.0001 is outside the travel limits [0.0, 300.0] mm"
    )
    assert limits.violation(x=10, y=-0.5) == "y=-0.5 is outside the travel limits [0.0, 200.0] mm"
    assert limits.violation(z=0.1) == "z=0.1 is outside the travel limits [-50.0, 0.0] mm"
    assert "not a finite number" in (limits.violation(x=math.nan) or "")
    assert "not a finite number" in (limits.violation(y=math.inf) or "")
    assert "not a finite number" in (limits.violation(z="1") or "")  # type: ignore[arg-type]
    assert limits.violation(x=None, y=None) is None
    assert limits.contains(150, 100, -25)
    assert not limits.contains(150, 100, 1)


@pytest.mark.parametrize("bad", [(10.0, 10.0), (5.0, 1.0), (0.0, math.inf), (math.nan, 1.0)])
def test_travel_limits_reject_bad_ranges(bad: tuple[float, float]) -> None:
    with pytest.raises(ValueError, match=r"TravelLimits\.y"):
        TravelLimits(y=bad)


def test_format_axis_words() -> None:
    assert format_axis_words(X=1, Y=None, Z=-2.5, F=600) == "X1.000 Z-2.500 F600.000"
    assert format_axis_words(X=0.0004) == "X0.000"
    assert format_axis_words() == ""


# --------------------------------------------------------------------------- build options, space

STOCK = {23: "0", 130: "200.000", 131: "150.000", 132: "50.000"}


def test_build_options_and_startup_block_results_are_parsed() -> None:
    options = parse_build_options("[OPT:VZ,15,128]")
    assert options == BuildOptions("VZ", 15, 128) and options.homing_force_origin
    assert not parse_build_options("[OPT:V,15,128]").homing_force_origin  # type: ignore[union-attr]
    assert parse_build_options("[VER:1.1h.20190830:]") is None
    assert startup_block(">G1X5:error:22") == ("G1X5", 22)
    assert startup_block(">G21 G90:ok") == ("G21 G90", None)
    assert startup_block("ok") is None


def test_machine_space_follows_the_sign_convention_of_the_build() -> None:
    assert machine_space(STOCK, BuildOptions("V")) == {
        "x": (-200.0, 0.0), "y": (-150.0, 0.0), "z": (-50.0, 0.0)
    }  # fmt: skip
    # $23 alone changes nothing without HOMING_FORCE_SET_ORIGIN
    assert machine_space({**STOCK, 23: "3"}, BuildOptions("V"))["x"] == (-200.0, 0.0)
    forced = machine_space({**STOCK, 23: "3"}, BuildOptions("VZ"))
    assert forced == {"x": (0.0, 200.0), "y": (0.0, 150.0), "z": (-50.0, 0.0)}
    assert machine_space({23: "0"}, BuildOptions("V")) is None


def test_travel_problems_name_axis_ranges_settings_and_the_reason() -> None:
    fits = TravelLimits(x=(-200.0, 0.0), y=(-100.0, -10.0), z=(-50.0, 0.0))
    assert travel_problems(fits, STOCK, BuildOptions("V")) == []
    positive = TravelLimits(x=(0.0, 300.0), y=(0.0, 200.0), z=(-50.0, 0.0))
    problems = travel_problems(positive, STOCK, BuildOptions("V"))
    assert len(problems) == 2
    assert problems[0] == (
        "x limits [0, 300] mm leave the controller's travel [-200, 0] mm ($130=200.000, $23=0, "
        "no HOMING_FORCE_SET_ORIGIN: the home corner is 0 and the travel is negative)"
    )
    assert problems[1].startswith("y limits [0, 200] mm leave the controller's travel [-150, 0]")
    too_long = travel_problems(positive, {**STOCK, 23: "3"}, BuildOptions("VZ"))
    assert too_long == [
        "x limits [0, 300] mm leave the controller's travel [0, 200] mm ($130=200.000, $23=3, "
        "built with HOMING_FORCE_SET_ORIGIN)",
        "y limits [0, 200] mm leave the controller's travel [0, 150] mm ($131=150.000, $23=3, "
        "built with HOMING_FORCE_SET_ORIGIN)",
    ]
