"""The work started beside eq. 1 (``plate_objects.start_beside``) gives what the sequence gives."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from labauto.synthetic.plates import generate_plate
from labauto.vision import plate_area, plate_objects
from labauto.vision.plate import PlateParams


def _prepared(img: np.ndarray) -> tuple:
    _, copy, params, (x0, y0), usable, rim = plate_area.prepare_plate(img, PlateParams())
    roi = copy.image[y0 : y0 + usable.shape[0], x0 : x0 + usable.shape[1]]
    return roi, usable, rim, params


def test_threaded_background_and_objects_equal_the_sequence() -> None:
    # faint colonies with a dark rim (as on AGAR plate 510) and colonies at the meniscus: the
    # rim profile and the ring search both change the outcome on this plate
    img, _ = generate_plate(
        1, agar="amber", faint_fraction=1.0, faint_contrast=0.04, ring_edge=10.0, n_meniscus=3
    )
    roi, usable, rim, params = _prepared(img)
    without_rings = replace(params, find_rings=False)
    assert not np.array_equal(
        plate_objects.agar_background(roi, usable, params, rim),
        plate_objects.agar_background(roi, usable, params),
    )
    bg = plate_objects.agar_background(roi, usable, params, rim)
    assert not np.array_equal(
        plate_objects.objects_by_segmentation(roi, usable, params, bg).foreground,
        plate_objects.objects_by_segmentation(roi, usable, without_rings, bg).foreground,
    )
    assert rim is not None and params.find_rings and params.rim_band_mm > 0
    profile, circles = plate_objects.start_beside(roi, usable, rim, params)
    assert profile is not None and circles is not None
    beside_bg = plate_objects.agar_background(roi, usable, params, rim, profile)
    alone_bg = plate_objects.agar_background(roi, usable, params, rim)
    assert np.array_equal(beside_bg, alone_bg)
    beside = plate_objects.objects_by_segmentation(roi, usable, params, beside_bg, circles)
    alone = plate_objects.objects_by_segmentation(roi, usable, params, alone_bg)
    assert len(beside.contours) == len(alone.contours) > 10
    for a, b in zip(beside.contours, alone.contours, strict=True):
        assert np.array_equal(a, b)
    for name in ("d_alpha", "inside", "centroids", "foreground", "doubtful"):
        assert np.array_equal(getattr(beside, name), getattr(alone, name)), name


def test_nothing_is_started_when_the_steps_are_off() -> None:
    img, _ = generate_plate(2, agar="clear")
    _, copy, params, (x0, y0), usable, rim = plate_area.prepare_plate(
        img, PlateParams(find_rings=False, rim_band_mm=0.0)
    )
    roi = copy.image[y0 : y0 + usable.shape[0], x0 : x0 + usable.shape[1]]
    assert plate_objects.start_beside(roi, usable, rim, params) == (None, None)
