"""The camera watching the picking head: did the head reach the commanded deck position?

A stepper gantry does not know where it is; it counts the steps it sent. Lost steps (moving
too fast, a crash into something, a slipped belt) leave the controller reporting the commanded
position while the head is elsewhere, and a pick then probes the wrong colony or the agar. So
during a run, after the head has travelled to a pick position (before it descends) and after
the pick (back at safe height), the camera takes an image, a coded marker on the head is found
in it, its pixel is mapped to the deck by the run's calibration, and it is compared with the
commanded position. Off by more than ``head_check.tolerance_mm`` (or not found) is a *miss*:
the pick fails, the robot is not moved again, and the run stops (``failed``, resumable after
the operator has looked; a resumed run homes first, which finds the real position again).

Small Protocols keep the check independent of the parts it uses:

``HeadCamera``
    ``capture() -> image``: an image of the deck now (a real camera plugin, or
    :class:`labauto.synthetic.head_camera.SimulatedHeadCamera`, which renders the head's
    marker where the simulated gantry really is).
``HeadLocator``
    ``locate(image) -> (x, y) pixel or None``: where the head is in an image
    (:class:`MarkerHeadLocator`: the coded marker with the configured id, its fitted centre).
``DeckMap``
    ``to_deck(pixels) -> deck mm``: the run's calibration, the config's homography
    (:class:`labauto.orchestrator.calibration.Calibration`) or a stored deck calibration
    (:class:`labauto.vision.deck.DeckCalibration`, a camera model).

The head's marker is at the head's own height (safe height plus the marker's offset) while a
homography maps one plane; with a camera model the marker's pixel is cast onto the plane at the
marker's height (``to_deck(pixels, z=...)``), so there is no parallax; with the homography the
tolerance has to allow for it (in the simulated workcell the homography's plane is the one the
marker is drawn in). The marker's horizontal offset from the head is taken off the seen position.

The head's marker is ``calibration.deck.head_marker`` (the one the automatic deck calibration
uses) unless ``head_check.marker_id`` names another.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from labauto.errors import RunError

__all__ = [
    "DeckMap",
    "HeadCamera",
    "HeadCheck",
    "HeadCheckResult",
    "HeadLocator",
    "HeadMiss",
    "MarkerHeadLocator",
    "head_check_for",
]


@runtime_checkable
class HeadCamera(Protocol):
    """A camera that can take an image now."""

    def capture(self) -> np.ndarray:
        """An image of the deck (BGR or grey ``uint8``)."""
        ...


class HeadLocator(Protocol):
    """Finds the head in an image."""

    def locate(self, image: np.ndarray) -> tuple[float, float] | None:
        """The head's pixel position, or ``None`` when it is not in the image."""
        ...


