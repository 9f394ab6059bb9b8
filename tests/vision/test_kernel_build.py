"""How the compiled kernels were built: portable flags, recorded in the build and in the binary."""

from __future__ import annotations

import importlib
import os
import platform
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from labauto.synthetic.shapes import make_scene
from labauto.vision import kernels
from labauto.vision.edges import _REMOVABLE, canny_edges


def _built_or_skip() -> tuple[str, ...]:
    if not kernels.built():
        pytest.skip("no compiled kernels are built in this install")
    return kernels.built()


def test_the_build_records_portable_flags() -> None:
    _built_or_skip()
    from labauto.vision.kernels import _build

    flags = kernels.build_flags()
    assert flags == _build.COMPILE_ARGS and "-ffp-contract=off" in flags
    assert "-march=native" not in flags
    if not os.environ.get("LABAUTO_MARCH"):
        assert not [f for f in flags if f.startswith(("-march", "-mcpu", "-mtune"))]
    assert set(kernels.KERNELS) <= set(_build.BUILT)
    for level, _march in _build.LEVELS:
        assert {f"{level}.{name}" for name in kernels.KERNELS} <= set(_build.BUILT)


def _targets(module: str) -> set[str]:
    """The -march targets the compiler recorded in a kernel's binary, and its flags' presence."""
    binary = Path(importlib.import_module(module).__file__).read_bytes()
    assert b"-ffp-contract=off" in binary, module  # the recorded command line is there
    return {m.decode() for m in re.findall(rb"-march=([\w.-]+)", binary)}


def test_every_kernel_binary_carries_the_recorded_flags() -> None:
    """The compiler wrote its command line into each binary (-frecord-gcc-switches)."""
    from labauto.vision.kernels import _build

    generic = {"x86-64"} if platform.machine().lower() in ("x86_64", "amd64") else set()
    for name in _built_or_skip():
        targets = _targets(f"labauto.vision.kernels.{name}")
        assert "native" not in targets, name
        if not os.environ.get("LABAUTO_MARCH"):
            assert targets <= generic, (name, targets)  # the compiler's own default only
        for level, march in _build.LEVELS:
            wide = _targets(f"labauto.vision.kernels.{level}.{name}")
            assert march in wide and "native" not in wide, (name, wide)


def test_the_kernels_loaded_are_those_for_this_cpu() -> None:
    _built_or_skip()
    from labauto.vision.kernels import _build, _cpu

    wide = bool(_build.LEVELS) and _cpu.x86_64_v3()
    assert kernels.level() == ("v3" if wide else "generic")
    package = "labauto.vision.kernels.v3" if wide else "labauto.vision.kernels"
    kernels.use("compiled")  # (the backend fixture puts it back)
    assert all(kernels.compiled(n).__name__ == f"{package}.{n}" for n in kernels.KERNELS)


def test_the_generic_and_the_wide_builds_give_the_same_results() -> None:
    """One wheel, any x86-64 CPU: the SSE2 and the AVX2 builds agree bit for bit."""
    from labauto.vision.kernels import _build, _cpu

    if not (_built_or_skip() and _build.LEVELS and _cpu.x86_64_v3()):
        pytest.skip("no wider build, or this CPU cannot run it")
    image = make_scene(np.random.default_rng(3))[0]
    results = []
    for package in ("labauto.vision.kernels", "labauto.vision.kernels.v3"):
        gradient = importlib.import_module(f"{package}.gradient")
        shape = importlib.import_module(f"{package}.shape")
        fit = importlib.import_module(f"{package}.ellipse_fit")
        gx, gy = np.empty(image.shape[:2], np.int16), np.empty(image.shape[:2], np.int16)
        gradient.max_channel_sobel(image, gx, gy, 2, 54)
        edge_map = canny_edges(gx, gy, 40.0, 90.0)
        link = importlib.import_module(f"{package}.edges").link
        removable = np.ascontiguousarray(_REMOVABLE, np.uint8)
        work = np.zeros((edge_map.shape[0] + 2, edge_map.shape[1] + 2), np.uint8)
        points, offsets, grads, closed = link(edge_map, work, removable, 2, 8, -1, gx, gy, True)
        k = len(offsets) - 1
        measured = shape.measure_contours(
            points, offsets, 3, np.ones(k, np.uint8), np.zeros((k, 2)), False, 6.0, 8, 8
        )
        params = np.empty((k, 5))
        out = (np.empty(k, np.int32), np.zeros(k), np.zeros(k, np.int32), np.zeros(k, np.uint8))
        fit.fit_ellipses(points, offsets.astype(np.intp), np.arange(k, dtype=np.intp), params,
                         *out, True, 20, 1e-9)  # fmt: skip
        results.append([gx, gy, points, grads, closed, *measured, params, *out])
    for generic, wide in zip(*results, strict=True):
        np.testing.assert_array_equal(generic, wide)


@pytest.mark.parametrize(
    ("setting", "expected"),
    [("off", "plain"), ("", "compiled"), ("auto", "compiled"), ("on", "compiled")],
)
def test_labauto_kernels_chooses_the_backend(setting: str, expected: str) -> None:
    _built_or_skip()
    done = subprocess.run(
        [sys.executable, "-c", "from labauto.vision import kernels; print(kernels.backend())"],
        env={**os.environ, "LABAUTO_KERNELS": setting},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.stdout.strip() == expected, done.stderr


def test_a_bad_labauto_kernels_is_named() -> None:
    done = subprocess.run(
        [sys.executable, "-c", "from labauto.vision import kernels; kernels.backend()"],
        env={**os.environ, "LABAUTO_KERNELS": "fast"},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode != 0 and "LABAUTO_KERNELS must be on, off or auto" in done.stderr


@pytest.mark.parametrize(("setting", "words"), [("off", "plain numpy/OpenCV"), ("", "compiled")])
def test_version_says_which_backend_runs(setting: str, words: str) -> None:
    _built_or_skip()
    labauto = Path(sys.executable).with_name("labauto")
    done = subprocess.run(
        [str(labauto), "--version"],
        env={**os.environ, "LABAUTO_KERNELS": setting},
        capture_output=True,
        text=True,
        timeout=60,
    )
    first, second = done.stdout.splitlines()
    assert first.startswith("labauto, version ")
    assert second.startswith("vision backend: ") and words in second


def test_use_refuses_an_unknown_backend() -> None:
    with pytest.raises(ValueError, match="backend must be one of"):
        kernels.use("fast")
