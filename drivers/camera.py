"""Camera sources: image files or a folder of them (simulated: ``labauto.synthetic.camera``).

A camera is an iterable of ``(name, image)`` pairs, ``image`` a BGR ``uint8`` array. A real
camera is a plugin that registers a ``camera`` driver with the same shape.
"""

from __future__ import annotations

from collections.abc import Iterator
from importlib import resources
from pathlib import Path

import numpy as np

from labauto.drivers.errors import DeviceError
from labauto.errors import ImageError
from labauto.imageio import read_image

#: The ``path`` that names the sample plates bundled with labauto.
SAMPLES = "samples"


def sample_plates_dir() -> Path:
    """The folder of the sample plates that ship with labauto."""
    return Path(str(resources.files("labauto") / "data" / "plates"))


class FolderCamera:
    """Serve the images of a folder (sorted by name) or a single image file.

    Parameters
    ----------
    path : str or Path
        A folder, an image file, or ``"samples"`` for the bundled sample plates.
    pattern : str
        Glob pattern of the images in a folder.
    """

    def __init__(self, path: str | Path, pattern: str = "*.png") -> None:
        self.path = sample_plates_dir() if str(path) == SAMPLES else Path(path)
        self.pattern = pattern

    def files(self) -> list[Path]:
        """The image files this camera serves, in order; raises if there are none."""
        if self.path.is_file():
            return [self.path]
        if not self.path.is_dir():
            raise DeviceError(f"{self.path}: no such image folder or file", device="camera")
        files = sorted(p for p in self.path.glob(self.pattern) if p.is_file())
        if not files:
            raise DeviceError(f"{self.path}: no images matching {self.pattern!r}", device="camera")
        return files

    def __iter__(self) -> Iterator[tuple[str, np.ndarray]]:
        for file in self.files():
            try:  # the one image reader: 16-bit and float files scaled as for detect and plate
                image = read_image(file)
            except ImageError as exc:
                raise DeviceError(str(exc), device="camera") from exc
            yield file.stem, image
