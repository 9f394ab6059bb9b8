"""A regular (non-editable) install carries everything labauto needs at run time.

The wheel is built without build isolation (setuptools and Cython come from the test environment,
see the Makefile), so the test needs no network; building it compiles the kernels.
"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.timeout(300)
def test_wheel_contains_packages_migrations_plates_and_register_map(tmp_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(tmp_path),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
        timeout=280,
    )
    (wheel,) = tmp_path.glob("labauto-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    expected = {
        "labauto/cli/main.py",
        "labauto/plugins/vision.py",
        "labauto/plugins/devices.py",
        "labauto/drivers/grbl.py",
        "labauto/drivers/analyzer_map.yaml",
        "labauto/migrations/env.py",
        "labauto/migrations/script.py.mako",
        "labauto/migrations/versions/0001_initial.py",
    }
    assert expected <= names
    assert (
        len([n for n in names if n.startswith("labauto/data/plates/") and n.endswith(".png")]) >= 3
    )
    kernels = {Path(n).name.split(".")[0] for n in names if n.startswith("labauto/vision/kernels/")}
    pyx = {p.stem for p in (ROOT / "labauto" / "vision" / "kernels").glob("*.pyx")}
    assert pyx and pyx | {"__init__"} <= kernels  # every kernel compiled into the wheel
    assert all(n.endswith((".py", ".so", ".pyd")) for n in names if "/kernels/" in n)
    assert not [n for n in names if n.split("/")[0] in ("plugins", "drivers", "migrations")]
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    assert "labauto = labauto.cli.main:main" in zipfile.ZipFile(wheel).read(entry_points).decode()
