"""Reading images from disk with errors that name the file and what is wrong with it."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from labauto.errors import ImageError


def read_image(path: str | Path) -> np.ndarray:
    """Read an image file as a BGR ``uint8`` array (grey images come back 2-D).

    Raises
    ------
    ImageError
        If the file is missing, empty, not a readable image, or has no pixels.
    """
    path = Path(path)
    if not path.exists():
        raise ImageError(f"{path}: no such image file")
    if path.is_dir():
        raise ImageError(f"{path}: is a folder, expected an image file")
    data = np.fromfile(path, dtype=np.uint8)
    if data.size == 0:
        raise ImageError(f"{path}: file is empty")
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ImageError(f"{path}: not a readable image (corrupt or unsupported format)")
    if image.size == 0:
        raise ImageError(f"{path}: image has no pixels")
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return image


def write_image(path: str | Path, image: np.ndarray) -> Path:
    """Write ``image`` to ``path`` (format from the suffix), creating the folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, encoded = cv2.imencode(path.suffix or ".png", image)
    if not ok:
        raise ImageError(f"{path}: cannot encode image as {path.suffix or '.png'}")
    encoded.tofile(path)
    return path
