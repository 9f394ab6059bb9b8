"""The two backends: what runs where, and the same answers from both."""

from __future__ import annotations

import numpy as np

from labauto.synthetic.plates import generate_plate
from labauto.synthetic.shapes import make_scene
from labauto.vision import kernels
from labauto.vision.detector import detect
from labauto.vision.plate import analyze_plate


def test_the_plate_analysis_asks_for_no_kernel(monkeypatch) -> None:
    """So the plate, orchestrator and reliability tests cover both backends in one pass."""
    asked: list[str] = []
    compiled = kernels.compiled

    def spy(name: str):
        asked.append(name)
        return compiled(name)

    monkeypatch.setattr(kernels, "compiled", spy)
    image, _ = generate_plate(4, agar="macconkey")
    assert analyze_plate(image).colonies
    assert asked == []
    detect(image)
    assert set(asked) == set(kernels.KERNELS)  # (the spy sees the kernels detect asks for)


def test_detect_gives_the_same_objects_on_both_backends(backend: str) -> None:
    image = make_scene(np.random.default_rng(11))[0]
    found = detect(image).to_dict()["objects"]
    other = "plain" if backend == "compiled" else "compiled"
    if other == "compiled" and not kernels.built():
        return  # nothing to compare with (an install without kernels)
    kernels.use(other)
    again = detect(image).to_dict()["objects"]
    assert len(found) > 50
    assert _labels(again) == _labels(found)
    np.testing.assert_allclose(_numbers(again), _numbers(found), rtol=1e-9, atol=1e-9)


def _labels(objects: list[dict]) -> list[tuple]:
    keys = ("id", "n_points", "closed", "centroid_inside", "is_des", "shape")
    return [(*(o[k] for k in keys), o["ellipse"] is None) for o in objects]


def _numbers(objects: list[dict]) -> np.ndarray:
    """Every number of the objects (centroid, D_alpha, ellipse) in one array."""
    rows = []
    for o in objects:
        e = o["ellipse"] or {"center": [0, 0], "axes": [0, 0], "angle": 0}
        rows.append([*o["centroid"], o["d_alpha_median"], o["d_alpha_mean"], *e["center"]])
        rows[-1] += [*e["axes"], e["angle"]]
    return np.array(rows)
