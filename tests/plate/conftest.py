"""Shared plates for the plate tests: generated once per session, with exact ground truth."""

from __future__ import annotations

import numpy as np
import pytest

from labauto.synthetic.plates import PlateTruth, generate_plate

#: (seed, agar) of the fixed test set: every agar twice, dark and light stages mixed.
PLATE_SET = (
    (0, "amber"),
    (1, "red_blood"),
    (2, "chocolate"),
    (3, "clear"),
    (4, "macconkey"),
    (5, "chromogenic"),
    (6, "amber"),
    (7, "red_blood"),
    (8, "chocolate"),
    (9, "clear"),
    (10, "macconkey"),
    (11, "chromogenic"),
)


@pytest.fixture(scope="session")
def plates() -> list[tuple[np.ndarray, PlateTruth]]:
    """The fixed set of generated plates (image, truth)."""
    return [generate_plate(seed, agar=agar) for seed, agar in PLATE_SET]
