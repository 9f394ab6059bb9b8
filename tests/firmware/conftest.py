"""Fixtures for the tests against the real GRBL 1.1h firmware (grbl-sim, built for the host).

The firmware is compiled once per source version from ``../shared/firmware/grbl`` (or
``$LABAUTO_GRBL_SOURCE``) into pytest's cache folder, a scratch folder outside the package.
Without the sources (a user's machine) every test here is skipped with the reason; in CI
(``CI`` set) missing sources or a failed build are errors, never skips.

grbl-sim runs the firmware in real time and keeps one CPU core busy while it runs, so a module
shares one firmware process where it can, and the moves are short.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from firmware_bridge import FIRMWARE_DIR, FirmwareBridge, build_grbl_sim, make_eeprom, source_digest


def _source() -> Path:
    return Path(os.environ.get("LABAUTO_GRBL_SOURCE", FIRMWARE_DIR))


def _unavailable(reason: str) -> None:
    if os.environ.get("CI"):
        pytest.fail(f"GRBL firmware tests cannot run in CI: {reason}", pytrace=False)
    pytest.skip(reason)


@pytest.fixture(scope="session")
def grbl_sim_exe(request: pytest.FixtureRequest) -> Path:
    """The grbl-sim executable, built in pytest's cache folder if not built yet."""
    source = _source()
    if not (source / "grbl" / "grbl-sim" / "Makefile").is_file():
        _unavailable(f"no GRBL firmware sources at {source} (see ../shared/firmware/README.md)")
    for tool in ("make", "cc", "stdbuf"):
        if shutil.which(tool) is None:
            _unavailable(f"building/running grbl-sim needs {tool!r}, which is not installed")
    name = f"grbl-sim-{source_digest(source)}"
    cache = getattr(request.config, "cache", None)  # absent with -p no:cacheprovider
    scratch = Path(cache.mkdir(name)) if cache is not None else _scratch(request, name)
    try:
        return build_grbl_sim(source, scratch)
    except RuntimeError as exc:
        pytest.fail(str(exc), pytrace=False)


def _scratch(request: pytest.FixtureRequest, name: str) -> Path:
    factory: pytest.TempPathFactory = request.getfixturevalue("tmp_path_factory")
    return factory.mktemp(name)


@pytest.fixture(scope="session")
def eeprom(grbl_sim_exe: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An EEPROM file holding :data:`firmware_bridge.TEST_SETTINGS`."""
    return make_eeprom(grbl_sim_exe, tmp_path_factory.mktemp("grbl-eeprom"))


@pytest.fixture(scope="module")
def firmware(grbl_sim_exe: Path, eeprom: Path) -> Iterator[FirmwareBridge]:
    """One firmware process for a whole module, started once (no restart on open)."""
    with FirmwareBridge(grbl_sim_exe, eeprom) as bridge:
        yield bridge
