"""Helpers of the reliability suite: fast simulated workcells, crash injection, invariants.

Everything is real: the run's SQLite file is migrated by Alembic, the GRBL driver talks to the
simulated gantry over a pseudo-terminal and the Modbus driver to the simulated analyzer over
TCP. A crash is injected in-process by :class:`CrashingStore` (after its n-th committed write it
raises :class:`SimulatedCrash`, a ``BaseException`` that no ``except Exception`` catches, as if
the process had died right after that commit), or for real with SIGKILL.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import yaml

from labauto.config import Config, parse_config
from labauto.drivers.camera import sample_plates_dir
from labauto.store import Store


class SimulatedCrash(BaseException):
    """The process 'dies' here: raised after a committed write, never caught by the run."""


def workcell_config(tmp_path: Path, plates: int = 2, **sections: Any) -> Config:
    """A fast simulated workcell on ``plates`` sample plates copied into ``tmp_path``."""
    folder = tmp_path / "plates"
    folder.mkdir(parents=True, exist_ok=True)
    for png in sorted(sample_plates_dir().glob("*.png"))[:plates]:
        shutil.copy(png, folder / png.name)
    data: dict[str, Any] = {
        "name": "reliability",
        "database": {"url": f"sqlite:///{tmp_path / 'labauto.db'}"},
        "camera": {"path": str(folder)},
        "robot": {
            "simulator": {"speed_factor": 400.0},
            "timeout_s": 1.0,
            "dwell_s": 0.0,
        },
        "analyzer": {"simulator": {"speed_factor": 100.0, "analysis_seconds": 0.5}},
        "picking": {"max_picks": 1},
        "output": {"dir": str(tmp_path / "out"), "annotate": False},
        "run": {"retry": {"attempts": 3, "initial_delay_s": 0.05, "max_delay_s": 0.2}},
    }
    for section, values in sections.items():
        if isinstance(values, dict) and isinstance(data.get(section), dict):
            merged = dict(data[section])
            for key, value in values.items():
                if isinstance(value, dict) and isinstance(merged.get(key), dict):
                    merged[key] = {**merged[key], **value}
                else:
                    merged[key] = value
            data[section] = merged
        else:
            data[section] = values
    return parse_config(data, "<reliability>", environ={})


def write_config(config: Config, path: Path) -> Path:
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return path


def db_path(config: Config) -> Path:
    return Path(config.database.url.removeprefix("sqlite:///"))


class CrashingStore(Store):
    """A store that 'dies' right after its ``crash_after``-th committed write (0: never).

    Only writes of the thread that opened it count (the lease heartbeat writes from its own
    thread at times that vary, so counting it would make the boundaries move between runs).
    """

    def __init__(self, engine: Any, crash_after: int = 0) -> None:
        super().__init__(engine)
        self.crash_after = crash_after
        self.commits = 0
        self._thread = threading.get_ident()

    @classmethod
    def open_crashing(cls, url: str, crash_after: int = 0) -> CrashingStore:
        base = Store.open(url)
        return cls(base.engine, crash_after)

    @contextmanager
    def _write(self, operation: str) -> Iterator[Any]:
        with super()._write(operation) as session:
            yield session
        if threading.get_ident() != self._thread:
            return
        self.commits += 1
        if self.crash_after and self.commits == self.crash_after:
            raise SimulatedCrash(f"killed after commit {self.commits} ({operation})")


def query(db: Path, sql: str) -> list[tuple]:
    with sqlite3.connect(db, timeout=10) as connection:
        return connection.execute(sql).fetchall()


def plate_picture(db: Path, run_id: int = 1) -> dict[str, Any]:
    """What a run stored and planned, per plate place, in terms that do not depend on row ids.

    For each image position: the plate name, the number of detections and colonies, and the
    colony indexes chosen for picking in pick order.
    """
    picture: dict[str, Any] = {}
    for image_id, position, name in query(
        db, f"select id, position, path from images where run_id = {run_id} order by position"
    ):
        detections = query(db, f"select count(*) from detections where image_id = {image_id}")
        colonies = query(db, f"select count(*) from colonies where image_id = {image_id}")
        picked = query(
            db,
            "select c.colony_index from picks p join colonies c on c.id = p.colony_id "
            f"where c.image_id = {image_id} order by p.sequence",
        )
        picture[str(position)] = {
            "plate": name,
            "detections": detections[0][0],
            "colonies": colonies[0][0],
            "picks": [index for (index,) in picked],
        }
    return picture


def integrity_problems(db: Path, run_id: int = 1) -> list[str]:
    """Duplicate rows, repeated picks and dangling rows in a run (empty when all is well)."""
    problems = []
    checks = {
        "plate stored twice": "select position from images where run_id = {r} "
        "group by position having count(*) > 1",
        "detection stored twice": "select image_id, object_index from detections where "
        "run_id = {r} group by image_id, object_index having count(*) > 1",
        "colony stored twice": "select image_id, colony_index from colonies where run_id = {r} "
        "group by image_id, colony_index having count(*) > 1",
        "colony planned twice": "select colony_id from picks where run_id = {r} "
        "group by colony_id having count(*) > 1",
        "pick started twice": "select data from events where run_id = {r} and kind = "
        "'pick.state' and json_extract(data, '$.to') = 'moving' "
        "group by json_extract(data, '$.pick_id') having count(*) > 1",
        "image without colonies": "select i.id from images i where i.run_id = {r} and not "
        "exists (select 1 from colonies c where c.image_id = i.id)",
        "pick left in flight": "select id from picks where run_id = {r} and state in "
        "('moving', 'picked', 'delivered', 'planned')",
        "two results for a pick": "select pick_id from analyzer_results group by pick_id "
        "having count(*) > 1",
    }
    for name, sql in checks.items():
        rows = query(db, sql.format(r=run_id))
        if rows:
            problems.append(f"{name}: {rows[:3]}")
    return problems


def labauto(*args: str, cwd: Path, env: dict[str, str] | None = None) -> subprocess.Popen:
    """Start a real ``labauto`` process (the installed CLI, ``python -m labauto.cli.main``)."""
    return subprocess.Popen(
        [sys.executable, "-m", "labauto.cli.main", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **(env or {})},
    )


class Trigger:
    """A reporter that runs ``action`` once, at the first event of kind ``kind``."""

    def __init__(self, kind: str, action: Any) -> None:
        self.kind, self.action, self.fired = kind, action, False

    def on_event(self, kind: str, message: str, data: dict[str, Any]) -> None:
        if not self.fired and kind == self.kind:
            self.fired = True
            self.action()
