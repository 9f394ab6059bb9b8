"""A small simulated workcell for run tests: one sample plate, fast simulated devices."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

from labauto.config import Config, parse_config
from labauto.drivers.camera import sample_plates_dir


def workcell_config(tmp_path: Path, plates: int = 1, **sections: Any) -> Config:
    """A config for a simulated run on ``plates`` sample plates copied into ``tmp_path``."""
    folder = tmp_path / "plates"
    folder.mkdir(exist_ok=True)
    for png in sorted(sample_plates_dir().glob("*.png"))[:plates]:
        shutil.copy(png, folder / png.name)
    data: dict[str, Any] = {
        "name": "test-run",
        "database": {"url": f"sqlite:///{tmp_path / 'labauto.db'}"},
        "camera": {"path": str(folder)},
        "robot": {"simulator": {"speed_factor": 200.0}, "timeout_s": 1.0, "dwell_s": 0.0},
        "analyzer": {"simulator": {"speed_factor": 50.0, "analysis_seconds": 1.0}},
        "picking": {"max_picks": 3},
        "output": {"dir": str(tmp_path / "out")},
    }
    for section, values in sections.items():
        if isinstance(values, dict) and isinstance(data.get(section), dict):
            data[section] = {**data[section], **values}
        else:
            data[section] = values
    return parse_config(data, "<test>", environ={})


class Recorder:
    """A reporter that keeps every event and can act on one (``when(kind, action)``)."""

    def __init__(self) -> None:
        self.events: list[tuple[str, str]] = []
        self._actions: list[tuple[Callable[[str, str], bool], Callable[[], None]]] = []

    def when(self, predicate: Callable[[str, str], bool], action: Callable[[], None]) -> None:
        """Run ``action`` once, at the first event for which ``predicate(kind, message)``."""
        self._actions.append((predicate, action))

    def on_event(self, kind: str, message: str, data: dict[str, Any]) -> None:
        self.events.append((kind, message))
        for entry in list(self._actions):
            predicate, action = entry
            if predicate(kind, message):
                self._actions.remove(entry)
                action()

    def kinds(self) -> list[str]:
        return [kind for kind, _ in self.events]
