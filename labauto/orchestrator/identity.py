"""A run's effective config and its hash: what ties a stored run to the config it runs with.

The effective config is the validated config with every default filled in (the dataclass
sections ``detector`` and ``plate`` expanded too), as JSON data. The ``database`` section is left
out: it says where the run is stored, not what it does. The hash is the SHA-256 of that JSON with
sorted keys, so the same settings written in another order or spelling give the same hash.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any

from labauto.config import DATACLASS_SECTIONS, Config, section_params

EXCLUDED_SECTIONS = ("database",)
"""Sections that do not change what a run does."""


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    return value


def effective_config(config: Config) -> dict[str, Any]:
    """The config as JSON data with every default, dataclass sections expanded."""
    document = config.model_dump(mode="json")
    for section in DATACLASS_SECTIONS:
        document[section] = _plain(dataclasses.asdict(section_params(config, section)))
    return document


def config_hash(document: dict[str, Any]) -> str:
    """SHA-256 of an effective config, ``EXCLUDED_SECTIONS`` left out."""
    kept = {key: value for key, value in document.items() if key not in EXCLUDED_SECTIONS}
    text = json.dumps(kept, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(value, dict):
        flat: dict[str, Any] = {}
        for key, item in value.items():
            flat.update(_flatten(item, f"{prefix}.{key}" if prefix else str(key)))
        return flat
    return {prefix: value}


def config_differences(stored: Any, current: dict[str, Any], limit: int = 4) -> list[str]:
    """The dotted keys whose values differ, as ``key: stored -> current`` (at most ``limit``)."""
    old = {
        key: value
        for key, value in _flatten(stored if isinstance(stored, dict) else {}).items()
        if key.split(".")[0] not in EXCLUDED_SECTIONS
    }
    new = {
        key: value
        for key, value in _flatten(current).items()
        if key.split(".")[0] not in EXCLUDED_SECTIONS
    }
    changed = sorted(key for key in old.keys() | new.keys() if old.get(key) != new.get(key))
    shown = [f"{key}: {old.get(key)!r} -> {new.get(key)!r}" for key in changed[:limit]]
    if len(changed) > limit:
        shown.append(f"and {len(changed) - limit} more")
    return shown
