"""How the compiled kernels were built: portable flags, recorded in the build and in the binary."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from labauto.vision import kernels


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
    assert set(_build.BUILT) == set(kernels.built())


def test_every_kernel_binary_carries_the_recorded_flags() -> None:
    """The compiler wrote its command line into each binary (-frecord-gcc-switches)."""
    for name in _built_or_skip():
        binary = Path(sys.modules[f"labauto.vision.kernels.{name}"].__file__).read_bytes()
        assert b"-ffp-contract=off" in binary, name
        assert b"-march=native" not in binary, name


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
