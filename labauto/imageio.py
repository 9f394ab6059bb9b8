"""Reading and writing image files, with errors that name the file and what is wrong with it.

:func:`read_image` is the one reader of image files: ``labauto detect``, ``labauto plate`` and
the Python API all get the same ``uint8`` image from a file. The decoded pixels go through the
same validator as an array given directly (:func:`labauto.vision.image.as_image`); what the file
adds is the bit depth of 16-bit integer samples: a PNG's ``sBIT`` chunk says how many bits are
significant, and without it the depth is the smallest of 8, 10, 12, 14 and 16 bits that holds the
image's largest value (so 12-bit camera data in a 16-bit PNG fills 0-255 instead of reading as
black).

Before anything is decoded, the size a PNG header claims is checked against a pixel budget
(``max_pixels``), so a tiny file that claims 100000 x 100000 pixels is refused instead of
allocating gigabytes.
"""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np

from labauto.errors import ImageError
from labauto.vision.image import as_image

MAX_PIXELS = 64_000_000
"""Largest image read by default (64 Mpixel; a plate camera gives 1-20 Mpixel)."""

MAX_FILE_BYTES = 512 * 1024 * 1024
"""Largest image file read."""

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_DEPTHS = (8, 10, 12, 14, 16)


def read_image(path: str | Path, max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """Read an image file as a BGR ``uint8`` array (grey images come back 2-D).

    Parameters
    ----------
    path : str or Path
        The image file.
    max_pixels : int
        Pixel budget: larger images are refused.

    Raises
    ------
    ImageError
        If the file is missing, empty, too large, not a readable image, has no pixels, or has
        sample values that cannot be mapped to 0-255.
    """
    path = Path(path)
    if not path.exists():
        raise ImageError(f"{path}: no such image file")
    if path.is_dir():
        raise ImageError(f"{path}: is a folder, expected an image file")
    if not path.is_file():
        raise ImageError(f"{path}: is not a regular file")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise ImageError(f"{path}: file of {size} bytes is over the {MAX_FILE_BYTES} byte limit")
    data = np.fromfile(path, dtype=np.uint8)
    if data.size == 0:
        raise ImageError(f"{path}: file is empty")
    header = bytes(data[:4096])
    claimed = png_size(header)
    if claimed is not None:
        _check_budget(path, claimed[0], claimed[1], max_pixels)
    try:
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise ImageError(f"{path}: cannot decode image ({_first_line(exc)})") from None
    if image is None:
        raise ImageError(f"{path}: not a readable image (corrupt or unsupported format)")
    if image.size == 0:
        raise ImageError(f"{path}: image has no pixels")
    _check_budget(path, image.shape[1], image.shape[0], max_pixels)
    bits = sample_depth(image, png_significant_bits(header))
    try:
        return as_image(image, min_side=1, significant_bits=bits, name=str(path))
    except ValueError as exc:
        raise ImageError(str(exc)) from None


def _check_budget(path: Path, width: int, height: int, max_pixels: int) -> None:
    if width * height > max_pixels:
        raise ImageError(
            f"{path}: image of {width} x {height} pixels is over the budget of "
            f"{max_pixels / 1e6:g} Mpixel"
        )


def _first_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:200]


def png_size(header: bytes) -> tuple[int, int] | None:
    """``(width, height)`` from a PNG's IHDR chunk, or ``None`` if ``header`` is not a PNG."""
    if not header.startswith(_PNG_SIGNATURE) or header[12:16] != b"IHDR" or len(header) < 24:
        return None
    width, height = struct.unpack(">II", header[16:24])
    return width, height


def png_significant_bits(header: bytes) -> int | None:
    """The largest significant bit depth of a PNG's ``sBIT`` chunk, if it has one early on."""
    if not header.startswith(_PNG_SIGNATURE):
        return None
    offset = 8
    while offset + 8 <= len(header):
        length = struct.unpack(">I", header[offset : offset + 4])[0]
        kind = header[offset + 4 : offset + 8]
        if kind == b"sBIT":
            values = header[offset + 8 : offset + 8 + length]
            return max(values) if values else None
        if kind in (b"IDAT", b"IEND"):
            return None
        offset += 12 + length
    return None


def sample_depth(image: np.ndarray, significant_bits: int | None = None) -> int | None:
    """The bit depth of an integer image's samples (``None`` for ``uint8`` and floats).

    ``significant_bits`` (a PNG's ``sBIT``) when given, else the smallest of 8, 10, 12, 14 and 16
    bits that holds the image's largest value.
    """
    if image.dtype == np.uint8 or image.dtype.kind not in "iu":
        return None
    if significant_bits:
        return significant_bits
    high = max(int(image.max()), 0)
    return next((d for d in _DEPTHS if high < 2**d), max(16, high.bit_length()))


def check_image_target(path: str | Path) -> Path:
    """Refuse, before any work is done, a file name OpenCV cannot write an image to."""
    path = Path(path)
    suffix = path.suffix or ".png"
    try:
        ok = cv2.haveImageWriter(str(path.with_suffix(suffix)))
    except cv2.error:
        ok = False
    if not ok:
        raise ImageError(
            f"{path}: cannot write images of type {suffix!r} (use .png, .jpg, .tif or .bmp)"
        )
    return path


def write_image(path: str | Path, image: np.ndarray) -> Path:
    """Write ``image`` to ``path`` (format from the suffix), creating the folder."""
    path = check_image_target(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        ok, encoded = cv2.imencode(path.suffix or ".png", image)
    except cv2.error as exc:
        raise ImageError(f"{path}: cannot encode image ({_first_line(exc)})") from None
    if not ok:
        raise ImageError(f"{path}: cannot encode image as {path.suffix or '.png'}")
    encoded.tofile(path)
    return path
