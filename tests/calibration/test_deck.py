"""Deck calibration (issue 14.5): the pose over the deck from the head's marker or a board."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml

from labauto.calibration.deck import calibrate_deck
from labauto.config import parse_config
from labauto.errors import CalibrationError
from labauto.orchestrator.calibration import Calibration, stored_deck_calibration
from labauto.store import Store
from labauto.synthetic.camera import CameraModel, HeadMarker, SceneCamera
from labauto.vision.board_points import find_board_points
from labauto.vision.boards import coded_board
from labauto.vision.deck import DeckCalibration, DeckCalibrationFailed, board_to_deck
from labauto.vision.markers import detect_markers

K = np.array([[1400.0, 0.0, 640.0], [0.0, 1400.0, 512.0], [0.0, 0.0, 1.0]])
D = np.array([-0.1, 0.03, 0.0, 0.0, 0.0])
SIZE = (1280, 1024)
MODEL = CameraModel.looking_down(K, D, (84.0, 71.0, 140.0), SIZE, tilt_deg=(2.0, -3.0))


def _surface_truth(n: int = 30, z: float = -30.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    deck = np.column_stack((rng.uniform(30, 140, n), rng.uniform(25, 115, n), np.full(n, z)))
    px, _ = cv2.projectPoints(deck, MODEL.rvec, MODEL.tvec, K, D)
    return px.reshape(-1, 2), deck[:, :2]


def _head_pairs(heights=(-5.0, -20.0)) -> tuple[np.ndarray, np.ndarray]:
    where = [0.0, 0.0, 0.0]
    camera = SceneCamera(MODEL, head_position=lambda: where, head_marker=HeadMarker(300, 1.5))
    pixels, points = [], []
    for z in heights:
        for x in np.linspace(44, 124, 3):
            for y in np.linspace(40, 102, 3):
                where[:] = [x, y, z]
                (m,) = [m for m in detect_markers(camera.capture()) if m.id == 300]
                pixels.append(m.center)
                points.append((x, y, z))
    return np.array(pixels), np.array(points)


@pytest.fixture(scope="module")
def head_pairs():
    return _head_pairs()


def test_head_marker_pose_maps_pixels_to_the_surface(head_pairs) -> None:
    cal = DeckCalibration.from_points(*head_pairs, K, D, SIZE, surface_z=-30.0)
    assert cal.residual_mm < 0.01
    assert np.allclose(cal.camera_position(), (84.0, 71.0, 140.0), atol=0.05)
    pixels, deck = _surface_truth()
    assert np.abs(cal.to_deck(pixels) - deck).max() < 0.01  # 10 um on the agar
    assert np.abs(cal.to_pixels(deck) - pixels).max() < 0.01


def test_it_beats_a_homography_through_the_same_lens(head_pairs) -> None:
    cal = DeckCalibration.from_points(*head_pairs, K, D, SIZE, surface_z=-30.0)
    pixels, deck = _surface_truth(60)
    homography = Calibration.from_points(pixels[:30], deck[:30], max_residual_mm=10.0)
    h_error = np.abs(homography.to_deck(pixels[30:]) - deck[30:]).max()
    d_error = np.abs(cal.to_deck(pixels[30:]) - deck[30:]).max()
    assert h_error > 0.1 and d_error < h_error / 10  # the lens bends what a homography keeps


def test_bad_pairs_are_refused_with_the_residual(head_pairs) -> None:
    pixels, points = head_pairs
    shaken = pixels + np.random.default_rng(2).normal(0, 15.0, pixels.shape)
    with pytest.raises(DeckCalibrationFailed, match=r"residual .* exceeds the limit of 0\.500"):
        DeckCalibration.from_points(shaken, points, K, D, SIZE, surface_z=-30.0)
    with pytest.raises(DeckCalibrationFailed, match="at least 6 points, got 5"):
        DeckCalibration.from_points(pixels[:5], points[:5], K, D, SIZE, surface_z=-30.0)


def test_board_lying_on_the_deck() -> None:
    board = coded_board(4, 5, 16.0)
    origin, angle = (50.0, 100.0, -30.0), 4.0
    image = SceneCamera(MODEL, sheets=[(board, origin, angle)]).capture()
    view = find_board_points(image, board)
    assert len(view) == 20
    deck = board_to_deck(view.object_points, origin, angle)
    cal = DeckCalibration.from_points(view.image_points, deck, K, D, SIZE, surface_z=-30.0)
    assert cal.residual_mm < 0.01
    pixels, truth = _surface_truth()
    assert np.abs(cal.to_deck(pixels) - truth).max() < 0.02


def _config(tmp_path, **deck) -> object:
    doc = {
        "database": {"url": f"sqlite:///{tmp_path / 'deck.db'}"},
        "robot": {"simulate": True, "simulator": {"speed_factor": 200.0}},
        "calibration": {"deck": {"camera": "cam", "surface_z_mm": -30.0,
                                 "grid": {"counts": [3, 2], "z_mm": [-5.0, -20.0]}, **deck}},
    }  # fmt: skip
    return parse_config(yaml.safe_load(yaml.safe_dump(doc)), "<test>")


def _store_camera(store) -> None:
    doc = {"camera_matrix": K.tolist(), "dist_coeffs": D.tolist(), "image_size": list(SIZE),
           "rms_px": 0.01}  # fmt: skip
    store.save_calibration("cam", "camera", doc)


def test_simulated_gantry_carries_the_marker_and_runs_use_the_result(tmp_path) -> None:
    config = _config(tmp_path)
    with Store.open(config.database.url) as store:
        _store_camera(store)
        cal, report = calibrate_deck(config, store)
        assert len(report["positions"]) == 12 and all(p["pixel"] for p in report["positions"])
        assert cal.residual_mm < 0.01
        store.save_calibration("deck", "deck", cal.to_dict(), cal.residual_mm)
        used = stored_deck_calibration(config, store)
        assert isinstance(used, DeckCalibration)
        pixels, deck = _surface_truth()
        assert np.abs(used.to_deck(pixels) - deck).max() < 0.01
        # a stored calibration over the limit is refused, not used
        bad = {**cal.to_dict(), "residual_mm": 0.9}
        store.save_calibration("deck", "deck", bad, 0.9)
        with pytest.raises(CalibrationError, match=r"residual of 0\.900 mm, over the limit"):
            stored_deck_calibration(config, store)


def test_without_a_camera_calibration_the_deck_is_refused_in_one_line(tmp_path) -> None:
    config = _config(tmp_path)
    with Store.open(config.database.url) as store, pytest.raises(CalibrationError) as err:
        calibrate_deck(config, store)
    assert "no stored camera calibration named 'cam'" in str(err.value)
    assert "\n" not in str(err.value)


def test_a_stored_deck_calibration_that_cannot_be_read_is_refused_in_one_line(tmp_path) -> None:
    config = _config(tmp_path)
    with Store.open(config.database.url) as store:
        _store_camera(store)
        camera = store.latest_calibration("cam", "camera")
        store.save_calibration("deck", "deck", camera.data, 0.001)  # a camera document, no pose
        with pytest.raises(CalibrationError) as err:
            stored_deck_calibration(config, store)
    message = str(err.value)
    assert "stored deck calibration 'deck' (id 2) cannot be read (no 'rvec')" in message
    assert "labauto calibrate deck" in message and "\n" not in message


def test_a_marker_out_of_view_is_reported(tmp_path) -> None:
    config = _config(tmp_path, grid={"x_mm": [250.0, 290.0], "y_mm": [150.0, 190.0],
                                     "counts": [3, 2], "z_mm": [-5.0]})  # fmt: skip
    with Store.open(config.database.url) as store:
        _store_camera(store)
        with pytest.raises(CalibrationError, match="seen at 0 of 6 positions"):
            calibrate_deck(config, store)


def test_board_source_through_the_config(tmp_path) -> None:
    from labauto.calibration.boards_io import write_board

    _, description = write_board(coded_board(4, 5, 16.0), tmp_path / "deckboard.svg")
    board = {"path": str(description), "origin_mm": [50.0, 100.0, -30.0], "angle_deg": 4.0}
    config = _config(tmp_path, source="board", board=board)
    with Store.open(config.database.url) as store:
        _store_camera(store)
        cal, report = calibrate_deck(config, store)
    assert report["source"] == "board" and report["markers"] == 20
    assert cal.residual_mm < 0.01
    pixels, deck = _surface_truth()
    assert np.abs(cal.to_deck(pixels) - deck).max() < 0.02


def test_a_folder_camera_gives_its_next_frame_at_each_position(tmp_path) -> None:
    from labauto.calibration.deck import _frame_source
    from labauto.imageio import write_image

    frames = tmp_path / "frames"
    for k in range(2):
        write_image(frames / f"f{k}.png", np.full((8, 8), 40 * (k + 1), np.uint8))
    doc = {"camera": {"driver": "folder", "path": str(frames)}, "robot": {"simulate": False}}
    config = parse_config(yaml.safe_load(yaml.safe_dump(doc)), "<test>")
    capture = _frame_source(config, None)
    assert [int(capture()[0, 0]) for _ in range(2)] == [40, 80]
    with pytest.raises(CalibrationError, match="no more images"):
        capture()


def test_board_points_as_a_list_and_no_pixels_at_all() -> None:
    assert board_to_deck([[1.0, 2.0]], (10.0, 20.0, -3.0)).tolist() == [[11.0, 18.0, -3.0]]
    cal = DeckCalibration.from_dict(
        {"camera_matrix": K.tolist(), "dist_coeffs": D.tolist(), "rvec": MODEL.rvec.tolist(),
         "tvec": MODEL.tvec.tolist(), "surface_z_mm": -30.0, "residual_mm": 0.0,
         "n_points": 6, "image_size": list(SIZE)}
    )  # fmt: skip
    assert cal.to_deck(np.zeros((0, 2))).shape == (0, 2)
