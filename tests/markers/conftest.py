"""Scenes of the paper's marker experiment, rendered once per test session."""

from __future__ import annotations

import numpy as np
import pytest

from labauto.synthetic.marker_scenes import marker_scene


@pytest.fixture(scope="session")
def noisy_scenes():
    """Two scenes: 40 markers (tilt <= 60 deg), 40 rectangles, 50 artefacts, blur 1, noise 2."""
    return [marker_scene(np.random.default_rng(seed)) for seed in (11, 12)]


@pytest.fixture(scope="session")
def clean_scene():
    """One noise-free scene (blur 1, even light)."""
    return marker_scene(np.random.default_rng(13), noise_sigma=0.0, light_gain=(1.0, 1.0))
