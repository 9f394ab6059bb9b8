"""The hook specifications of labauto's plugin system (pluggy project name ``"labauto"``).

Plugins extend labauto in five families. Registration hooks are callback style, as in llm: the
hook receives a ``register`` function and calls it once per thing it provides, so one plugin can
provide several segmenters, drivers and so on::

    from labauto.hookspecs import hookimpl

    @hookimpl
    def labauto_register_segmenters(register):
        register("my-threshold", my_segmenter)

Every hook is called with keyword arguments only (pluggy's rule). The families:

* segmentation: ``labauto_register_segmenters`` — a segmenter turns an image into detected
  objects: ``segmenter(image, params) -> DetectionResult`` (``labauto.vision.detector``).
* classification: ``labauto_register_classifiers`` — a classifier labels detected objects:
  ``classifier(image, result) -> list[str]``, one label per object of ``result``.
* application: ``labauto_register_applications`` — an application runs a whole analysis on an
  image, e.g. the plate analysis: ``application(image, params) -> object with to_dict()``.
* drivers: ``labauto_register_drivers`` — ``register(kind, name, factory)`` where ``kind`` is
  ``"robot"``, ``"analyzer"`` or ``"camera"`` and ``factory(config_section)`` builds a device
  satisfying the Protocol of that kind in :mod:`labauto.devices` (``Robot``, ``Analyzer``,
  ``Camera``); the orchestrator relies on nothing else.
* events: ``labauto_detections_stored``, ``labauto_pick_finished``, ``labauto_run_finished`` —
  called by the orchestrator after the fact, for exporters (a LIMS, a message bus). An exception
  in an event hook is logged in the run's audit log and does not stop the run.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pluggy

from labauto.devices import Analyzer, Camera, Robot

#: A driver factory: ``factory(config_section)`` returns an unconnected device.
DriverFactory = Callable[[Any], Robot | Analyzer | Camera]

PROJECT_NAME = "labauto"
ENTRY_POINT_GROUP = "labauto"

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


@hookspec
def labauto_register_segmenters(register: Callable[[str, Callable[..., Any]], None]) -> None:
    """Register segmenters: ``register(name, segmenter)``.

    ``segmenter(image, params)`` takes a BGR or gray ``numpy`` image and a
    ``labauto.vision.detector.DetectorParams`` and returns a ``DetectionResult``.
    """


@hookspec
def labauto_register_classifiers(register: Callable[[str, Callable[..., Any]], None]) -> None:
    """Register classifiers: ``register(name, classifier)``.

    ``classifier(image, result)`` returns one label (a string) per object of the
    ``DetectionResult`` ``result``.
    """


@hookspec
def labauto_register_applications(register: Callable[[str, Callable[..., Any]], None]) -> None:
    """Register applications: ``register(name, application)``.

    ``application(image, params)`` runs a whole analysis and returns a result with ``to_dict()``
    (the built-in ``"plate"`` application returns a ``PlateResult``).
    """


@hookspec
def labauto_register_drivers(register: Callable[[str, str, DriverFactory], None]) -> None:
    """Register device drivers: ``register(kind, name, factory)``.

    ``kind`` is ``"robot"``, ``"analyzer"`` or ``"camera"``; ``factory(section)`` receives the
    validated config section of that device and returns an unconnected device satisfying
    :class:`labauto.devices.Robot`, :class:`~labauto.devices.Analyzer` or
    :class:`~labauto.devices.Camera`.
    """


@hookspec
def labauto_detections_stored(run_id: int | None, image_id: int, plate: str, count: int) -> None:
    """Called after the detections of one image were stored (``count`` rows)."""


@hookspec
def labauto_pick_finished(run_id: int, pick: dict[str, Any]) -> None:
    """Called when a pick reaches a final state (analyzed or failed); ``pick`` is its row."""


@hookspec
def labauto_run_finished(run_id: int, state: str, summary: dict[str, Any]) -> None:
    """Called once when a run ends (stopped, failed or succeeded) with its summary counts."""
