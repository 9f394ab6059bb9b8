"""Checking and normalising the rows handed to the store's bulk inserts.

A row is a mapping of column names to values. Before a bulk insert every row of a batch gets the
same keys (missing optional columns filled with their default), numpy scalars become Python
scalars (``sqlite3`` cannot bind ``numpy.int64``), and JSON columns are made plain JSON data.
Errors name the row index and the field.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import asdict, is_dataclass
from datetime import date, datetime
from typing import Any

from .errors import InvalidValue

_PLAIN_TYPES = frozenset({int, float, str, bool, type(None)})


def plain_scalar(value: Any) -> Any:
    """Return ``value`` as a plain Python scalar (numpy scalars via ``.item()``)."""
    if type(value) in _PLAIN_TYPES:
        return value
    item = getattr(value, "item", None)
    if callable(item):
        return item()
    return value


def _json_default(value: Any) -> Any:
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return value.tolist()
    if isinstance(value, datetime | date):
        return value.isoformat()
    if hasattr(value, "model_dump"):  # pydantic models
        return value.model_dump(mode="json")
    if is_dataclass(value) and not isinstance(value, type):
        return asdict(value)
    if isinstance(value, set | frozenset | tuple):
        return list(value)
    raise TypeError(f"object of type {type(value).__name__} is not JSON serializable")


def json_data(value: Any, field: str) -> Any:
    """Return ``value`` as plain JSON data (dicts, lists, str, numbers, bool, None).

    numpy arrays and scalars, datetimes (ISO 8601 text), pydantic models, dataclasses, tuples
    and sets are converted.

    Parameters
    ----------
    value : object
        The data to store in a JSON column.
    field : str
        Name used in the error message.

    Raises
    ------
    InvalidValue
        If the value cannot be written as JSON.
    """
    if value is None or type(value) in _PLAIN_TYPES:
        return value
    try:
        return json.loads(json.dumps(value, default=_json_default))
    except (TypeError, ValueError) as exc:
        raise InvalidValue(f"{field}: cannot store as JSON: {exc}") from exc


class RowShape:
    """The columns a bulk insert accepts: required ones, optional ones with their defaults.

    Parameters
    ----------
    table : str
        Table name, for error messages.
    required : iterable of str
        Columns every row must give.
    optional : mapping of str to object
        Columns a row may give, with the value used when it does not.
    json_columns : iterable of str
        Columns whose values are converted with :func:`json_data`.
    """

    def __init__(
        self,
        table: str,
        required: Iterable[str],
        optional: Mapping[str, Any],
        json_columns: Iterable[str] = (),
    ) -> None:
        self.table = table
        self.required = frozenset(required)
        self.optional = dict(optional)
        self.allowed = self.required | self.optional.keys()
        self.json_columns = frozenset(json_columns)
        self._checked_keysets: set[frozenset[str]] = set()

    def check_keys(self, index: int, keys: Iterable[str]) -> None:
        """Raise :class:`InvalidValue` if a row's keys are unknown or a required one is missing."""
        keyset = frozenset(keys)
        if keyset in self._checked_keysets:
            return
        unknown = keyset - self.allowed
        if unknown:
            raise InvalidValue(
                f"{self.table} row {index}: unknown field(s) {sorted(unknown)}; "
                f"allowed: {sorted(self.allowed)}"
            )
        missing = self.required - keyset
        if missing:
            raise InvalidValue(f"{self.table} row {index}: missing field(s) {sorted(missing)}")
        self._checked_keysets.add(keyset)

    def normalise(self, index: int, row: Mapping[str, Any], fixed: Mapping[str, Any]) -> dict:
        """Return a full row: defaults, then the given values as plain scalars, then ``fixed``."""
        self.check_keys(index, row.keys())
        out = dict(self.optional)
        for key, value in row.items():
            if key in self.json_columns:
                out[key] = json_data(value, f"{self.table} row {index} field {key!r}")
            else:
                out[key] = plain_scalar(value)
        out.update(fixed)
        return out
