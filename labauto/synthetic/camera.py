"""A simulated camera: serves synthetic plates from the generator, with exact truth behind them.

It lives beside the generator it draws from (not in ``labauto.drivers``): it is a source of
rendered test scenes, not a driver for a device. It has the ``Camera`` shape of
``labauto.devices``: an iterable of ``(name, image)`` pairs, ``image`` a BGR ``uint8`` array.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from labauto.synthetic.plates import generate_plate


class SimulatedCamera:
    """Serve ``count`` synthetic plates generated from consecutive seeds."""

    def __init__(self, count: int = 3, first_seed: int = 0) -> None:
        self.count = count
        self.first_seed = first_seed

    def __iter__(self) -> Iterator[tuple[str, np.ndarray]]:
        for seed in range(self.first_seed, self.first_seed + self.count):
            image, _truth = generate_plate(seed)
            yield f"simulated-{seed:04d}", image
