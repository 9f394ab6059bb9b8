"""Simulated cameras: synthetic plates, and a camera over the deck that sees the tool head.

They live beside the generators they draw from (not in ``labauto.drivers``): they are sources of
rendered test scenes, not drivers for devices. Both have the ``Camera`` shape of
``labauto.devices``: an iterable of ``(name, image)`` pairs.

* :class:`SimulatedCamera` serves synthetic plates (BGR) from consecutive seeds.
* :class:`SceneCamera` is a fixed camera (:class:`CameraModel`: intrinsics, distortion, pose
  over the deck) that renders, on each :meth:`~SceneCamera.capture`, the deck, boards lying on
  it and the coded marker of the tool head where a ``head_position`` source (the simulated
  gantry) says the head is: deck calibration and head-position checks run against it in
  simulation.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from labauto.synthetic.board_views import draw_board
from labauto.synthetic.grey_look import GreyLook
from labauto.synthetic.markers import (
    PlaneToImage,
    camera_map,
    disc_polygon,
    draw_marker,
    fill_polygons,
)
from labauto.synthetic.plates import generate_plate
from labauto.vision.boards import Board
from labauto.vision.marker_codes import QUIET_RADIUS


class SimulatedCamera:
    """Serve ``count`` synthetic plates generated from consecutive seeds."""

    def __init__(self, count: int = 3, first_seed: int = 0) -> None:
        self.count = count
        self.first_seed = first_seed

    def __iter__(self) -> Iterator[tuple[str, np.ndarray]]:
        for seed in range(self.first_seed, self.first_seed + self.count):
            image, _truth = generate_plate(seed)
            yield f"simulated-{seed:04d}", image


# ------------------------------------------------------------------ a camera over the deck


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera (OpenCV model) fixed over the deck.

    ``rvec``, ``tvec`` give the deck frame (machine X, Y, Z in mm, Z up) in the camera frame.
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    image_size: tuple[int, int]

    @classmethod
    def looking_down(
        cls,
        camera_matrix: np.ndarray,
        dist_coeffs: np.ndarray,
        position_mm: tuple[float, float, float],
        image_size: tuple[int, int],
        tilt_deg: tuple[float, float] = (0.0, 0.0),
    ) -> CameraModel:
        """A camera at ``position_mm`` looking straight down (image x along +X, up along +Y),
        optionally tilted by small angles about X and Y."""
        down = np.diag([1.0, -1.0, -1.0])  # camera x = X, y = -Y, z = -Z
        tx, ty = np.deg2rad(tilt_deg)
        tilt = cv2.Rodrigues(np.array([tx, ty, 0.0]))[0]
        rot = tilt @ down
        tvec = -rot @ np.asarray(position_mm, np.float64)
        return cls(
            np.asarray(camera_matrix, np.float64),
            np.asarray(dist_coeffs, np.float64).ravel(),
            cv2.Rodrigues(rot)[0].ravel(),
            tvec,
            (int(image_size[0]), int(image_size[1])),
        )

    def sheet_map(self, origin_mm: Sequence[float], angle_deg: float = 0.0) -> PlaneToImage:
        """Plane-to-image map of a sheet lying face up at ``origin_mm`` (its top-left corner),
        its x axis turned ``angle_deg`` from +X toward +Y, its y axis down the page."""
        a = np.deg2rad(angle_deg)
        x_axis = np.array([np.cos(a), np.sin(a), 0.0])
        y_axis = np.array([np.sin(a), -np.cos(a), 0.0])  # down the page, seen from above
        rot = cv2.Rodrigues(np.asarray(self.rvec, np.float64))[0]
        sheet = np.column_stack((x_axis, y_axis, np.cross(x_axis, y_axis)))
        r = rot @ sheet
        t = rot @ np.asarray(origin_mm, np.float64) + np.asarray(self.tvec, np.float64)
        return camera_map(self.camera_matrix, self.dist_coeffs, cv2.Rodrigues(r)[0], t)


@dataclass(frozen=True)
class HeadMarker:
    """A coded marker carried by the tool head, ``offset_mm`` from the head's position."""

    marker_id: int
    radius_mm: float
    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)


#: A mid-grey deck, dark ink, a slight blur and some sensor noise.
DECK_CAMERA_LOOK = GreyLook(ground=150.0, ink=25.0, blur_sigma=0.8, noise_sigma=2.0)


class SceneCamera:
    """A camera over the deck that renders what it would see, on every ``capture()``.

    The scene is the deck (a uniform grey), boards lying on it (``sheets``: a board and where it
    lies) and, when a ``head_position`` source is given (e.g. ``lambda: gantry.position`` of
    :class:`labauto.drivers.grbl_sim.SimulatedGantry`), the tool head's marker where the head
    really is at that moment. Exact geometry through the camera model (lens distortion
    included), then blur and noise. ``look`` gives the deck's grey level (its ground), the
    ink, blur and noise; ``paper`` is the grey of the boards and of the head marker's quiet zone.
    """

    def __init__(
        self,
        model: CameraModel,
        *,
        head_position: Callable[[], Sequence[float]] | None = None,
        head_marker: HeadMarker | None = None,
        sheets: Sequence[tuple[Board, Sequence[float], float]] = (),
        look: GreyLook = DECK_CAMERA_LOOK,
        paper: float = 225.0,
        seed: int = 0,
    ) -> None:
        self.model = model
        self.head_position = head_position
        self.head_marker = head_marker
        self.sheets = list(sheets)
        self.look, self.paper = look, paper
        self._rng = np.random.default_rng(seed)

    def capture(self) -> np.ndarray:
        """One grey uint8 frame of the scene as it is now."""
        img = self.look.canvas(self.model.image_size)
        ink = self.look.ink
        for board, origin, angle in self.sheets:
            to_image = self.model.sheet_map(origin, angle)
            draw_board(img, board, to_image, paper=self.paper, ink=ink)
        if self.head_position is not None and self.head_marker is not None:
            x, y, z = (float(v) for v in self.head_position())
            m = self.head_marker
            dx, dy, dz = m.offset_mm
            q = m.radius_mm * QUIET_RADIUS
            to_image = self.model.sheet_map((x + dx - q, y + dy + q, z + dz))
            quiet = disc_polygon((q, q), q, 512)
            fill_polygons(img, [to_image(quiet)], self.paper)
            draw_marker(img, m.marker_id, (q, q), m.radius_mm, to_image=to_image, ink=ink)
        return self.look.develop(img, self._rng)

    def __iter__(self) -> Iterator[tuple[str, np.ndarray]]:
        """The ``Camera`` shape: one frame, named by the head's position."""
        pos = self.head_position() if self.head_position is not None else (0.0, 0.0, 0.0)
        yield f"deck-{pos[0]:.1f}-{pos[1]:.1f}-{pos[2]:.1f}", self.capture()
