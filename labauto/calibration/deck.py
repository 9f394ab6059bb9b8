"""``labauto calibrate deck``: the camera's pose over the deck, automatically (issue 14.5).

Two sources of point pairs (pixel, deck position), then :class:`labauto.vision.deck.
DeckCalibration` (``solvePnP`` with the stored camera intrinsics and distortion):

* ``source: head`` (default): the paper's "locomotor system" moves the calibration field. The
  gantry carries a coded marker on its tool head (``calibration.deck.head_marker``: id, radius,
  offset from the head's position) to a grid of deck positions at one or more heights
  (``calibration.deck.grid``); at each the camera takes a frame and the marker of that id is
  found. With ``robot.simulate: true`` the camera is a :class:`labauto.synthetic.camera.
  SceneCamera` that renders the marker where the simulated gantry really is, so the whole
  procedure runs in simulation; otherwise frames come from the configured camera driver.
* ``source: board``: a coded board lying face up on the deck at a known place
  (``calibration.deck.board``: its YAML, the deck position of its top-left corner and its
  angle), in one image (``image``, or a frame of the camera).

The result is stored (table ``calibrations``, kind ``deck``, under ``calibration.deck.name``)
and runs then use it instead of the homography of ``calibration.points``; a calibration whose
residual exceeds ``calibration.max_residual_mm`` is refused.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import numpy as np

from labauto.config import Config
from labauto.errors import CalibrationError
from labauto.vision.deck import DeckCalibration, DeckCalibrationFailed, board_to_deck
from labauto.vision.markers import detect_markers

if TYPE_CHECKING:
    from labauto.store.calibrations import CalibrationStore


def head_positions(config: Config) -> list[tuple[float, float, float]]:
    """The grid of head positions (x fastest, then y, then each height)."""
    grid = config.calibration.deck.grid
    xs = np.linspace(*grid.x_mm, grid.counts[0])
    ys = np.linspace(*grid.y_mm, grid.counts[1])
    return [(float(x), float(y), float(z)) for z in grid.z_mm for y in ys for x in xs]


def camera_intrinsics(
    config: Config, store: CalibrationStore
) -> tuple[np.ndarray, np.ndarray, tuple[int, int], str]:
    """The stored camera calibration the deck calibration builds on."""
    name = config.calibration.deck.camera
    stored = store.latest_calibration(name, "camera")
    if stored is None:
        which = f"named {name!r}" if name else "at all"
        raise CalibrationError(
            f"no stored camera calibration {which}: run labauto calibrate camera --board "
            "BOARD.yaml IMAGES... --save NAME first (and set calibration.deck.camera)"
        )
    return stored.camera_matrix, stored.dist_coeffs, stored.image_size, stored.name


def simulated_deck_camera(config: Config, head_position: Callable[[], tuple] | None):
    """The simulated camera over the deck of a config (``calibration.deck.simulated_camera``).

    It renders a board lying on the deck (``source: board``) and, with a ``head_position``
    source (e.g. ``lambda: gantry.position``), the head's marker (``calibration.deck.
    head_marker``) where the head is. Deck calibrations made in simulation are made with it;
    a run's head check can use the same camera.
    """
    from labauto.synthetic.camera import CameraModel, HeadMarker, SceneCamera

    deck = config.calibration.deck
    sim = deck.simulated_camera
    model = CameraModel.looking_down(
        np.array(sim.camera_matrix), np.array(sim.dist_coeffs), sim.position_mm,
        sim.image_size, sim.tilt_deg,
    )  # fmt: skip
    sheets = []
    if deck.source == "board" and deck.board is not None:
        from labauto.calibration.boards_io import read_board

        sheets.append((read_board(deck.board.path), deck.board.origin_mm, deck.board.angle_deg))
    marker = HeadMarker(deck.head_marker.id, deck.head_marker.radius_mm, deck.head_marker.offset_mm)
    return SceneCamera(model, head_position=head_position, head_marker=marker, sheets=sheets)


@contextlib.contextmanager
def _robot(config: Config) -> Iterator:
    from labauto.plugin_manager import load_plugins

    plugins = load_plugins(config.plugins.enabled, config.plugins.disabled)
    robot = plugins.registry.driver("robot", config.robot.driver)(config.robot)
    try:
        robot.connect()
        if config.robot.home_on_start:
            robot.home()
        yield robot
    finally:
        robot.close()


def _frame_source(config: Config, robot) -> Callable[[], np.ndarray]:
    simulator = getattr(robot, "simulator", None) if robot is not None else None
    if config.robot.simulate and simulator is not None:
        return simulated_deck_camera(config, lambda: simulator.position).capture
    from labauto.plugin_manager import load_plugins

    plugins = load_plugins(config.plugins.enabled, config.plugins.disabled)
    camera = plugins.registry.driver("camera", config.camera.driver)(config.camera)
    frames = iter(camera)  # one pass: each capture is the next frame, not the first again

    def capture() -> np.ndarray:
        frame = next(frames, None)
        if frame is None:
            raise CalibrationError(f"camera {config.camera.driver!r} gave no more images")
        return frame[1]

    return capture


def _check_size(image: np.ndarray, size: tuple[int, int], camera_name: str) -> None:
    h, w = image.shape[:2]
    if (w, h) != tuple(size):
        raise CalibrationError(
            f"the camera gives {w}x{h} images but camera calibration {camera_name!r} is for "
            f"{size[0]}x{size[1]}"
        )


def calibrate_deck(config: Config, store: CalibrationStore) -> tuple[DeckCalibration, dict]:
    """Run the configured deck calibration; returns it and a report (positions, camera used).

    Raises
    ------
    CalibrationError
        No stored camera calibration, the marker or board not seen often enough, or a residual
        over ``calibration.max_residual_mm``.
    """
    deck = config.calibration.deck
    k, d, size, camera_name = camera_intrinsics(config, store)
    surface = config.robot.pick_z_mm if deck.surface_z_mm is None else deck.surface_z_mm
    if deck.source == "board":
        pixels, points, report = _board_pairs(config, size, camera_name)
    else:
        pixels, points, report = _head_pairs(config, size, camera_name)
    try:
        cal = DeckCalibration.from_points(
            pixels, points, k, d, size,
            surface_z=surface, max_residual_mm=config.calibration.max_residual_mm,
        )  # fmt: skip
    except DeckCalibrationFailed as exc:
        raise CalibrationError(f"{exc} ({report['summary']})") from None
    report["camera"] = camera_name
    return cal, report


def _head_pairs(config: Config, size: tuple[int, int], camera_name: str):
    deck = config.calibration.deck
    marker = deck.head_marker
    pixels, points, positions = [], [], []
    with _robot(config) as robot:
        capture = _frame_source(config, robot)
        for x, y, z in head_positions(config):
            robot.move_to(x, y, z)
            image = capture()
            _check_size(image, size, camera_name)
            seen = [m for m in detect_markers(image) if m.id == marker.id]
            where = (x + marker.offset_mm[0], y + marker.offset_mm[1], z + marker.offset_mm[2])
            entry = {"head_mm": [x, y, z], "marker_mm": list(where), "pixel": None}
            if seen:
                pixels.append(seen[0].center)
                points.append(where)
                entry["pixel"] = [float(v) for v in seen[0].center]
            positions.append(entry)
        robot.move_to(*head_positions(config)[0][:2])  # head up, out of the way
    summary = f"head marker {marker.id} seen at {len(pixels)} of {len(positions)} positions"
    if len(pixels) < 6:
        raise CalibrationError(
            f"{summary}: too few to calibrate the deck (needs 6); check "
            "calibration.deck.grid and head_marker"
        )
    return np.array(pixels), np.array(points), {"source": "head", "positions": positions,
                                                "summary": summary}  # fmt: skip


def _board_pairs(config: Config, size: tuple[int, int], camera_name: str):
    from labauto.calibration.boards_io import read_board
    from labauto.imageio import read_image
    from labauto.vision.board_points import find_board_points
    from labauto.vision.boards import CodedBoard

    spec = config.calibration.deck.board
    if spec is None:
        raise CalibrationError("calibration.deck.board: needed for source: board")
    board = read_board(spec.path)
    if not isinstance(board, CodedBoard):
        raise CalibrationError(f"{spec.path}: a deck board must be a coded board")
    if spec.image is not None:
        image = read_image(spec.image)
    elif config.robot.simulate:
        image = simulated_deck_camera(config, None).capture()
    else:
        image = _frame_source(config, None)()
    _check_size(image, size, camera_name)
    view = find_board_points(image, board)
    summary = f"{len(view)} of {len(board.ids)} board markers seen"
    if len(view) < 6:
        raise CalibrationError(f"{summary} ({view.reason or 'too few'}): needs 6")
    points = board_to_deck(view.object_points, spec.origin_mm, spec.angle_deg)
    return view.image_points, points, {"source": "board", "summary": summary,
                                       "markers": len(view)}  # fmt: skip
