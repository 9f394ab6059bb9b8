"""Fixtures for the store tests: a real SQLite file per test, migrated by Alembic."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from labauto.store import Store


@pytest.fixture
def db_url(tmp_path: Path) -> str:
    """URL of a fresh SQLite file (not created yet)."""
    return f"sqlite:///{tmp_path / 'labauto.db'}"


@pytest.fixture
def store(db_url: str):
    """A Store on a real SQLite file, migrated to head."""
    with Store.open(db_url) as opened:
        yield opened


@dataclass(frozen=True)
class Scene:
    """A run with one plate and one image, ready for detections and colonies."""

    run_id: int
    plate_id: int
    image_id: int


@pytest.fixture
def scene(store: Store) -> Scene:
    run_id = store.create_run("test run", {"robot": "sim"})
    plate_id = store.add_plate("plate-001", "camera:0").id
    image_id = store.add_image(plate_id, "plate-001.png", 640, 480, "ab" * 32, run_id=run_id).id
    return Scene(run_id, plate_id, image_id)


def _detection_row(index: int, **overrides) -> dict:
    """A complete detection row with exact, index-dependent values."""
    row = {
        "object_index": index,
        "method": "canny",
        "centroid_x": 10.0 + index,
        "centroid_y": 20.0 + 0.5 * index,
        "n_points": 40 + index % 7,
        "closed": index % 2 == 0,
        "d_alpha_median": 1.5,
        "d_alpha_mean": 2.25,
        "centroid_inside": True,
        "is_des": index % 3 != 0,
        "shape": "ellipse",
        "ellipse_cx": 10.0 + index,
        "ellipse_cy": 20.0 + 0.5 * index,
        "ellipse_a": 6.0,
        "ellipse_b": 4.0,
        "ellipse_angle": 30.0,
        "area_px": 75.4,
    }
    row.update(overrides)
    return row


def _colony_row(index: int, **overrides) -> dict:
    """A complete colony row."""
    row = {
        "colony_index": index,
        "klass": "authentic",
        "centroid_x": 100.0 + index,
        "centroid_y": 200.0,
        "area_px": 50.0,
        "d_alpha_median": 1.0,
        "contour": [[0, 0], [4, 0], [4, 3]],
    }
    row.update(overrides)
    return row


@pytest.fixture
def detection_row():
    """Factory: ``detection_row(index, **overrides)`` -> a complete detection row."""
    return _detection_row


@pytest.fixture
def colony_row():
    """Factory: ``colony_row(index, **overrides)`` -> a complete colony row."""
    return _colony_row
