"""labauto.vision.median: np.median's value from one partition."""

from __future__ import annotations

import numpy as np
import pytest

from labauto.vision.median import median


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.uint8, np.int32])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 7, 10, 999, 1000, 100_001, 100_000])
def test_same_value_as_numpy(dtype: type, n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(3):
        values = rng.gamma(2.0, 10.0, size=n).astype(dtype)
        assert median(values) == float(np.median(values))


def test_ties_and_input_left_alone() -> None:
    values = np.array([5, 1, 5, 5, 2, 9], np.float32)
    before = values.copy()
    assert median(values) == 5.0
    assert np.array_equal(values, before)
    assert median(np.array([1.0, 2.0], np.float32)) == 1.5


@pytest.mark.parametrize("bad", [np.zeros(0), np.zeros((3, 3))])
def test_refuses_empty_or_2d(bad: np.ndarray) -> None:
    with pytest.raises(ValueError, match="non-empty 1-D"):
        median(bad)
