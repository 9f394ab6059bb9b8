"""A sample third-party labauto plugin: one implementation of every hook.

It is what an integrator would write for their own instrument: a segmenter, a classifier, an
application, a camera driver, and event hooks that record what the orchestrator reports (an
exporter to a LIMS would send them on instead).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from labauto.hookspecs import hookimpl

#: Events received through the event hooks, in order: (hook name, keyword arguments).
EVENTS: list[tuple[str, dict[str, Any]]] = []


def threshold_segmenter(image: np.ndarray, params: Any) -> Any:
    """Segment with the adaptive colour threshold and mark the result as this plugin's."""
    from labauto.vision.detector import detect

    result = detect(image, replace(params, method="color"))
    result.method = "sample-threshold"
    return result


def size_classifier(image: np.ndarray, result: Any) -> list[str]:
    """Label each object ``large`` or ``small`` by its number of contour points."""
    return ["large" if obj.n_points >= 100 else "small" for obj in result.objects]


class CountResult:
    """The result of the sample application."""

    def __init__(self, count: int) -> None:
        self.count = count

    def to_dict(self) -> dict[str, int]:
        return {"count": self.count}


def count_application(image: np.ndarray, params: Any) -> CountResult:
    """Count the DES in an image."""
    from labauto.vision.detector import DetectorParams, detect

    return CountResult(sum(o.is_des for o in detect(image, DetectorParams()).objects))


class NoiseCamera:
    """A camera that serves ``frames`` deterministic noise images."""

    def __init__(self, section: Any = None, frames: int = 2) -> None:
        self.frames = frames

    def __iter__(self):
        rng = np.random.default_rng(0)
        for index in range(self.frames):
            yield f"noise-{index}", rng.integers(0, 255, (64, 80, 3), dtype=np.uint8)


@hookimpl
def labauto_register_segmenters(register):
    register("sample-threshold", threshold_segmenter)


@hookimpl
def labauto_register_classifiers(register):
    register("sample-size", size_classifier)


@hookimpl
def labauto_register_applications(register):
    register("sample-count", count_application)


@hookimpl
def labauto_register_drivers(register):
    register("camera", "sample-noise", NoiseCamera)


@hookimpl
def labauto_detections_stored(run_id, image_id, plate, count):
    EVENTS.append(
        (
            "detections_stored",
            {"run_id": run_id, "image_id": image_id, "plate": plate, "count": count},
        )
    )


@hookimpl
def labauto_pick_finished(run_id, pick):
    EVENTS.append(("pick_finished", {"run_id": run_id, "pick": pick}))


@hookimpl
def labauto_run_finished(run_id, state, summary):
    EVENTS.append(("run_finished", {"run_id": run_id, "state": state, "summary": summary}))
