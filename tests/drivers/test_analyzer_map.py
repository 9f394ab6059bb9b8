"""Register map: loading, validation errors (file + key path), value codecs, read grouping."""

from __future__ import annotations

import copy
import struct
from pathlib import Path
from typing import Any

import pytest
from analyzer_fixtures import default_map_data, write_map

from labauto.drivers.analyzer_map import (
    DEFAULT_MAP_PATH,
    MapError,
    RegisterField,
    decode_spans,
    decode_value,
    encode_value,
    load_map,
    parse_map,
    read_spans,
)

pytestmark = pytest.mark.timeout(10)


def test_default_map_loads_with_documented_layout() -> None:
    m = load_map()
    assert m.source == str(DEFAULT_MAP_PATH)
    assert (m.unit_id, m.word_order, m.poll_interval_s) == (1, "big", 0.05)
    assert m.command.code("load") == 1 and m.command.code("reset") == 4
    assert m.state.name_of(2) == "done" and m.state.name_of(99) is None
    assert m.sample_id.type == "string" and m.sample_id.registers == 8
    assert [f.name for f in m.results] == ["od600", "ph", "cell_count", "temperature_c"]
    assert m.results[3].scale == pytest.approx(0.1)
    assert {f.table for f in m.results} == {"input"}


def _set(data: dict[str, Any], path: str, value: Any) -> None:
    """Set ``a.b[2].c`` in nested data; value ``DELETE`` removes the key."""
    keys: list[Any] = []
    for part in path.split("."):
        name, _, index = part.partition("[")
        keys.append(name)
        if index:
            keys.append(int(index.rstrip("]")))
    node = data
    for key in keys[:-1]:
        node = node[key]
    if value is DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value


DELETE = object()

BAD_MAPS = [
    # (what is changed, new value, text the error must contain)
    ("colour", "blue", "colour: unknown key"),
    ("results[0].scal", 2.0, "results[0].scal: unknown key"),
    ("results[1].type", "float64", "results[1].type: must be one of"),
    ("results[1].address", 11, "registers overlap: results[1] (input 11-12) and results[0]"),
    ("identification[1].address", 107, "identification[1]: registers overlap"),
    ("word_order", "middle", "word_order: must be one of big, little"),
    ("word_order", DELETE, "word_order: missing required key"),
    ("results[2].word_order", "sideways", "results[2].word_order: must be one of big, little"),
    ("results[3].word_order", "little", "results[3].word_order: applies only to 32-bit types"),
    ("results[0].registers", 4, "results[0].registers: only for strings"),
    ("sample_id.registers", DELETE, "sample_id.registers: missing required key"),
    ("sample_id.table", "input", "sample_id.table: must be holding"),
    ("command.table", "input", "command.table: must be holding"),
    ("state.codes.error", DELETE, "state.codes: missing code(s) error"),
    ("state.codes.done", 1, "state.codes.done: code 1 is already used by 'busy'"),
    ("command.codes.start", "two", "command.codes.start: codes must be integers"),
    ("device.unit_id", 300, "device.unit_id: must be in 1..247, got 300"),
    ("device.unit_id", 0, "device.unit_id: must be in 1..247, got 0"),
    ("device.unit_id", True, "device.unit_id: must be an integer"),
    ("timing.poll_interval_s", 0, "timing.poll_interval_s: must be > 0"),
    ("results[0].scale", 0, "results[0].scale: must not be 0"),
    ("results[2].name", "od600", "results[2].name: duplicate name 'od600'"),
    ("results[2].name", "cells/mL", "results[2].name: must be an identifier"),
    ("results", [], "results: must be a non-empty list"),
    ("error_code.type", "string", "error_code.type: must be one of uint16"),
    ("results[0].address", 65535, "results[0].address: 65535 + 2 registers runs past 65535"),
    ("state", "input 0", "state: must be a mapping"),
]


@pytest.mark.parametrize(("key_path", "value", "expected"), BAD_MAPS, ids=[b[2] for b in BAD_MAPS])
def test_bad_map_names_file_and_key_path(
    tmp_path: Path, key_path: str, value: Any, expected: str
) -> None:
    data = copy.deepcopy(default_map_data())
    _set(data, key_path, value)
    path = write_map(tmp_path, data, "instrument.yaml")
    with pytest.raises(MapError) as info:
        load_map(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), message
    assert expected in message, message


def test_unchanged_copy_of_default_map_is_valid(tmp_path: Path) -> None:
    """The mutation helper itself does not break a map: the control for BAD_MAPS."""
    path = write_map(tmp_path, copy.deepcopy(default_map_data()))
    assert load_map(path).results == load_map().results


def test_state_may_list_several_codes() -> None:
    data = default_map_data()
    data["state"]["codes"]["busy"] = [1, 5, 6]
    m = parse_map(data, "several.yaml")
    assert [m.state.name_of(c) for c in (1, 5, 6, 2)] == ["busy", "busy", "busy", "done"]
    assert m.state.code("busy") == 1


def test_same_address_in_holding_and_input_tables_is_not_an_overlap() -> None:
    m = load_map()  # command is holding 0 and state is input 0 in the default map
    assert (m.command.field.table, m.command.field.address) == ("holding", 0)
    assert (m.state.field.table, m.state.field.address) == ("input", 0)


