"""A regular (non-editable) install carries everything labauto needs at run time.

The wheels are built without build isolation (setuptools and Cython come from the test
environment, see the Makefile), so the tests need no network. One wheel is built with the C
compiler (the kernels compiled), one with no compiler on PATH (labauto's plain path only); each
is installed into a folder of its own and imported from there, with the kernels on and off.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PIP = (sys.executable, "-m", "pip")
COMPILERS = ("cc", "gcc", "clang", "c++", "g++", "x86_64-linux-gnu-gcc", "aarch64-linux-gnu-gcc")


def _build_wheel(out: Path, env: dict[str, str] | None = None) -> Path:
    """``pip wheel`` of this source tree into ``out`` (a copy, so the tree's own build and
    compiled kernels are not touched)."""
    source = out / "src"
    shutil.copytree(
        ROOT,
        source,
        ignore=shutil.ignore_patterns(".venv", ".git", "build", "*.so", "*.c", "*.egg-info", "out"),
    )
    done = subprocess.run(
        [*PIP, "wheel", "--no-deps", "--no-build-isolation", "-w", str(out), str(source)],
        capture_output=True,
        text=True,
        timeout=560,
        env=env,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    (wheel,) = out.glob("labauto-*.whl")
    return wheel


def _install(wheel: Path, target: Path) -> Path:
    subprocess.run(
        [*PIP, "install", "--no-deps", "--target", str(target), str(wheel)],
        check=True,
        capture_output=True,
        timeout=120,
    )
    return target


PROBE = """
import json, labauto, numpy as np
from labauto.synthetic.shapes import make_scene
from labauto.vision import kernels
result = labauto.detect(make_scene(np.random.default_rng(5))[0])
print(json.dumps({
    "file": labauto.__file__, "backend": kernels.backend(), "built": kernels.built(),
    "describe": kernels.describe(), "level": kernels.level(),
    "kernel_files": [getattr(kernels.compiled(n), "__file__", None) for n in kernels.built()],
    "objects": [[o["n_points"], o["shape"], round(o["d_alpha_median"], 6)]
                for o in result.to_dict()["objects"]],
}))
"""


def _probe(target: Path, kernels_setting: str) -> dict:
    """Import labauto from ``target`` and detect once. ``-S``: without the site hooks, so the
    development install (an editable one) is not seen; its dependencies come from purelib."""
    path = os.pathsep.join([str(target), sysconfig.get_paths()["purelib"]])
    env = {**os.environ, "PYTHONPATH": path, "LABAUTO_KERNELS": kernels_setting}
    done = subprocess.run(
        [sys.executable, "-S", "-c", PROBE],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        cwd=target,  # not the source tree
    )
    assert done.returncode == 0, done.stderr[-2000:]
    info = json.loads(done.stdout)
    assert Path(info["file"]).is_relative_to(target)
    return info


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel of a regular build (with the C compiler)."""
    return _build_wheel(tmp_path_factory.mktemp("wheel"))


@pytest.mark.timeout(600)
def test_the_wheel_imports_with_the_kernels_on_and_off(wheel: Path, tmp_path: Path) -> None:
    target = _install(wheel, tmp_path / "site")
    on, off = _probe(target, "on"), _probe(target, "off")
    assert on["backend"] == "compiled" and set(on["built"]) == {
        "edges", "ellipse_fit", "gradient", "shape",
    }  # fmt: skip
    assert all(Path(f).is_relative_to(target) for f in on["kernel_files"])
    assert "-march=native" not in on["describe"]
    assert off["backend"] == "plain" and "LABAUTO_KERNELS=off" in off["describe"]
    assert on["objects"] == off["objects"] and len(on["objects"]) > 50


@pytest.mark.timeout(600)
def test_without_a_compiler_the_install_runs_the_plain_path(tmp_path: Path) -> None:
    """``pip wheel`` with no C compiler on PATH: a wheel without kernels, which detects."""
    tools = tmp_path / "bin"  # PATH: everything on this PATH but the C compilers
    tools.mkdir()
    for folder in os.environ["PATH"].split(os.pathsep):
        for tool in Path(folder).glob("*") if Path(folder).is_dir() else ():
            compiler = tool.name in COMPILERS or tool.name.endswith(("-gcc", "-cc", "-gcc-12"))
            if not compiler and not (tools / tool.name).exists():
                (tools / tool.name).symlink_to(tool)
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "CXX", "LDSHARED")}
    env["PATH"] = str(tools)
    assert (
        shutil.which("gcc", path=env["PATH"]) is None
        and shutil.which("cc", path=env["PATH"]) is None
    )
    wheel = _build_wheel(tmp_path / "wheel", env)
    names = zipfile.ZipFile(wheel).namelist()
    assert not [n for n in names if n.endswith((".so", ".pyd"))]
    info = _probe(_install(wheel, tmp_path / "site"), "")
    assert info["backend"] == "plain" and info["built"] == []
    assert "no compiled kernels installed" in info["describe"]
    assert len(info["objects"]) > 50


@pytest.mark.timeout(600)
def test_wheel_contains_packages_migrations_plates_and_register_map(wheel: Path):
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
    assert pyx and pyx | {"__init__", "_build"} <= kernels  # every kernel compiled into the wheel
    assert all(n.endswith((".py", ".so", ".pyd")) for n in names if "/kernels/" in n)
    assert not [n for n in names if n.split("/")[0] in ("plugins", "drivers", "migrations")]
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    assert "labauto = labauto.cli.main:main" in zipfile.ZipFile(wheel).read(entry_points).decode()
