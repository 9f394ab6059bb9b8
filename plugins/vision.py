"""Built-in plugin: the paper's detector as segmenters and classifiers.

Segmenters ``canny`` and ``color`` are the two contour methods of section 3.1; classifiers
``shape`` (the harmonic-analysis label of section 3.2) and ``des`` (DES or not, section 3.2).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from labauto.hookspecs import hookimpl
from labauto.vision.detector import DetectionResult, DetectorParams, detect


def _segmenter(method: str):
    def segment(image: np.ndarray, params: DetectorParams) -> DetectionResult:
        return detect(image, replace(params, method=method))

    segment.__doc__ = f"Detect objects with the {method!r} contour method of the paper."
    return segment


def shape_labels(image: np.ndarray, result: DetectionResult) -> list[str]:
    """The harmonic-analysis shape label of every object."""
    return [obj.shape for obj in result.objects]


def des_labels(image: np.ndarray, result: DetectionResult) -> list[str]:
    """``"des"`` for a deformed elliptic shape, ``"artefact"`` otherwise."""
    return ["des" if obj.is_des else "artefact" for obj in result.objects]


@hookimpl
def labauto_register_segmenters(register: Any) -> None:
    register("canny", _segmenter("canny"))
    register("color", _segmenter("color"))


@hookimpl
def labauto_register_classifiers(register: Any) -> None:
    register("shape", shape_labels)
    register("des", des_labels)
