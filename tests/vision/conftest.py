"""Fixtures for the detector tests (helpers live in vision_helpers.py)."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240607)


@pytest.fixture(autouse=True)
def _every_backend(backend: str) -> str:
    """Every vision test runs on both backends (see tests/conftest.py)."""
    return backend
