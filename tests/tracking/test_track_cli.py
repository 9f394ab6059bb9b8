"""``labauto track``: sources, JSON lines, board and pose, and bad input (issue 15 points 1, 9)."""

from __future__ import annotations

import json
import time
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
import yaml

from labauto.cli.main import main
from labauto.cli.track_sources import SourceError, open_source
from labauto.synthetic.marker_sequences import board_points

KEYS = {"frame", "timing_ms", "mode", "markers", "lost", "appeared"}


@pytest.fixture
def frame_folder(tmp_path, hard_sequence):
    folder = tmp_path / "frames"
    folder.mkdir()
    for frame in hard_sequence[:6]:
        cv2.imwrite(str(folder / f"f{frame.index:03d}.png"), frame.image)
    return folder


def track(capsys, *args):
    code = main(["track", *map(str, args)])
    out, err = capsys.readouterr()
    return code, [json.loads(line) for line in out.splitlines() if line.startswith("{")], err


def test_json_lines_per_frame_from_a_folder_in_name_order(frame_folder, hard_sequence, capsys):
    code, lines, err = track(capsys, frame_folder, "--json-lines")
    assert code == 0 and err == ""
    assert [d["frame"] for d in lines] == list(range(6))
    for document, frame in zip(lines, hard_sequence, strict=False):
        assert set(document) == KEYS
        assert document["mode"] in ("roi", "full") and isinstance(document["timing_ms"], float)
        assert all(set(m) == {"id", "center"} for m in document["markers"])
        found = {m["id"]: m["center"] for m in document["markers"]}
        assert set(found) == frame.visible
        for mid, center in found.items():
            assert np.hypot(*np.subtract(center, frame.centers[mid])) < 0.3
    assert lines[0]["mode"] == "full" and lines[0]["appeared"] == sorted(hard_sequence[0].visible)
    assert [d["mode"] for d in lines[2:]].count("roi") >= 3  # frame 1: no velocities yet


def test_board_and_calibration_give_the_pose_per_frame(
    frame_folder, hard_sequence, hard_spec, tmp_path, capsys
):
    board = tmp_path / "board.yaml"
    markers = [{"id": k, "center_mm": [x, y]} for k, (x, y, _) in board_points(hard_spec).items()]
    board.write_text(yaml.safe_dump({"type": "coded", "markers": markers[:-1]}))  # one left out
    calibration = tmp_path / "camera.json"
    calibration.write_text(
        json.dumps(
            {
                "camera_matrix": hard_spec.camera_matrix.tolist(),
                "dist_coeffs": list(hard_spec.dist_coeffs),
            }
        )
    )
    code, lines, _ = track(
        capsys,
        frame_folder,
        "--json-lines",
        "--fit",
        "--board",
        board,
        "--calibration",
        calibration,
    )
    assert code == 0
    left_out = markers[-1]["id"]
    for document, frame in zip(lines, hard_sequence, strict=False):
        assert left_out not in {m["id"] for m in document["markers"]}
        pose = document["pose"]
        assert np.linalg.norm(np.subtract(pose["tvec_mm"], frame.tvec)) < 0.5
        assert pose["reprojection_rms_px"] < 0.3 and len(pose["markers"]) >= 4


def test_a_video_file_is_tracked(tmp_path, hard_sequence, capsys):
    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (800, 600))
    assert writer.isOpened()
    for frame in hard_sequence[:4]:
        writer.write(cv2.cvtColor(frame.image, cv2.COLOR_GRAY2BGR))
    writer.release()
    code, lines, _ = track(capsys, video, "--json-lines")
    assert code == 0 and len(lines) == 4
    assert {m["id"] for m in lines[-1]["markers"]} == hard_sequence[3].visible


def test_without_json_lines_a_summary(frame_folder, capsys):
    code = main(["track", str(frame_folder)])
    out = capsys.readouterr().out
    assert code == 0 and "6 frames, 12 markers seen" in out and "windowed search" in out


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (
            lambda p: (p / "junk.mp4").write_bytes(b"\x00not a video" * 50) and p / "junk.mp4",
            "cannot open as a video",
        ),
        (lambda p: (p / "empty").mkdir() or p / "empty", "folder has no images"),
        (lambda p: p / "nothing-here", "no such video file or folder"),
    ],
)
def test_bad_sources_end_in_one_line(tmp_path, capsys, make, message):
    code, lines, err = track(capsys, make(tmp_path), "--json-lines")
    assert code == 1 and lines == []
    assert err.count("\n") == 1 and err.startswith("labauto: error: ") and message in err


def test_an_unreadable_frame_keeps_the_frames_before_it(frame_folder, capsys):
    (frame_folder / "f003.png").write_bytes(b"\x89PNG broken")
    code, lines, err = track(capsys, frame_folder, "--json-lines")
    assert code == 1 and [d["frame"] for d in lines] == [0, 1, 2]
    assert err.count("\n") == 1 and "f003.png" in err and "after 3 frames" in err


