"""Register map of a Modbus analyzer: load and validate the YAML, encode and decode values.

The map says where the analyzer keeps its command register, sample id, state, error code, result
and identification registers, and how to read them. ``drivers/analyzer_map.yaml`` is the default
(the simulated analyzer); a real instrument gets its own file in the same format. The file's
comments document the format; the choices made here are:

* Addresses are 0-based protocol addresses (what goes on the wire), in one of two tables:
  ``holding`` (read/write, function codes 3/6/16) or ``input`` (read-only, function code 4).
* Types: ``uint16``, ``int16`` (1 register); ``uint32``, ``int32``, ``float32`` (2 registers);
  ``string`` (``registers: N`` registers, 2 ASCII characters each, first character in the high
  byte, padded with NUL bytes; trailing NULs and spaces are dropped when read).
* Bytes inside a register are big-endian (Modbus). ``word_order`` (top level, required, and
  overridable per 32-bit field) says which word of a 32-bit value comes first: ``big`` = most
  significant word at the lower address, ``little`` = least significant first.
* A value read is ``raw * scale``; a value written is ``value / scale`` (rounded for integers).
  Integer fields with scale 1 read as ``int``, everything else as ``float``.
* The sample id is whatever type the map gives it; the default map uses an 8-register string.
* State codes map a state name (``idle``, ``busy``, ``done``, ``error``, all required) to one code
  or a list of codes, so an instrument with several busy codes can be mapped. Command codes need
  ``load``, ``start``, ``abort``, ``reset``; ``none`` and extra commands are allowed.
* How the driver confirms that the analyzer took a command (many instruments act on a command
  only at their next PLC scan, 10-100 ms later): ``command.clears`` (default true) says the
  command register reads 0 once taken; the optional ``confirmation`` section names a
  ``sample_echo`` register (the sample id the analyzer works on, same type as ``sample_id``) and
  a ``result_counter`` (incremented per finished analysis); ``timing.command_timeout_s``
  (default 2) bounds the wait.
* ``device.unit_id`` is a Modbus unit address, 1..247 (0 is broadcast, 248-255 reserved).

Validation rejects unknown keys, missing keys, wrong types, bad codes and overlapping registers
with a :class:`MapError` naming the file and the key path (e.g. ``results[2].type``).
"""

from __future__ import annotations

import itertools
import math
import re
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal, cast

import yaml

DEFAULT_MAP_PATH = Path(__file__).with_name("analyzer_map.yaml")

TableName = Literal["holding", "input"]
TABLES: tuple[TableName, ...] = ("holding", "input")
WORD_ORDERS = ("big", "little")
#: type name -> (struct format of one value, registers per value); string width is per field.
VALUE_TYPES: dict[str, tuple[str, int]] = {
    "uint16": ("H", 1),
    "int16": ("h", 1),
    "uint32": ("I", 2),
    "int32": ("i", 2),
    "float32": ("f", 2),
    "string": ("s", 0),
}
NUMBER_TYPES = tuple(t for t in VALUE_TYPES if t != "string")
STATE_NAMES = ("idle", "busy", "done", "error")
REQUIRED_COMMANDS = ("load", "start", "abort", "reset")
MAX_REGISTERS_PER_READ = 125  # Modbus limit for function codes 3 and 4

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_REQUIRED = object()

Value = int | float | str


class MapError(ValueError):
    """A register map is invalid. The message names the file and the key path."""


@dataclass(frozen=True)
class RegisterField:
    """One value held in one or more consecutive registers.

    ``registers`` is the width in registers (1 or 2 for numbers, N for strings).
    """

    name: str
    address: int
    type: str
    table: TableName = "holding"
    registers: int = 1
    scale: float = 1.0
    word_order: str = "big"
    unit: str = ""

    @property
    def end(self) -> int:
        """One past the last register address."""
        return self.address + self.registers

    def describe(self) -> str:
        """Short text such as ``input 10-11`` for messages."""
        last = self.end - 1
        span = f"{self.address}" if last == self.address else f"{self.address}-{last}"
        return f"{self.table} {span}"