class DeckMap(Protocol):
    """Pixel to deck millimetres (a camera model also takes the height ``z`` to map onto)."""

    def to_deck(self, pixels: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class MarkerHeadLocator:
    """The head is the coded marker ``marker_id``.

    ``centre`` is ``"centroid"`` (the DES centroid of its centre circle: exact to a few
    hundredths of a pixel for a camera looking straight down, where perspective bias is
    negligible) or ``"fitted"`` (the detector's bias-corrected centre, for an oblique camera).
    """

    marker_id: int
    centre: str = "centroid"
    options: tuple[tuple[str, Any], ...] = ()

    def locate(self, image: np.ndarray) -> tuple[float, float] | None:
        from labauto.vision.markers import detect_markers

        for marker in detect_markers(image, **dict(self.options)):
            if marker.id == self.marker_id:
                point = marker.centroid if self.centre == "centroid" else marker.center
                return (float(point[0]), float(point[1]))
        return None


@dataclass(frozen=True)
class HeadCheckResult:
    """One comparison of the head's seen and commanded positions.

    Attributes
    ----------
    commanded_mm : (x, y)
        Where the head was sent (deck mm).
    seen_mm : (x, y) or None
        Where the camera saw it (``None``: the marker was not found).
    pixel : (x, y) or None
        The marker's pixel.
    error_mm : float or None
        Distance between the two.
    tolerance_mm : float
        Largest distance accepted.
    """

    commanded_mm: tuple[float, float]
    seen_mm: tuple[float, float] | None
    pixel: tuple[float, float] | None
    error_mm: float | None
    tolerance_mm: float

    @property
    def ok(self) -> bool:
        """The head was seen within the tolerance of where it was sent."""
        return self.error_mm is not None and self.error_mm <= self.tolerance_mm

    def message(self) -> str:
        """One line for the audit log."""
        x, y = self.commanded_mm
        if self.seen_mm is None:
            return (
                f"head marker not found by the camera at ({x:.2f}, {y:.2f}) mm "
                f"(tolerance {self.tolerance_mm:g} mm)"
            )
        sx, sy = self.seen_mm
        verdict = "within" if self.ok else "beyond"
        return (
            f"head seen at ({sx:.2f}, {sy:.2f}) mm, commanded ({x:.2f}, {y:.2f}) mm: "
            f"{self.error_mm:.2f} mm off, {verdict} the tolerance of {self.tolerance_mm:g} mm"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON form for the audit log's event data."""
        return {
            "commanded_mm": list(self.commanded_mm),
            "seen_mm": None if self.seen_mm is None else list(self.seen_mm),
            "pixel": None if self.pixel is None else list(self.pixel),
            "error_mm": self.error_mm,
            "tolerance_mm": self.tolerance_mm,
            "ok": self.ok,
        }


class HeadCheck:
    """Compare where the camera sees the head with where it was commanded.

    Parameters
    ----------
    camera : HeadCamera
        Takes the image.
    locator : HeadLocator
        Finds the head's pixel in it.
    deck_map : DeckMap
        Maps that pixel to the deck.
    tolerance_mm : float
        Largest distance accepted (> 0).
    height_mm : float, optional
        The marker's height during a check, for a deck map that is a camera model
        (``to_deck(pixels, z=height_mm)``); ``None`` for a homography.
    offset_mm : (dx, dy)
        The marker's horizontal offset from the head.
    """

    def __init__(
        self,
        camera: HeadCamera,
        locator: HeadLocator,
        deck_map: DeckMap,
        tolerance_mm: float,
        *,
        height_mm: float | None = None,
        offset_mm: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        if not (math.isfinite(tolerance_mm) and tolerance_mm > 0):
            raise ValueError(f"tolerance_mm must be a finite number > 0, got {tolerance_mm!r}")
        self.camera = camera
        self.locator = locator
        self.deck_map = deck_map
        self.tolerance_mm = float(tolerance_mm)
        self.height_mm = height_mm
        self.offset_mm = (float(offset_mm[0]), float(offset_mm[1]))

    def check(self, x_mm: float, y_mm: float) -> HeadCheckResult:
        """Take an image and compare the head's position with ``(x_mm, y_mm)``."""
        commanded = (float(x_mm), float(y_mm))
        pixel = self.locator.locate(self.camera.capture())
        if pixel is None:
            return HeadCheckResult(commanded, None, None, None, self.tolerance_mm)
        pixels = np.asarray([pixel], np.float64)
        if self.height_mm is None:
            seen = self.deck_map.to_deck(pixels)[0]
        else:
            seen = self.deck_map.to_deck(pixels, z=self.height_mm)[0]  # type: ignore[call-arg]
        seen_mm = (float(seen[0]) - self.offset_mm[0], float(seen[1]) - self.offset_mm[1])
        error = math.hypot(seen_mm[0] - commanded[0], seen_mm[1] - commanded[1])
        return HeadCheckResult(commanded, seen_mm, pixel, error, self.tolerance_mm)


class HeadMiss(RunError):
    """The head was not where it was sent: the pick fails and the run stops moving."""

    def __init__(self, pick_id: int, result: HeadCheckResult) -> None:
        super().__init__(f"pick {pick_id}: {result.message()}; motion stopped")
        self.pick_id = pick_id
        self.result = result


def head_check_for(config: Any, workcell: Any, calibration: Any) -> HeadCheck | None:
    """The head check a run's config asks for (``None`` when ``head_check.enabled`` is off).

    ``head_check.camera: simulated`` renders the head's marker where the simulated gantry of
    ``workcell.robot.simulator`` really is: through the inverse of ``calibration``'s homography
    (:class:`~labauto.synthetic.head_camera.SimulatedHeadCamera`), or, when the run uses a
    stored deck calibration (a camera model), with the simulated deck camera of
    ``calibration.deck.simulated_camera`` that the deck calibration itself uses. ``camera``
    uses the workcell camera's ``capture()``.

    Raises
    ------
    RunError
        The camera asked for cannot take images, or a simulated camera model would render
        another marker than ``head_check.marker_id``.
    """
    section = config.head_check
    if not section.enabled:
        return None
    head = config.calibration.deck.head_marker
    marker_id = head.id if section.marker_id is None else section.marker_id
    radius = head.radius_mm if section.marker_radius_mm is None else section.marker_radius_mm
    dx, dy, dz = head.offset_mm
    homography = getattr(calibration, "homography", None)
    height = None if homography is not None else config.robot.safe_z_mm + dz
    if section.camera == "simulated":
        gantry = getattr(workcell.robot, "simulator", None)
        if gantry is None:
            raise RunError(
                "head_check.camera: 'simulated' needs a simulated robot (robot.simulate)"
            )
        camera = _simulated_camera(config, gantry, homography, marker_id, radius)
    else:
        camera = workcell.camera
        if not isinstance(camera, HeadCamera):
            raise RunError(
                f"head_check.camera: the camera driver {config.camera.driver!r} cannot take an "
                "image on demand (it has no capture())"
            )
    return HeadCheck(
        camera,
        MarkerHeadLocator(marker_id),
        calibration,
        section.tolerance_mm,
        height_mm=height,
        offset_mm=(dx, dy),
    )


def _simulated_camera(
    config: Any, gantry: Any, homography: np.ndarray | None, marker_id: int, radius: float
) -> HeadCamera:
    """The simulated camera that sees the head (see :func:`head_check_for`)."""
    head = config.calibration.deck.head_marker
    if homography is None:  # a camera model: the deck calibration's own simulated camera
        from labauto.calibration.deck import simulated_deck_camera

        if marker_id != head.id:
            raise RunError(
                f"head_check.marker_id: {marker_id} is not the simulated deck camera's head "
                f"marker (calibration.deck.head_marker.id {head.id})"
            )
        return simulated_deck_camera(config, lambda: gantry.position)
    from labauto.synthetic.head_camera import SimulatedHeadCamera, deck_to_image

    dx, dy, _dz = head.offset_mm

    def marker_position() -> tuple[float, float]:
        x, y, _z = gantry.position
        return (x + dx, y + dy)

    return SimulatedHeadCamera(marker_position, deck_to_image(homography), marker_id, radius)