def test_a_camera_that_stops_delivering_is_one_line_after_its_frames(
    hard_sequence, capsys, monkeypatch
):
    def stalling_camera(section):
        def frames():
            for frame in hard_sequence[:3]:
                yield f"cam-{frame.index}", frame.image
            time.sleep(30)

        return frames()

    registry = SimpleNamespace(driver=lambda kind, name: stalling_camera)
    monkeypatch.setattr(
        "labauto.plugin_manager.load_plugins", lambda *a, **k: SimpleNamespace(registry=registry)
    )
    started = time.monotonic()
    code, lines, err = track(capsys, "camera:stalls", "--json-lines", "--frame-timeout", "0.5")
    assert time.monotonic() - started < 10
    assert code == 1 and len(lines) == 3
    assert "camera:stalls: camera delivered no frame for 0.5 s (after 3 frames)" in err


def test_a_camera_that_fails_and_an_unknown_camera(capsys):
    def broken():
        yield "one", np.full((100, 100), 200, np.uint8)
        raise OSError("USB gone")

    frames = open_source("camera:x", camera_factory=lambda name: broken(), frame_timeout_s=2)
    assert next(frames)[0] == "one"
    with pytest.raises(SourceError, match="camera failed after 1 frames: OSError: USB gone"):
        next(frames)
    code, _, err = track(capsys, "camera:nosuch")
    assert code == 1 and "no camera driver named 'nosuch'" in err


def test_two_cameras_give_triangulated_3d_positions(tmp_path, hard_spec, capsys):
    from test_pose import render_view

    from labauto.vision.pose import CameraView

    points = board_points(hard_spec)  # a board lying still: it is the world frame
    k = np.array([[900.0, 0, 399.5], [0, 900, 299.5], [0, 0, 1]])
    dist = np.array([-0.05, 0.01, 0, 0, 0])
    views = {
        "left": CameraView(k, dist, np.array([0.25, -0.2, 0.02]), np.array([-60.0, 0.0, 480.0])),
        "right": CameraView(k, dist, np.array([0.2, 0.25, -0.03]), np.array([60.0, 10.0, 470.0])),
    }
    args = []
    for name, view in views.items():
        folder = tmp_path / name
        folder.mkdir()
        for n in range(3):
            cv2.imwrite(str(folder / f"{n}.png"), render_view(points, view))
        calibration = tmp_path / f"{name}.json"
        calibration.write_text(
            json.dumps(
                {
                    "camera_matrix": k.tolist(),
                    "dist_coeffs": dist.tolist(),
                    "rvec": view.rvec.tolist(),
                    "tvec": view.tvec.tolist(),
                }
            )
        )
        args.append((folder, calibration))
    (left, cal_left), (right, cal_right) = args
    code, lines, err = track(
        capsys, left, "--stereo", right, "--calibration", cal_left, "--calibration2", cal_right,
        "--fit", "--json-lines",
    )  # fmt: skip
    assert code == 0, err
    assert len(lines) == 3
    for document in lines:
        found = {p["id"]: p for p in document["points_3d"]}
        assert set(found) == set(points)
        for mid, point in found.items():
            assert np.linalg.norm(np.subtract(point["position_mm"], points[mid])) < 0.5
            assert max(point["reprojection_px"]) < 0.5
    # a calibration without the camera's pose is refused in one line
    code, _, err = track(
        capsys, left, "--stereo", right, "--calibration", tmp_path / "nope.json",
        "--calibration2", cal_right,
    )  # fmt: skip
    assert code == 1 and "calibration file not found" in err
    (tmp_path / "nopose.json").write_text(json.dumps({"camera_matrix": k.tolist()}))
    code, _, err = track(
        capsys, left, "--stereo", right, "--calibration", tmp_path / "nopose.json",
        "--calibration2", cal_right,
    )  # fmt: skip
    assert code == 1 and "needs the camera's pose: rvec and tvec" in err


@pytest.mark.parametrize("suffix", [".json", ".yaml", ".xml"])
def test_a_calibration_written_by_calibrate_out_is_read_back(tmp_path, suffix):
    """``calibrate camera --out FILE.json`` writes FileStorage's JSON (opencv-matrix objects,
    ``distortion_coefficients``): --calibration read it as our --json and refused it."""
    from labauto.calibration.files import write_opencv_yaml
    from labauto.cli.track_inputs import read_camera, read_camera_view

    k = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]
    doc = {"camera_matrix": k, "dist_coeffs": [0.1, 0.0, 0.0, 0.0, 0.0], "image_size": [640, 480],
           "rvec": [0.1, 0.2, 0.3], "tvec": [1.0, 2.0, 3.0]}  # fmt: skip
    path = write_opencv_yaml(tmp_path / f"cal{suffix}", doc)
    matrix, dist = read_camera(path)
    assert matrix.tolist() == k and dist.tolist() == doc["dist_coeffs"]
    assert read_camera_view(path).tvec.tolist() == doc["tvec"]
    plain = tmp_path / "ours.json"  # the JSON of calibrate camera --json still reads as it is
    plain.write_text(json.dumps(doc))
    assert read_camera(plain)[0].tolist() == k
