"""The ``labauto`` command: subcommands, JSON contracts, one-line errors and exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from labauto import __version__
from labauto.cli.main import main
from labauto.drivers.camera import sample_plates_dir
from labauto.synthetic.shapes import ellipse, render, square

DETECT_OBJECT_KEYS = {
    "id", "centroid", "n_points", "closed", "d_alpha_median", "d_alpha_mean",
    "centroid_inside", "is_des", "shape", "ellipse",
}  # fmt: skip
COLONY_KEYS = {
    "id", "centroid", "class", "area_px", "d_alpha_median", "estimated_count", "contour",
}  # fmt: skip


def labauto(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "labauto.cli.main", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )


@pytest.fixture()
def scene_file(tmp_path: Path) -> Path:
    gray = render(
        [ellipse((80.4, 70.2), (40.0, 22.0), 30.0), square((220.0, 90.0), 30.0)], 320, 200
    )
    path = tmp_path / "scene.png"
    cv2.imwrite(str(path), np.dstack([gray, gray, gray]))
    return path


def test_version_and_help():
    result = labauto("--version")
    assert result.returncode == 0 and __version__ in result.stdout
    for command in ("detect", "plate", "run", "runs", "plugins", "db", "devices"):
        result = labauto(command, "--help")
        assert result.returncode == 0 and "Usage: labauto" in result.stdout, command


def test_detect_json_contract(scene_file, capsys):
    assert main(["detect", str(scene_file), "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert {"width", "height", "method", "timing_ms", "objects"} <= set(document)
    assert (document["width"], document["height"], document["method"]) == (320, 200, "canny")
    assert all(set(obj) == DETECT_OBJECT_KEYS for obj in document["objects"])
    des = [obj for obj in document["objects"] if obj["shape"] == "ellipse"]
    assert len(des) == 1 and des[0]["is_des"]
    ellipse_json = des[0]["ellipse"]
    assert ellipse_json["center"] == pytest.approx([80.4, 70.2], abs=0.1)
    assert ellipse_json["axes"] == pytest.approx([40.0, 22.0], abs=0.2)
    assert ellipse_json["angle"] == pytest.approx(30.0, abs=0.5)


def test_detect_color_method(scene_file, capsys):
    assert main(["detect", str(scene_file), "--method", "color", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["method"] == "color"


def test_python_api_gives_the_same_json_as_the_cli(scene_file, capsys):
    import labauto

    assert main(["plate", str(next(sample_plates_dir().glob("*.png"))), "--json"]) == 0
    cli_document = json.loads(capsys.readouterr().out)
    api_document = labauto.analyze_plate(next(sample_plates_dir().glob("*.png"))).to_dict()
    cli_document.pop("timing_ms"), api_document.pop("timing_ms")
    assert json.loads(json.dumps(api_document)) == cli_document


def test_plate_json_contract(tmp_path, capsys):
    plate = next(sample_plates_dir().glob("*.png"))
    annotated = tmp_path / "annotated.png"
    assert main(["plate", str(plate), "--json", "--annotate", str(annotated)]) == 0
    document = json.loads(capsys.readouterr().out)
    assert {"width", "height", "timing_ms", "dish", "colonies", "counts"} <= set(document)
    assert set(document["counts"]) == {"authentic", "merged", "mixed", "colonies_estimate"}
    assert all(set(colony) >= COLONY_KEYS for colony in document["colonies"])
    assert document["counts"]["authentic"] == sum(
        c["class"] == "authentic" for c in document["colonies"]
    )
    assert cv2.imread(str(annotated)).shape == (1024, 1280, 3)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "file is empty"),
        (b"this is not a png", "not a readable image (corrupt or unsupported format)"),
        (None, "no such image file"),
    ],
)
def test_bad_image_is_one_line_on_stderr_with_exit_1(tmp_path, content, message):
    path = tmp_path / "bad.png"
    if content is not None:
        path.write_bytes(content)
    result = labauto("detect", str(path))
    assert result.returncode == 1
    assert result.stderr.strip() == f"labauto: error: {path}: {message}"
    assert "Traceback" not in result.stderr


def test_debug_shows_the_traceback(tmp_path):
    path = tmp_path / "bad.png"
    path.write_bytes(b"garbage")
    result = labauto("--debug", "detect", str(path))
    assert result.returncode != 0 and "Traceback" in result.stderr


def test_wrong_image_shape_is_refused(tmp_path, capsys):
    path = tmp_path / "tiny.png"
    cv2.imwrite(str(path), np.zeros((1, 1, 3), np.uint8))
    assert main(["plate", str(path)]) == 1
    assert "labauto: error:" in capsys.readouterr().err


def test_bad_config_names_file_and_key(tmp_path, scene_file, capsys):
    config = tmp_path / "x.yaml"
    config.write_text("robot:\n  port: 3\n")
    assert main(["detect", str(scene_file), "--config", str(config)]) == 1
    assert capsys.readouterr().err.strip() == (
        f"labauto: error: {config}: robot.port: expected a string, got 3"
    )


def test_usage_error_exits_2(capsys):
    assert main(["detect"]) == 2
    assert "Missing argument" in capsys.readouterr().err


def test_plugins_lists_builtins_and_reports_the_broken_one(capsys):
    assert main(["plugins", "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    names = {p["name"]: p for p in document["plugins"]}
    assert {"vision", "plate", "devices"} <= set(names)
    assert names["vision"]["source"] == "builtin" and names["vision"]["version"] == __version__
    assert "labauto_register_segmenters" in names["vision"]["hooks"]
    assert {"canny", "color"} <= set(document["segmenters"])
    assert "robot:grbl" in document["drivers"]
    assert "sample" in names  # the sample third-party plugin, through its entry point
    assert [f["name"] for f in document["failed"]] == ["broken"]


def test_db_upgrade_creates_the_schema(tmp_path, monkeypatch, capsys):
    db = tmp_path / "fresh.db"
    monkeypatch.setenv("LABAUTO_DATABASE_URL", f"sqlite:///{db}")
    assert main(["db", "upgrade"]) == 0
    import sqlite3

    tables = {
        row[0]
        for row in sqlite3.connect(db).execute(
            "select name from sqlite_master where type = 'table'"
        )
    }
    assert {
        "plates",
        "images",
        "runs",
        "detections",
        "colonies",
        "picks",
        "analyzer_results",
        "events",
        "alembic_version",
    } <= tables


def test_devices_check_simulated_workcell_answers(capsys):
    assert main(["devices", "check", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["robot"]["ok"] and report["robot"]["detail"]["firmware"] == "1.1h"
    assert report["analyzer"]["ok"] and report["analyzer"]["detail"]["state"] == "idle"


def test_devices_check_fails_when_a_device_does_not_answer(tmp_path, capsys):
    config = tmp_path / "hw.yaml"
    config.write_text("robot:\n  simulate: false\n  port: /dev/labauto-no-such-port\n")
    assert main(["devices", "check", "--config", str(config)]) == 1
    captured = capsys.readouterr()
    assert "robot: NO ANSWER" in captured.out and "analyzer: ok" in captured.out
    assert "labauto: error: robot did not answer" in captured.err


def test_config_show_prints_every_default_and_reads_back_the_same(tmp_path, capsys):
    assert main(["config", "show"]) == 0
    full = capsys.readouterr().out
    document = yaml.safe_load(full)
    assert document["detector"]["des_threshold_deg"] > 0
    assert document["plate"]["detector"]["method"] == "color"
    assert document["robot"]["simulate"] is True
    path = tmp_path / "full.yaml"
    path.write_text(full)
    assert main(["config", "show", "--config", str(path)]) == 0
    assert capsys.readouterr().out == full


def test_faults_from_the_config_reach_the_simulated_devices(tmp_path, capsys):
    config = tmp_path / "faulty.yaml"
    config.write_text(
        "robot:\n  timeout_s: 0.3\n  simulator:\n    faults: [{kind: no_reply, count: 5}]\n"
        "analyzer:\n  simulator:\n    faults: {busy: null}\n"
    )
    assert main(["devices", "check", "--config", str(config), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert not report["robot"]["ok"] and "DeviceTimeout" in report["robot"]["detail"]
    assert report["analyzer"]["ok"]  # it answers, and says it is busy
    assert report["analyzer"]["detail"]["state"] == "busy"