@dataclass(frozen=True)
class CodedRegister:
    """A uint16 register whose values are named codes (the command and the state registers)."""

    field: RegisterField
    codes: Mapping[str, tuple[int, ...]]

    def code(self, name: str) -> int:
        """The (first) code for ``name``; KeyError names the known codes."""
        try:
            return self.codes[name][0]
        except KeyError:
            raise KeyError(f"unknown code name {name!r}; known: {', '.join(self.codes)}") from None

    def name_of(self, code: int) -> str | None:
        """The name of ``code``, or None if the map does not know it."""
        for name, values in self.codes.items():
            if code in values:
                return name
        return None


@dataclass(frozen=True)
class AnalyzerMap:
    """A validated register map (see the module docstring for the format)."""

    source: str
    unit_id: int
    model: str
    word_order: str
    poll_interval_s: float
    command: CodedRegister
    sample_id: RegisterField
    state: CodedRegister
    error_code: RegisterField
    results: tuple[RegisterField, ...]
    identification: tuple[RegisterField, ...] = field(default=())
    #: The register where the analyzer shows the sample id it works on (optional).
    sample_echo: RegisterField | None = None
    #: A number the analyzer increments with each finished analysis (optional).
    result_counter: RegisterField | None = None
    #: Whether the command register reads 0 again once the analyzer took the command.
    command_clears: bool = True
    #: Seconds the analyzer may take to show it took a command (a PLC scans every 10-100 ms).
    command_timeout_s: float = 2.0

    def fields(self) -> tuple[RegisterField, ...]:
        """Every register field of the map."""
        confirmation = tuple(f for f in (self.sample_echo, self.result_counter) if f is not None)
        return (
            self.command.field,
            self.sample_id,
            self.state.field,
            self.error_code,
            *self.results,
            *self.identification,
            *confirmation,
        )


# -- loading ----------------------------------------------------------------------------------
def load_map(path: str | Path | None = None) -> AnalyzerMap:
    """Load and validate a register map YAML file.

    Parameters
    ----------
    path : str or Path, optional
        The YAML file; the default map (``drivers/analyzer_map.yaml``) when omitted.

    Returns
    -------
    AnalyzerMap

    Raises
    ------
    MapError
        The file is missing, not YAML, or not a valid map (the message names file and key path).
    """
    path = Path(path) if path is not None else DEFAULT_MAP_PATH
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MapError(f"{path}: cannot read the register map: {exc.strerror or exc}") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise MapError(f"{path}: not valid YAML: {exc}") from exc
    return parse_map(data, source=str(path))


def parse_map(data: Any, source: str = "<map>") -> AnalyzerMap:
    """Validate a register map given as plain data (what ``yaml.safe_load`` returns).

    Parameters
    ----------
    data : mapping
        The map's top-level mapping.
    source : str
        Name used in error messages (normally the file path).

    Raises
    ------
    MapError
        With the source and the key path of the first problem found.
    """
    top = _Section(data, "", source)
    device = top.section("device")
    unit_id = device.integer("unit_id", 1, 247)
    model = device.text("model", default="")
    device.finish()

    word_order = top.choice("word_order", WORD_ORDERS)
    timing = top.section("timing")
    poll_interval_s = timing.number("poll_interval_s", positive=True)
    command_timeout_s = timing.number("command_timeout_s", default=2.0, positive=True)
    timing.finish()

    command_node = top.section("command")
    command_clears = command_node.get("clears", True)
    if not isinstance(command_clears, bool):
        command_node.fail("clears", f"must be true or false, got {_kind(command_clears)}")
    command = _coded_register(command_node, "holding", REQUIRED_COMMANDS, "command")
    sample_id = _field(top.section("sample_id"), "sample_id", word_order, fixed_table="holding")
    state = _coded_register(top.section("state"), None, STATE_NAMES, "state")
    error_code = _field(top.section("error_code"), "error_code", word_order, numbers_only=True)
    results = _field_list(top, "results", word_order, required=True)
    identification = _field_list(top, "identification", word_order, required=False)
    sample_echo = result_counter = None
    if "confirmation" in top.data:
        confirm = top.section("confirmation")
        if "sample_echo" in confirm.data:
            sample_echo = _field(confirm.section("sample_echo"), "sample_echo", word_order)
            if sample_echo.type != sample_id.type:
                confirm.fail("sample_echo", f"must have the sample id's type {sample_id.type}")
        if "result_counter" in confirm.data:
            result_counter = _field(
                confirm.section("result_counter"), "result_counter", word_order, numbers_only=True
            )
        confirm.finish()
    top.finish()

    named = [
        ("command", command.field),
        ("sample_id", sample_id),
        ("state", state.field),
        ("error_code", error_code),
        *((f"results[{i}]", f) for i, f in enumerate(results)),
        *((f"identification[{i}]", f) for i, f in enumerate(identification)),
        *((f"confirmation.{f.name}", f) for f in (sample_echo, result_counter) if f is not None),
    ]
    _check_overlaps(named, source)
    _check_unique_names(results, "results", source)
    _check_unique_names(identification, "identification", source)
    return AnalyzerMap(
        source=source,
        unit_id=unit_id,
        model=model,
        word_order=word_order,
        poll_interval_s=poll_interval_s,
        command=command,
        sample_id=sample_id,
        state=state,
        error_code=error_code,
        results=tuple(results),
        identification=tuple(identification),
        sample_echo=sample_echo,
        result_counter=result_counter,
        command_clears=command_clears,
        command_timeout_s=command_timeout_s,
    )


