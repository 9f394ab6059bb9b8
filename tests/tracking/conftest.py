"""Rendered sequences for the tracking tests (rendered once per session; helpers in
tracking_helpers.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from labauto.synthetic.marker_sequences import SequenceSpec, render_sequence

#: A 3 x 4 board swinging partly out of an 800 x 600 view and back, tilting up to 30 degrees,
#: with lens distortion, motion blur, drifting uneven light, noise and an occluding bar.
HARD = SequenceSpec(
    rows=3,
    cols=4,
    width=800,
    height=600,
    focal_px=900.0,
    distance_mm=450.0,
    amplitude_mm=(110.0, 50.0),
    period_frames=80.0,
    motion_blur=True,
    exposure=0.25,
    occluder=True,
    noise_sigma=2.0,
)


@pytest.fixture(scope="session")
def hard_sequence():
    return list(render_sequence(HARD, 80, np.random.default_rng(15)))


@pytest.fixture(scope="session")
def still_sequence():
    """The same board, slower, no blur and no occluder: for the fitted-centre accuracy."""
    spec = replace(
        HARD, amplitude_mm=(40.0, 20.0), period_frames=200.0, motion_blur=False, occluder=False
    )
    return spec, list(render_sequence(spec, 16, np.random.default_rng(16)))


@pytest.fixture(scope="session")
def hard_spec() -> SequenceSpec:
    return HARD
