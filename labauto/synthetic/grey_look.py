"""The look every rendered grey test scene shares: a ground to draw on, ink, blur and noise.

A scene (a marker scene, a board view, a frame of a marker sequence, a simulated camera's
capture) starts from a blank float image at the ground's grey level (:meth:`GreyLook.canvas`),
draws its own objects into it with the ink, applies its own light, and ends as a camera would
deliver it: blurred, with sensor noise, rounded to ``uint8`` (:meth:`GreyLook.develop`, which is
:func:`labauto.synthetic.markers.finish`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from labauto.synthetic.markers import finish

__all__ = ["GreyLook"]


@dataclass(frozen=True)
class GreyLook:
    """Grey levels, blur and noise of a rendered grey scene.

    Attributes
    ----------
    ground : float
        Grey level of what the scene is drawn on (paper, deck, table).
    ink : float
        Grey level of what is drawn (markers, shapes).
    blur_sigma : float
        Gaussian blur of the lens, pixels (0: none).
    noise_sigma : float
        Gaussian sensor noise, grey levels (0: none).
    """

    ground: float
    ink: float
    blur_sigma: float = 0.0
    noise_sigma: float = 0.0

    def canvas(self, size: tuple[int, int]) -> np.ndarray:
        """A float image of ``size`` (width, height) at the ground's grey level, to draw on."""
        width, height = size
        return np.full((height, width), float(self.ground))

    def develop(self, image: np.ndarray, rng: np.random.Generator | None) -> np.ndarray:
        """The drawn ``image`` blurred, with noise from ``rng``, rounded to ``uint8``."""
        return finish(image, blur_sigma=self.blur_sigma, noise_sigma=self.noise_sigma, rng=rng)