class _Section:
    """A mapping being validated: remembers its key path and which keys were used."""

    def __init__(self, data: Any, path: str, source: str) -> None:
        self.path, self.source = path, source
        if not isinstance(data, Mapping):
            self.fail("", f"must be a mapping, got {_kind(data)}")
        self.data: Mapping[str, Any] = data
        self.used: set[str] = set()

    def where(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path and key else (key or self.path or "top level")

    def fail(self, key: str, message: str) -> None:
        raise MapError(f"{self.source}: {self.where(key)}: {message}")

    def get(self, key: str, default: Any = _REQUIRED) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is _REQUIRED:
                self.fail(key, "missing required key")
            return default
        return self.data[key]

    def section(self, key: str) -> _Section:
        return _Section(self.get(key), self.where(key), self.source)

    def integer(self, key: str, low: int, high: int, default: Any = _REQUIRED) -> int:
        value = self.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(key, f"must be an integer, got {_kind(value)}")
        if not low <= value <= high:
            self.fail(key, f"must be in {low}..{high}, got {value}")
        return value

    def number(self, key: str, default: Any = _REQUIRED, positive: bool = False) -> float:
        value = self.get(key, default)
        is_number = isinstance(value, int | float) and not isinstance(value, bool)
        if not is_number or not math.isfinite(value):
            self.fail(key, f"must be a finite number, got {_kind(value)}")
        if positive and value <= 0:
            self.fail(key, f"must be > 0, got {value}")
        return float(value)

    def text(self, key: str, default: Any = _REQUIRED) -> str:
        value = self.get(key, default)
        if not isinstance(value, str):
            self.fail(key, f"must be a string, got {_kind(value)}")
        return value

    def choice(self, key: str, choices: Sequence[str], default: Any = _REQUIRED) -> str:
        value = self.get(key, default)
        if value not in choices:
            self.fail(key, f"must be one of {', '.join(choices)}; got {value!r}")
        return value

    def finish(self) -> None:
        unknown = [str(k) for k in self.data if k not in self.used]
        if unknown:
            allowed = ", ".join(sorted(self.used))
            self.fail(unknown[0], f"unknown key (allowed here: {allowed})")


def _field(
    node: _Section,
    name: str,
    default_word_order: str,
    *,
    fixed_table: str | None = None,
    numbers_only: bool = False,
) -> RegisterField:
    """Parse a field mapping: address, table, type, registers, scale, word_order, unit."""
    address = node.integer("address", 0, 65535)
    table = cast(TableName, node.choice("table", TABLES, default=fixed_table or "holding"))
    if fixed_table and table != fixed_table:
        node.fail("table", f"must be {fixed_table} (the driver writes this register)")
    allowed_types = NUMBER_TYPES if numbers_only else tuple(VALUE_TYPES)
    type_name = node.choice("type", allowed_types)
    if type_name == "string":
        registers = node.integer("registers", 1, MAX_REGISTERS_PER_READ)
        if "scale" in node.data:
            node.fail("scale", "does not apply to a string")
    else:
        if "registers" in node.data:
            node.fail("registers", f"only for strings; {type_name} has a fixed width")
        registers = VALUE_TYPES[type_name][1]
    scale = 1.0 if type_name == "string" else node.number("scale", default=1.0)
    if scale == 0:
        node.fail("scale", "must not be 0")
    word_order = default_word_order
    if "word_order" in node.data:
        if registers != 2 or type_name == "string":
            node.fail("word_order", f"applies only to 32-bit types, not {type_name}")
        word_order = node.choice("word_order", WORD_ORDERS)
    unit = node.text("unit", default="")
    if address + registers > 65536:
        node.fail("address", f"{address} + {registers} registers runs past 65535")
    node.finish()
    return RegisterField(name, address, type_name, table, registers, scale, word_order, unit)


def _coded_register(
    node: _Section, fixed_table: str | None, required: Sequence[str], name: str
) -> CodedRegister:
    """Parse a uint16 register with named codes (command or state)."""
    address = node.integer("address", 0, 65535)
    table = cast(TableName, node.choice("table", TABLES, default=fixed_table or "holding"))
    if fixed_table and table != fixed_table:
        node.fail("table", f"must be {fixed_table} (the driver writes this register)")
    codes_node = node.section("codes")
    codes: dict[str, tuple[int, ...]] = {}
    seen: dict[int, str] = {}
    for code_name in codes_node.data:
        key_path = codes_node.where(str(code_name))
        if not isinstance(code_name, str) or not _NAME.match(code_name):
            codes_node.fail(str(code_name), "code names must be identifiers (letters, digits, _)")
        value = codes_node.get(code_name)
        values = value if isinstance(value, list) and value else [value]
        for code in values:
            if isinstance(code, bool) or not isinstance(code, int) or not 0 <= code <= 65535:
                raise MapError(
                    f"{node.source}: {key_path}: codes must be integers 0..65535 "
                    f"(or a non-empty list of them), got {code!r}"
                )
            if code in seen:
                raise MapError(
                    f"{node.source}: {key_path}: code {code} is already used by {seen[code]!r}"
                )
            seen[code] = code_name
        codes[code_name] = tuple(values)
    missing = [n for n in required if n not in codes]
    if missing:
        codes_node.fail("", f"missing code(s) {', '.join(missing)}")
    node.finish()
    register = RegisterField(name, address, "uint16", table, 1)
    return CodedRegister(register, MappingProxyType(codes))


def _field_list(top: _Section, key: str, word_order: str, *, required: bool) -> list[RegisterField]:
    items = top.get(key, _REQUIRED if required else [])
    if not isinstance(items, list) or (required and not items):
        top.fail(key, f"must be a {'non-empty ' if required else ''}list, got {_kind(items)}")
    fields = []
    for i, item in enumerate(items):
        node = _Section(item, f"{key}[{i}]", top.source)
        name = node.text("name")
        if not _NAME.match(name):
            node.fail("name", f"must be an identifier (letters, digits, _), got {name!r}")
        fields.append(_field(node, name, word_order))
    return fields


def _check_overlaps(named: Iterable[tuple[str, RegisterField]], source: str) -> None:
    for table in TABLES:
        in_table = sorted((f.address, path, f) for path, f in named if f.table == table)
        for (_, path_a, a), (_, path_b, b) in itertools.pairwise(in_table):
            if b.address < a.end:
                raise MapError(
                    f"{source}: {path_b}: registers overlap: {path_b} ({b.describe()}) and "
                    f"{path_a} ({a.describe()})"
                )


def _check_unique_names(fields: Sequence[RegisterField], key: str, source: str) -> None:
    seen: set[str] = set()
    for i, f in enumerate(fields):
        if f.name in seen:
            raise MapError(f"{source}: {key}[{i}].name: duplicate name {f.name!r}")
        seen.add(f.name)


def _kind(value: Any) -> str:
    return f"{type(value).__name__} {value!r}" if value is not None else "nothing"


# -- values <-> registers ---------------------------------------------------------------------
def encode_value(register_field: RegisterField, value: Value) -> list[int]:
    """Registers that hold ``value`` in ``register_field`` (inverse of :func:`decode_value`).

    Raises
    ------
    ValueError
        The value does not fit the field (wrong kind, out of range, string too long or not ASCII).
    """
    f = register_field
    if f.type == "string":
        if not isinstance(value, str):
            raise ValueError(f"{f.name}: expected a string, got {_kind(value)}")
        try:
            raw = value.encode("ascii")
        except UnicodeEncodeError:
            raise ValueError(f"{f.name}: {value!r} is not plain ASCII") from None
        if len(raw) > 2 * f.registers:
            raise ValueError(
                f"{f.name}: {value!r} has {len(raw)} characters; the map allows "
                f"{2 * f.registers} ({f.registers} registers)"
            )
        return _bytes_to_words(raw.ljust(2 * f.registers, b"\0"))
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{f.name}: expected a number, got {_kind(value)}")
    fmt, _ = VALUE_TYPES[f.type]
    raw_value: int | float = value / f.scale if f.scale != 1 else value
    if f.type != "float32" and isinstance(raw_value, float):
        if not math.isfinite(raw_value):
            raise ValueError(f"{f.name}: {value!r} is not finite")
        raw_value = round(raw_value)
    try:
        packed = struct.pack(f">{fmt}", raw_value)
    except (struct.error, OverflowError):
        raise ValueError(f"{f.name}: {value!r} does not fit in {f.type}") from None
    words = _bytes_to_words(packed)
    return words[::-1] if f.word_order == "little" else words


def decode_value(register_field: RegisterField, registers: Sequence[int]) -> Value:
    """The value held in ``registers`` (exactly ``register_field.registers`` of them)."""
    f = register_field
    if len(registers) != f.registers:
        raise ValueError(f"{f.name}: expected {f.registers} registers, got {len(registers)}")
    if f.type == "string":
        raw = _words_to_bytes(registers)
        return raw.decode("ascii", errors="replace").rstrip("\0 ")
    words = list(registers)[::-1] if f.word_order == "little" else list(registers)
    fmt, _ = VALUE_TYPES[f.type]
    (raw_value,) = struct.unpack(f">{fmt}", _words_to_bytes(words))
    if f.scale == 1:
        return raw_value
    return raw_value * f.scale


def _bytes_to_words(data: bytes) -> list[int]:
    return [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]


def _words_to_bytes(words: Iterable[int]) -> bytes:
    return b"".join(int(w).to_bytes(2, "big") for w in words)


# -- reading several fields at once -----------------------------------------------------------
@dataclass(frozen=True)
class ReadSpan:
    """Consecutive registers of one table covering one or more adjacent fields."""

    table: TableName
    address: int
    count: int
    fields: tuple[RegisterField, ...]


def read_spans(
    fields: Iterable[RegisterField], max_registers: int = MAX_REGISTERS_PER_READ
) -> list[ReadSpan]:
    """Group fields into as few reads as possible without reading gaps.

    Fields are merged only when they touch (no unmapped register between them), since a real
    instrument may answer ILLEGAL_DATA_ADDRESS for registers it does not have.
    """
    spans: list[ReadSpan] = []
    for f in sorted(fields, key=lambda f: (f.table, f.address)):
        last = spans[-1] if spans else None
        if (
            last is not None
            and last.table == f.table
            and last.address + last.count == f.address
            and last.count + f.registers <= max_registers
        ):
            spans[-1] = ReadSpan(f.table, last.address, last.count + f.registers, (*last.fields, f))
        else:
            spans.append(ReadSpan(f.table, f.address, f.registers, (f,)))
    return spans


def decode_spans(spans: Iterable[ReadSpan], values: Iterable[Sequence[int]]) -> dict[str, Value]:
    """Decode each span's registers into ``{field name: value}``."""
    out: dict[str, Value] = {}
    for span, registers in zip(spans, values, strict=True):
        for f in span.fields:
            offset = f.address - span.address
            out[f.name] = decode_value(f, registers[offset : offset + f.registers])
    return out
