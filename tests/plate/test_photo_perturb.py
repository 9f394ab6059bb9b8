"""The benchmark's nuisance changes (benchmarks/photo_perturb.py) move the truth with the photo."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from bench_real_plates import shifted
from photo_perturb import parse


@pytest.mark.parametrize("spec", ["rot90", "flip"])
def test_boxes_move_with_the_photo(spec: str) -> None:
    # a bright box on a dark photo, not square and off centre: after the change the box
    # given for it covers exactly the bright pixels
    photo = np.zeros((60, 90, 3), np.uint8)
    photo[10:20, 50:80] = 255  # rows 10-19, columns 50-79: box (50, 10, 80, 20)
    change = parse(spec)
    moved = change.image(photo)
    (x0, y0, x1, y1) = change.boxes(np.array([[50.0, 10.0, 80.0, 20.0]]), 90, 60)[0]
    ys, xs = np.nonzero(moved[..., 0])
    assert (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1) == (x0, y0, x1, y1)


def test_a_shifted_photo_keeps_its_boxes_on_the_plate() -> None:
    # the benchmark's --shifts: the photo cut at its top and left, the box moved with it
    photo = np.zeros((60, 90, 3), np.uint8)
    photo[10:20, 50:80] = 255
    boxes = np.array([[50.0, 10.0, 80.0, 20.0]])
    same, kept = shifted(photo, boxes, 0)
    assert same is photo and kept is boxes
    moved, (moved_box,) = shifted(photo, boxes, 3)
    assert moved.shape == (57, 87, 3)
    ys, xs = np.nonzero(moved[..., 0])
    assert (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1) == tuple(moved_box)


def test_photometric_changes_keep_boxes_and_change_levels() -> None:
    photo = np.full((8, 8, 3), 100, np.uint8)
    boxes = np.array([[1.0, 2.0, 3.0, 4.0]])
    assert parse("gain").image(photo)[0, 0].tolist() == [60, 60, 60]
    assert parse("wb:1,1,2").image(photo)[0, 0].tolist() == [100, 100, 200]
    assert parse("gamma:1").image(photo)[0, 0].tolist() == [100, 100, 100]
    assert np.array_equal(parse("noise").boxes(boxes, 8, 8), boxes)


@pytest.mark.parametrize("spec", ["blur", "wb:1,1", "gain:x", "rot90:2"])
def test_a_wrong_perturbation_is_named(spec: str) -> None:
    with pytest.raises(ValueError, match="perturb"):
        parse(spec)
