"""Points 8-11 of issue 12: bad input ends in one clear line and a non-zero exit, never a
traceback or a hang, and nothing stored is lost.

Each case runs the real command line: most in-process through ``labauto.cli.main.main`` (fast),
the ones that used to hang or blow the stack in real processes with a deadline.
"""

from __future__ import annotations

import signal
import struct
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from reliability_helpers import db_path, labauto, query, workcell_config, write_config

from labauto.cli.main import main
from labauto.drivers.camera import sample_plates_dir
from labauto.imageio import read_image

pytestmark = pytest.mark.timeout(120)

SAMPLE = sorted(sample_plates_dir().glob("*.png"))[0]

CONFIG_CASES = {
    "alias bomb": "a: &a [x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a]\n"
    "c: [*b, *b, *b, *b, *b, *b, *b, *b]\n",
    "deep nesting": "a: " + "[" * 100 + "]" * 100 + "\n",
    "unknown gantry fault": "robot:\n  simulator:\n    faults: [{kind: meteor}]\n",
    "gantry fault with a bad count": (
        "robot:\n  simulator:\n    faults: [{kind: delay, count: 0}]\n"
    ),
    "unknown analyzer fault": "analyzer:\n  simulator:\n    faults: {meteor: 1}\n",
    "NaN plate value": "plate:\n  min_colony_area_px: .nan\n",
    "negative plate value": "plate:\n  min_width_mm: -3\n",
    "plate range upside down": "plate:\n  dish_radius_range: [0.6, 0.2]\n",
    "canny_low > canny_high": "detector:\n  canny_low: 200\n  canny_high: 100\n",
    "NaN calibration point": "calibration:\n  points:\n"
    + "".join(f"    - {{pixel: [{x}, .nan], deck: [1, 2]}}\n" for x in range(4)),
    "NaN travel limit": "robot:\n  limits_x_mm: [0, .nan]\n",
    "infinite timeout": "robot:\n  timeout_s: .inf\n",
    "deposit outside the travel": "robot:\n  deposit: {x: 500, y: 10, z: -10}\n",
    "register map /etc/passwd": "analyzer:\n  register_map: /etc/passwd\n",
    "heartbeat slower than the lease": "run:\n  heartbeat_s: 60\n  lease_timeout_s: 30\n",
}

EXPECTED = {
    "alias bomb": "YAML aliases (*name) are not accepted",
    "deep nesting": "nested deeper than 32 levels",
    "unknown gantry fault": "robot.simulator.faults: unknown fault 'meteor'",
    "gantry fault with a bad count": "count: expected a value >= 1, got 0",
    "unknown analyzer fault": "analyzer.simulator.faults: unknown fault 'meteor'",
    "NaN plate value": "plate.min_colony_area_px: expected a finite number, got nan",
    "negative plate value": "plate.min_width_mm: expected a value >= 0, got -3",
    "plate range upside down": "plate.dish_radius_range: expected [low, high] with low <= high",
    "canny_low > canny_high": "detector: canny_low (200) must not exceed canny_high (100)",
    "NaN calibration point": "calibration.points.0.pixel.1: expected a finite number, got nan",
    "NaN travel limit": "robot.limits_x_mm.1: expected a finite number, got nan",
    "infinite timeout": "robot.timeout_s: expected a finite number, got inf",
    "deposit outside the travel": "deposit.x: 500 mm is outside the travel limits [0, 300] mm",
    "register map /etc/passwd": "/etc/passwd: expected a register map (a mapping), got str",
    "heartbeat slower than the lease": "heartbeat_s (60) must be less than lease_timeout_s (30)",
}


def one_error_line(err: str) -> str:
    """The single line of an error report (fails on a traceback or on several lines)."""
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith("labauto: error: "), lines[0]
    return lines[0]


@pytest.mark.parametrize("case", list(CONFIG_CASES))
def test_bad_config_is_one_clear_line(tmp_path, capsys, case):
    path = tmp_path / "bad.yaml"
    path.write_text(CONFIG_CASES[case])
    started = time.monotonic()
    assert main(["config", "show", "--config", str(path)]) == 1
    assert time.monotonic() - started < 5  # no expansion, no hang
    line = one_error_line(capsys.readouterr().err)
    assert str(path) in line and EXPECTED[case] in line, line
    assert "root:" not in line  # a register-map error does not print the file


def test_a_config_file_over_the_size_limit_is_refused(tmp_path, capsys):
    path = tmp_path / "big.yaml"
    path.write_text("# padding\n" * 120_000)  # 1.2 MB
    assert main(["config", "show", "--config", str(path)]) == 1
    assert "config file is larger than 1024 KiB" in one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize(
    ("args", "text", "expected"),
    [
        (["config", "show", "--config", "/dev/zero"], None, "is a device, FIFO or socket"),
        (["config", "show"], "analyzer:\n  register_map: /dev/zero\n", "register_map: /dev/zero"),
        (["config", "show"], "a: " + "[" * 20000 + "]" * 20000 + "\n", "nested deeper than"),
    ],
    ids=["config /dev/zero", "register_map /dev/zero", "nesting 20000 deep"],
)
def test_inputs_that_used_to_hang_or_overflow_end_in_one_line(tmp_path, args, text, expected):
    if text is not None:
        path = tmp_path / "x.yaml"
        path.write_text(text)
        args = [*args, "--config", str(path)]
    child = labauto(*args, cwd=tmp_path)
    _, err = child.communicate(timeout=30)
    assert child.returncode == 1
    assert expected in one_error_line(err)


