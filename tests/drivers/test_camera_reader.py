"""The folder camera reads through labauto's one image reader (16-bit files scaled, not black)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from labauto.drivers.camera import FolderCamera
from labauto.drivers.errors import DeviceError


def test_a_12_bit_png_in_a_run_reads_like_its_8_bit_twin(tmp_path):
    rng = np.random.default_rng(0)
    eight = rng.integers(0, 256, (80, 96, 3), dtype=np.uint8)
    twelve = np.rint(eight.astype(np.float64) * (4095 / 255)).astype(np.uint16)
    assert cv2.imwrite(str(tmp_path / "a.png"), eight)
    assert cv2.imwrite(str(tmp_path / "b.png"), twelve)
    (_, first), (_, second) = list(FolderCamera(tmp_path, "*.png"))
    assert second.dtype == np.uint8
    assert np.abs(first.astype(int) - second.astype(int)).max() <= 1


def test_a_corrupt_file_is_one_device_error_naming_it(tmp_path):
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(DeviceError, match=r"bad\.png"):
        list(FolderCamera(tmp_path, "*.png"))
