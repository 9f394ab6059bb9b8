"""Nuisance changes of a photo for ``bench_real_plates.py --perturb``: how far do its figures move?

A plate analysis tuned on two sets of photographs can follow their cameras rather than the
colonies. Each perturbation below changes something a colony count must not depend on (the
orientation, the exposure, the white balance, the compression, the sensor noise) and
``bench_real_plates.py --perturb SPEC`` scores the sets with it, so the change of the figures
shows how much of them is the pipeline's own jitter or a dependence on the camera.

``SPEC`` is ``NAME`` or ``NAME:VALUE``:

* ``rot90``: turned a quarter clockwise (the truth boxes with it);
* ``flip``: mirrored left to right (the boxes with it);
* ``gain:K``: every channel times ``K`` (exposure; 0.6 by default), clipped to 0-255;
* ``gamma:G``: ``255 (v / 255) ** G`` (a camera's tone curve; 0.7 by default);
* ``wb:B,G,R``: each channel times its factor (white balance; ``1.15,1,0.8`` by default);
* ``jpeg:Q``: encoded and decoded as JPEG of quality ``Q`` (40 by default);
* ``noise:SIGMA``: Gaussian noise of ``SIGMA`` grey levels added (4 by default; seeded).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

DEFAULTS = {
    "rot90": "",
    "flip": "",
    "gain": "0.6",
    "gamma": "0.7",
    "wb": "1.15,1,0.8",
    "jpeg": "40",
    "noise": "4",
}


@dataclass(frozen=True)
class Perturbation:
    """One nuisance change: ``name`` (a key of ``DEFAULTS``) and its ``values``."""

    name: str
    values: tuple[float, ...] = ()

    def image(self, image: np.ndarray) -> np.ndarray:
        """The photo (HxWx3 uint8) with the change applied."""
        if self.name == "rot90":
            return cv2.rotate(image, cv2.ROTATE_90_CLOCKWISE)
        if self.name == "flip":
            return cv2.flip(image, 1)
        if self.name == "jpeg":
            ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(self.values[0])])
            return cv2.imdecode(data, cv2.IMREAD_COLOR) if ok else image
        levels = image.astype(np.float32)
        if self.name == "gain":
            levels *= self.values[0]
        elif self.name == "gamma":
            levels = 255.0 * (levels / 255.0) ** self.values[0]
        elif self.name == "wb":
            levels *= np.asarray(self.values, np.float32)
        elif self.name == "noise":
            levels += np.random.default_rng(0).normal(0.0, self.values[0], levels.shape)
        return np.clip(levels + 0.5, 0, 255).astype(np.uint8)

    def boxes(self, boxes: np.ndarray, width: int, height: int) -> np.ndarray:
        """Boxes ``(x0, y0, x1, y1)`` of a ``width`` x ``height`` photo, moved with it."""
        x0, y0, x1, y1 = boxes.T
        if self.name == "rot90":  # (x, y) -> (height - y, x)
            return np.column_stack((height - y1, x0, height - y0, x1))
        if self.name == "flip":
            return np.column_stack((width - x1, y0, width - x0, y1))
        return boxes


def parse(spec: str) -> Perturbation:
    """The perturbation ``NAME`` or ``NAME:VALUE`` (module docstring).

    Raises
    ------
    ValueError
        If the name is unknown or the value is not a list of numbers.
    """
    name, _, value = spec.partition(":")
    if name not in DEFAULTS:
        raise ValueError(f"unknown perturbation {name!r}; one of {', '.join(DEFAULTS)}")
    text = value or DEFAULTS[name]
    try:
        values = tuple(map(float, text.split(","))) if text else ()
    except ValueError:
        raise ValueError(
            f"--perturb {spec!r}: the value must be numbers, comma-separated"
        ) from None
    wanted = len(DEFAULTS[name].split(",")) if DEFAULTS[name] else 0  # as many as the default
    if len(values) != wanted:
        raise ValueError(f"--perturb {spec!r}: {name} takes {wanted} number(s)")
    return Perturbation(name, values)
