"""The Python API: ``labauto.detect`` and ``labauto.analyze_plate``.

Both accept an image as a ``numpy`` array (BGR or grey, as OpenCV gives) or a path, and return a
result whose ``to_dict()`` is exactly the JSON that ``labauto detect --json`` and
``labauto plate --json`` print. Segmenters and applications come from the plugins, so a
third-party segmenter is used by name: ``labauto.detect(image, method="my-segmenter")``.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np

from labauto.imageio import read_image
from labauto.plugin_manager import Plugins, load_plugins


@functools.lru_cache(maxsize=1)
def default_plugins() -> Plugins:
    """The plugins every API call uses unless given its own (loaded once per process)."""
    return load_plugins()


def _as_image(image: np.ndarray | str | Path) -> np.ndarray:
    return read_image(image) if isinstance(image, str | Path) else image


def detect(
    image: np.ndarray | str | Path,
    method: str = "canny",
    *,
    plugins: Plugins | None = None,
    **params: Any,
):
    """Detect objects and deformed elliptic shapes (DES) in an image.

    Parameters
    ----------
    image : ndarray or path
        BGR (H, W, 3) or grey (H, W) image, or the path of an image file.
    method : str
        The segmenter: ``"canny"`` (colour Canny) or ``"color"`` (adaptive colour segmentation),
        or one registered by a plugin.
    plugins : Plugins, optional
        Use these plugins instead of the default ones.
    **params
        Detector parameters (fields of ``labauto.vision.detector.DetectorParams``).

    Returns
    -------
    DetectionResult
        The objects with their shape angle, DES flag, shape label and ellipse; ``to_dict()``
        gives the ``labauto detect --json`` document.
    """
    from labauto.vision.detector import DetectorParams

    segmenter = (plugins or default_plugins()).registry.get("segmenters", method)
    return segmenter(_as_image(image), DetectorParams(method=method, **params))


def analyze_plate(
    image: np.ndarray | str | Path,
    *,
    plugins: Plugins | None = None,
    **params: Any,
):
    """Analyse a petri-dish image: authentic, merged and mixed colonies (paper, section 4.1).

    Parameters
    ----------
    image : ndarray or path
        BGR (H, W, 3) image of a plate, or the path of an image file.
    plugins : Plugins, optional
        Use these plugins instead of the default ones.
    **params
        Plate-analysis parameters (fields of ``labauto.vision.plate.PlateParams``).

    Returns
    -------
    PlateResult
        The colonies and counts; ``to_dict()`` gives the ``labauto plate --json`` document.
    """
    from labauto.vision.plate import PlateParams

    application = (plugins or default_plugins()).registry.get("applications", "plate")
    return application(_as_image(image), PlateParams(**params))


def detect_markers(image: np.ndarray | str | Path, **options: Any):
    """Find the coded markers in an image (the paper's section 4.2).

    Parameters
    ----------
    image : ndarray or path
        BGR (H, W, 3) or grey (H, W) image, or the path of an image file.
    **options
        Fields of ``labauto.vision.markers.MarkerParams``.

    Returns
    -------
    list of Marker
        Sorted by id; ``Marker.to_dict()`` gives one entry of ``labauto markers detect --json``.
    """
    from labauto.vision.markers import detect_markers as _detect_markers

    return _detect_markers(_as_image(image), **options)