def test_file_errors_name_the_file(tmp_path: Path) -> None:
    missing = tmp_path / "nope.yaml"
    with pytest.raises(MapError, match=r"nope\.yaml: cannot read"):
        load_map(missing)
    broken = tmp_path / "broken.yaml"
    broken.write_text("device: {unit_id: 1\n", encoding="utf-8")
    with pytest.raises(MapError, match=r"broken\.yaml: not valid YAML"):
        load_map(broken)
    empty = tmp_path / "empty.yaml"
    empty.write_text("", encoding="utf-8")
    with pytest.raises(MapError, match=r"empty\.yaml: top level: must be a mapping"):
        load_map(empty)


# -- codecs, against values worked out by hand ---------------------------------------------------
def _f(type_name: str, word_order: str = "big", scale: float = 1.0, registers: int = 0):
    width = registers or (2 if type_name in ("uint32", "int32", "float32") else 1)
    return RegisterField("x", 0, type_name, "input", width, scale, word_order)


@pytest.mark.parametrize(
    ("field", "value", "registers"),
    [
        (_f("float32", "big"), 1.5, [0x3FC0, 0x0000]),  # 1.5 = 0x3FC00000
        (_f("float32", "little"), 1.5, [0x0000, 0x3FC0]),
        (_f("float32", "big"), -2.0, [0xC000, 0x0000]),
        (_f("uint32", "big"), 0x12345678, [0x1234, 0x5678]),
        (_f("uint32", "little"), 0x12345678, [0x5678, 0x1234]),
        (_f("int32", "big"), -2, [0xFFFF, 0xFFFE]),
        (_f("int32", "little"), -2, [0xFFFE, 0xFFFF]),
        (_f("uint16"), 65535, [0xFFFF]),
        (_f("int16"), -1, [0xFFFF]),
        (_f("int16", scale=0.1), -12.3, [0x10000 - 123]),
        (_f("uint16", scale=0.01), 7.25, [725]),
        (_f("string", registers=3), "AB", [0x4142, 0x0000, 0x0000]),
        (_f("string", registers=2), "S-01", [0x532D, 0x3031]),
    ],
)
def test_encode_and_decode_match_hand_packed_registers(
    field: RegisterField, value: Any, registers: list[int]
) -> None:
    assert encode_value(field, value) == registers
    decoded = decode_value(field, registers)
    assert decoded == pytest.approx(value) if not isinstance(value, str) else decoded == value


def test_float32_word_order_swaps_words_of_the_ieee_pattern() -> None:
    value = 2.2074594497680664  # a float32 value
    high, low = struct.unpack(">HH", struct.pack(">f", value))
    assert encode_value(_f("float32", "big"), value) == [high, low]
    assert encode_value(_f("float32", "little"), value) == [low, high]
    # Reading with the wrong word order gives a different number: the order matters.
    assert decode_value(_f("float32", "little"), [high, low]) != pytest.approx(value)


def test_integers_with_unit_scale_stay_integers_and_strings_drop_padding() -> None:
    assert isinstance(decode_value(_f("uint32"), [0, 7]), int)
    assert isinstance(decode_value(_f("int16", scale=0.5), [3]), float)
    assert decode_value(_f("string", registers=3), [0x4142, 0x2000, 0]) == "AB"


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        (_f("string", registers=2), "S-0001", "has 6 characters; the map allows 4"),
        (_f("string", registers=2), "Ä1", "is not plain ASCII"),
        (_f("string", registers=2), 12, "expected a string"),
        (_f("uint16"), 70000, "does not fit in uint16"),
        (_f("int16"), -40000, "does not fit in int16"),
        (_f("uint32"), -1, "does not fit in uint32"),
        (_f("uint16"), "7", "expected a number"),
        (_f("uint16"), True, "expected a number"),
    ],
)
def test_values_that_do_not_fit_are_refused(field: RegisterField, value: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        encode_value(field, value)


def test_read_spans_merge_touching_fields_but_never_read_gaps() -> None:
    a = RegisterField("a", 10, "float32", "input", 2)
    b = RegisterField("b", 12, "uint16", "input", 1)
    c = RegisterField("c", 20, "uint16", "input", 1)  # gap 13..19
    d = RegisterField("d", 13, "uint16", "holding", 1)  # other table
    spans = read_spans([c, b, a, d])
    assert [(s.table, s.address, s.count, [f.name for f in s.fields]) for s in spans] == [
        ("holding", 13, 1, ["d"]),
        ("input", 10, 3, ["a", "b"]),
        ("input", 20, 1, ["c"]),
    ]
    values = decode_spans(spans, [[5], [0x3FC0, 0, 9], [11]])
    assert values == {"d": 5, "a": 1.5, "b": 9, "c": 11}


def test_read_spans_respect_the_modbus_register_limit() -> None:
    fields = [RegisterField(f"s{i}", i * 60, "string", "input", 60) for i in range(3)]
    spans = read_spans(fields)
    assert [s.count for s in spans] == [120, 60]