def _png_claiming(width: int, height: int) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    body = zlib.compress(b"\0" * 16)
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", body) + chunk(b"IEND", b"")
    )


@pytest.mark.parametrize("command", ["plate", "detect"])
def test_a_png_claiming_100000_squared_pixels_is_refused_by_the_budget(tmp_path, capsys, command):
    path = tmp_path / "huge.png"
    path.write_bytes(_png_claiming(100_000, 100_000))
    assert main([command, str(path)]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert "image of 100000 x 100000 pixels is over the budget of 64 Mpixel" in line


def test_annotate_to_an_unknown_image_type_is_refused_before_the_work(tmp_path, capsys):
    target = tmp_path / "x.xyz"
    assert main(["plate", str(SAMPLE), "--annotate", str(target)]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert "x.xyz: cannot write images of type '.xyz'" in line
    assert not target.exists()


def test_12_bit_data_in_a_16_bit_png_is_scaled_not_black(tmp_path, capsys):
    eight = cv2.imread(str(SAMPLE), cv2.IMREAD_COLOR)
    twelve = np.rint(eight.astype(np.float64) * (4095 / 255)).astype(np.uint16)
    path = tmp_path / "twelve.png"
    cv2.imwrite(str(path), twelve)
    image = read_image(path)
    assert image.dtype == np.uint8 and np.abs(image.astype(int) - eight).max() <= 1
    assert main(["plate", str(SAMPLE), "--json"]) == 0
    reference = capsys.readouterr().out
    assert main(["plate", str(path), "--json"]) == 0
    import json

    counts = json.loads(capsys.readouterr().out)["counts"]
    assert counts == json.loads(reference)["counts"] and counts["authentic"] > 0


def test_a_float_tiff_gives_detect_and_plate_the_same_image(tmp_path, capsys):
    import json

    eight = cv2.imread(str(SAMPLE), cv2.IMREAD_COLOR)
    path = tmp_path / "float.tiff"
    assert cv2.imwrite(str(path), eight.astype(np.float32) / 255.0)
    assert np.array_equal(read_image(path), eight)  # one reader, one scaling
    assert main(["plate", str(path), "--json"]) == 0
    plate = json.loads(capsys.readouterr().out)
    assert plate["dish"] is not None and plate["counts"]["authentic"] > 0
    assert main(["detect", str(path), "--json"]) == 0
    assert main(["detect", str(SAMPLE), "--json"]) == 0
    out = capsys.readouterr().out
    first, second = out.split("\n}\n", 1)
    strip = lambda doc: {k: v for k, v in json.loads(doc).items() if k != "timing_ms"}  # noqa: E731
    assert strip(first + "\n}") == strip(second)


@pytest.mark.parametrize(
    "args",
    [
        ["runs", "show", "1", "--events", "99999999999999999999"],
        ["runs", "show", "99999999999999999999"],
        ["run", "--resume", "99999999999999999999"],
    ],
    ids=["--events overflow", "run id overflow", "--resume overflow"],
)
def test_numbers_too_large_for_the_database_are_usage_errors(capsys, args):
    assert main(args) == 2
    assert "is not in the range" in one_error_line(capsys.readouterr().err)


def test_an_opencv_error_is_one_line(tmp_path, capsys):
    path = tmp_path / "blur.yaml"
    path.write_text("detector:\n  blur_sigma: 1.0e9\n")
    assert main(["detect", str(SAMPLE), "--config", str(path)]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith("labauto: error: cv2.error:") and "--debug" in line


def test_runs_list_on_a_mistyped_database_creates_nothing(tmp_path, capsys):
    missing = tmp_path / "typo.db"
    path = tmp_path / "c.yaml"
    path.write_text(f"database:\n  url: sqlite:///{missing}\n")
    assert main(["runs", "list", "--config", str(path)]) == 1
    assert f"file {missing} does not exist" in one_error_line(capsys.readouterr().err)
    assert not missing.exists()


def test_an_unknown_enabled_plugin_is_named(tmp_path, capsys):
    config = workcell_config(tmp_path, plates=1, plugins={"enabled": ["nosuch", "devices"]})
    assert main(["run", "--config", str(write_config(config, tmp_path / "c.yaml"))]) == 1
    line = one_error_line(capsys.readouterr().err)
    assert "plugins.enabled: no installed plugin named 'nosuch'" in line


def test_an_unwritable_output_folder_is_found_before_the_first_plate(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    config = workcell_config(
        tmp_path, plates=1, output={"dir": str(blocker / "out"), "annotate": True}
    )
    assert main(["run", "--config", str(write_config(config, tmp_path / "c.yaml"))]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    db = db_path(config)
    assert query(db, "select state from runs") == [("failed",)]
    assert "output folder cannot be written" in query(db, "select error from runs")[0][0]
    assert query(db, "select count(*) from images") == [(0,)]  # found before plate 1
    assert query(db, "select count(*) from events where kind = 'robot.tx'") == [(0,)]


def test_sighup_stops_the_run_instead_of_leaving_it_running(tmp_path):
    config = workcell_config(
        tmp_path, plates=2, analyzer={"simulator": {"speed_factor": 2.0, "analysis_seconds": 2.0}}
    )
    config_file = write_config(config, tmp_path / "c.yaml")
    db = db_path(config)
    child = labauto("run", "--config", str(config_file), cwd=tmp_path)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                if query(db, "select 1 from picks where state = 'delivered'"):
                    break
            except Exception:
                pass
            time.sleep(0.02)
        child.send_signal(signal.SIGHUP)
        child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == 0
    assert query(db, "select state, lease_token from runs") == [("stopped", None)]
    assert Path(tmp_path).exists()
