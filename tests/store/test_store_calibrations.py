"""Stored calibrations through the Store facade (CalibrationStore), and their refusals."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import update

from labauto.cli.main import main
from labauto.store import CalibrationRecord, InvalidValue, Store, StoredCalibration
from labauto.store.calibrations import CalibrationStore

K = [[1400.0, 0.0, 640.0], [0.0, 1400.0, 512.0], [0.0, 0.0, 1.0]]
CAMERA = {"camera_matrix": K, "dist_coeffs": [-0.1, 0.03, 0.0, 0.0, 0.0],
          "image_size": [1280, 1024], "rms_px": 0.05, "views": [{"image": "a.png"}]}  # fmt: skip


def test_the_store_has_the_calibration_aggregate(store: Store) -> None:
    assert isinstance(store, CalibrationStore)
    assert store.latest_calibration() is None and store.list_calibrations() == []


def test_save_then_the_newest_of_a_name_and_kind_is_in_force(store: Store) -> None:
    first = store.save_calibration("cam", "camera", CAMERA)
    assert isinstance(first, StoredCalibration)
    assert (first.name, first.kind, first.image_size, first.rms_px) == (
        "cam", "camera", (1280, 1024), 0.05,
    )  # fmt: skip
    assert first.residual_mm is None and first.created_at.tzinfo is not None
    assert first.camera_matrix.shape == (3, 3) and first.dist_coeffs.shape == (5,)
    assert first.data == CAMERA
    second = store.save_calibration("cam", "camera", {**CAMERA, "rms_px": 0.04})
    deck = store.save_calibration("deck", "deck", {**CAMERA, "rvec": [0, 0, 0]}, residual_mm=0.2)
    assert store.latest_calibration("cam").id == second.id
    assert store.latest_calibration("cam", "camera").rms_px == 0.04
    assert store.latest_calibration("cam", "deck") is None
    assert store.latest_calibration(kind="deck").residual_mm == 0.2
    assert store.latest_calibration().id == deck.id
    assert [c.id for c in store.list_calibrations()] == [first.id, second.id, deck.id]
    np.testing.assert_array_equal(store.latest_calibration("cam").camera_matrix, np.array(K))


def test_numpy_values_in_the_document_are_stored_as_json(store: Store) -> None:
    doc = {**CAMERA, "camera_matrix": np.array(K), "dist_coeffs": np.zeros((1, 5))}
    stored = store.save_calibration("np", "camera", doc)
    assert stored.data["camera_matrix"] == K and stored.data["dist_coeffs"] == [[0.0] * 5]


@pytest.mark.parametrize(
    ("name", "kind", "doc", "message"),
    [
        ("cam", "lens", CAMERA, "calibration kind must be one of ('camera', 'deck'), got 'lens'"),
        ("", "camera", CAMERA, "calibration name must be 1-200 characters"),
        ("x" * 201, "camera", CAMERA, "calibration name must be 1-200 characters"),
        ("cam", "camera", {"camera_matrix": K}, "the document has no dist_coeffs, image_size"),
        ("cam", "camera", {**CAMERA, "camera_matrix": [1, 2]}, "'cam' camera_matrix: not a 3x3"),
        ("cam", "camera", {**CAMERA, "image_size": "big"}, "'cam': image_size, rms_px or"),
        ("cam", "camera", {**CAMERA, "rms_px": "low"}, "'cam': image_size, rms_px or"),
    ],
)
def test_a_bad_calibration_is_refused_in_one_line_and_nothing_is_stored(
    store: Store, name: str, kind: str, doc: dict, message: str
) -> None:
    with pytest.raises(InvalidValue) as err:
        store.save_calibration(name, kind, doc)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert store.list_calibrations() == []


def test_a_damaged_stored_row_is_named_in_one_line(store: Store) -> None:
    stored = store.save_calibration("cam", "camera", CAMERA)
    with store.engine.begin() as connection:
        connection.execute(update(CalibrationRecord).values(camera_matrix=[1.0, 2.0]))
    with pytest.raises(InvalidValue) as err:
        store.latest_calibration("cam")
    assert f"stored calibration 'cam' (id {stored.id}) camera_matrix: not a 3x3" in str(err.value)
    assert "\n" not in str(err.value)


def test_cli_list_and_export_of_a_damaged_row(tmp_path, capsys, monkeypatch, db_url) -> None:
    monkeypatch.setenv("LABAUTO_DATABASE_URL", db_url)
    with Store.open(db_url) as store:
        store.save_calibration("cam", "camera", CAMERA)
    assert main(["calibrate", "list"]) == 0
    out = capsys.readouterr().out
    assert "   1  cam  camera  1280x1024  RMS 0.0500 px  " in out
    with Store.open(db_url) as store, store.engine.begin() as connection:
        connection.execute(update(CalibrationRecord).values(dist_coeffs="not numbers"))
    assert main(["calibrate", "export", "cam", "--out", str(tmp_path / "cam.yaml")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("labauto: error: stored calibration 'cam' (id 1)")
