"""``labauto calibrate camera|export`` and its refusals, each one clear line (issue 14.9)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from labauto.calibration.boards_io import write_board
from labauto.cli.main import main
from labauto.store.db import current_revision, head_revision
from labauto.vision.boards import coded_board


@pytest.fixture()
def board_yaml(tmp_path, coded_views):
    _, description = write_board(coded_views.board, tmp_path / "board.svg")
    return str(description)


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("labauto: error: "), err
    return lines[0]


def test_json_save_and_export_read_by_opencv(
    tmp_path, capsys, monkeypatch, coded_views, board_yaml, write_views
) -> None:
    db = tmp_path / "cal.db"
    monkeypatch.setenv("LABAUTO_DATABASE_URL", f"sqlite:///{db}")
    images = write_views(coded_views, 5)
    code, out, err = _run(
        capsys, "calibrate", "camera", "--board", board_yaml, *images, "--json", "--save", "bench"
    )
    assert code == 0, err
    doc = json.loads(out)
    assert set(doc) == {"rms_px", "camera_matrix", "dist_coeffs", "image_size", "views"}
    assert [v["image"] for v in doc["views"]] == images
    assert current_revision(f"sqlite:///{db}") == head_revision()  # a real, migrated file
    exported = tmp_path / "camera.yaml"
    code, _, err = _run(capsys, "calibrate", "export", "bench", "--out", str(exported))
    assert code == 0, err
    fs = cv2.FileStorage(str(exported), cv2.FILE_STORAGE_READ)
    try:
        matrix = fs.getNode("camera_matrix").mat()
        dist = fs.getNode("distortion_coefficients").mat().ravel()
        width = int(fs.getNode("image_width").real())
    finally:
        fs.release()
    assert np.allclose(matrix, doc["camera_matrix"], rtol=0, atol=1e-9)
    assert np.allclose(dist, doc["dist_coeffs"], rtol=0, atol=1e-12)
    assert width == doc["image_size"][0]
    code, out, _ = _run(capsys, "calibrate", "list")
    assert code == 0 and "bench" in out and "camera" in out


def test_too_few_views(capsys, coded_views, board_yaml, write_views) -> None:
    images = write_views(coded_views, 2)
    code, _, err = _run(capsys, "calibrate", "camera", "--board", board_yaml, *images)
    assert code == 1
    assert "too few usable views: 2 of 2 (needs 3)" in _one_error_line(err)


def test_no_board_found(tmp_path, capsys, board_yaml) -> None:
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((300, 400), 180, np.uint8))
    code, _, err = _run(capsys, "calibrate", "camera", "--board", board_yaml, *[str(blank)] * 3)
    assert code == 1
    assert "0 of 3" in _one_error_line(err) and "3 x no board found" in err


def test_board_yaml_that_does_not_match_the_images(
    tmp_path, capsys, coded_views, write_views
) -> None:
    _, other = write_board(coded_board(3, 3, 20.0, first_id=300), tmp_path / "other.svg")
    images = write_views(coded_views, 3)
    code, _, err = _run(capsys, "calibrate", "camera", "--board", str(other), *images)
    assert code == 1
    line = _one_error_line(err)
    assert "other.yaml does not match the images" in line and "ids 300..308" in line


def test_unreadable_image_and_broken_board(tmp_path, capsys, board_yaml) -> None:
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    code, _, err = _run(capsys, "calibrate", "camera", "--board", board_yaml, str(bad))
    assert code == 1 and "bad.png" in _one_error_line(err)
    broken = tmp_path / "broken.yaml"
    broken.write_text(
        "type: coded\nmarker_radius_mm: 2\nmarkers: [{id: 5000, center_mm: [1, 2]}]\n"
    )
    code, _, err = _run(capsys, "calibrate", "camera", "--board", str(broken), str(bad))
    assert code == 1 and "markers[0].id: no such code 5000" in _one_error_line(err)


def test_export_of_an_unknown_name(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setenv("LABAUTO_DATABASE_URL", f"sqlite:///{tmp_path / 'x.db'}")
    code, _, err = _run(capsys, "calibrate", "export", "nosuch", "--out", str(tmp_path / "a.yaml"))
    assert code == 1 and "no stored calibration named 'nosuch'" in _one_error_line(err)
