"""Rendered board views, made once per test session."""

from __future__ import annotations

import cv2
import pytest
from calibration_helpers import Views, render_views

from labauto.vision.boards import board_from_dict, coded_board


@pytest.fixture(scope="session")
def coded_views() -> Views:
    """8 views of a 7x9 coded board (20 mm pitch), tilts up to 60 deg, blur, noise, light."""
    return render_views(coded_board(7, 9, 20.0), 8, seed=5)


@pytest.fixture(scope="session")
def circle_views() -> Views:
    """8 views of a symmetric 9x7 circle grid (spacing 20 mm, 8 mm circles)."""
    board = board_from_dict(
        {"type": "circle-grid", "cols": 9, "rows": 7, "spacing_mm": 20.0, "diameter_mm": 8.0}
    )
    return render_views(board, 8, seed=6)


@pytest.fixture()
def write_views(tmp_path):
    """Write views as PNG files and return their paths."""

    def write(views: Views, count: int | None = None) -> list[str]:
        paths = []
        for k, img in enumerate(views.images[:count]):
            path = tmp_path / f"view{k:02d}.png"
            cv2.imwrite(str(path), img)
            paths.append(str(path))
        return paths

    return write
