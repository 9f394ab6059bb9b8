"""Config files are validated when loaded, with errors naming file, key path and expectation."""

from __future__ import annotations

from pathlib import Path

import pytest

from labauto.config import ENV_OVERRIDES, detector_params, load_config
from labauto.errors import ConfigError

CONFIGS = sorted(Path(__file__).resolve().parents[2].joinpath("configs").glob("*.yaml"))


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "x.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_shipped_configs_are_valid(path):
    config = load_config(path, environ={})
    assert config.calibration.max_residual_mm > 0


def test_defaults_describe_a_simulated_workcell():
    config = load_config(None, environ={})
    assert config.robot.simulate and config.analyzer.simulate
    assert config.database.url.startswith("sqlite:///")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("robot:\n  port: 3\n", "x.yaml: robot.port: expected a string, got 3"),
        ("robot:\n  baudrate: -5\n", "robot.baudrate: expected a value > 0, got -5"),
        ("robot:\n  speed: 3\n", "robot.speed: unknown key"),
        ("colour: red\n", "colour: unknown key"),
        ("analyzer:\n  transport: udp\n", "analyzer.transport: expected 'tcp' or 'rtu', got 'udp'"),
        ("analyzer:\n  port: 70000\n", "analyzer.port: expected a value <= 65535, got 70000"),
        ("robot:\n  limits_x_mm: [10, 5]\n", "limits_x_mm: expected [min, max] with min < max"),
        ("calibration:\n  points: []\n", "calibration.points: expected at least 4 items, got 0"),
        ("detector:\n  canny_low: -1\n", "detector.canny_low: expected a value >= 0, got -1"),
        ("detector:\n  bogus: 1\n", "detector.bogus: unknown key"),
        ("detector:\n  statistic: mode\n", "detector.statistic: expected 'median' or 'mean'"),
        ("picking:\n  order: random\n", "picking.order: expected 'largest'"),
        ("plate:\n  detector:\n    bogus: 1\n", "plate.detector.bogus: unknown key"),
        ("plate:\n  min_width_mm: -5\n", "plate.min_width_mm: expected a value >= 0, got -5"),
        ("analyzer:\n  unit: 0\n", "analyzer.unit: expected a value >= 1, got 0"),
        ("analyzer:\n  parity: X\n", "analyzer.parity: expected 'N', 'E' or 'O'"),
        (
            "plate:\n  region: [1, 2]\n",
            "plate.region: expected one of: tuple[float, float, float]; "
            "tuple[tuple[float, float], ...]",
        ),
        ("- a\n- b\n", "expected a mapping of sections, got list"),
        ("robot: [1\n", "not valid YAML at line 2: expected ',' or ']'"),
    ],
)
def test_invalid_values_name_file_key_and_expectation(tmp_path, text, message):
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, text), environ={})
    assert message in str(info.value)
    assert str(tmp_path / "x.yaml") in str(info.value)


def test_missing_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match=r"nope\.yaml: config file not found"):
        load_config(tmp_path / "nope.yaml")


def test_environment_overrides_database_and_ports(tmp_path):
    environ = {
        "LABAUTO_DATABASE_URL": "sqlite:////tmp/other.db",
        "LABAUTO_ROBOT_PORT": "socket://127.0.0.1:2000",
        "LABAUTO_ANALYZER_HOST": "10.0.0.5",
        "LABAUTO_ANALYZER_PORT": "5020",
        "LABAUTO_ANALYZER_SERIAL_PORT": "/dev/ttyS3",
    }
    assert set(environ) == set(ENV_OVERRIDES)
    config = load_config(write(tmp_path, "robot:\n  port: /dev/ttyUSB0\n"), environ=environ)
    assert config.database.url == "sqlite:////tmp/other.db"
    assert config.robot.port == "socket://127.0.0.1:2000"
    assert (config.analyzer.host, config.analyzer.port) == ("10.0.0.5", 5020)
    assert config.analyzer.serial_port == "/dev/ttyS3"


def test_bad_environment_override_names_the_variable(tmp_path):
    with pytest.raises(ConfigError, match="LABAUTO_ANALYZER_PORT from the environment"):
        load_config(None, environ={"LABAUTO_ANALYZER_PORT": "abc"})


def test_detector_section_becomes_detector_params(tmp_path):
    config = load_config(
        write(tmp_path, "detector:\n  canny_low: 12\n  fit_ellipses: false\n"), environ={}
    )
    params = detector_params(config)
    assert params.canny_low == 12 and params.fit_ellipses is False
