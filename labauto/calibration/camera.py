"""Camera calibration from image files or arrays and a board: ``labauto.calibrate_camera``.

Reads the board description and the images, finds the board in each
(:func:`labauto.vision.board_points.find_board_points`), checks that the images and the board
belong together, and calibrates (:func:`labauto.vision.calibration.calibrate_camera`). Every
refusal is a :class:`~labauto.errors.CalibrationError` with one line that says what was wrong.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from labauto.errors import CalibrationError
from labauto.imageio import read_image
from labauto.vision.boards import Board, CodedBoard, GridBoard
from labauto.vision.calibration import (
    CalibrationFailed,
    CameraCalibration,
    ViewPoints,
)
from labauto.vision.calibration import calibrate_camera as _calibrate

Image = np.ndarray | str | Path


def _board(board: Board | str | Path) -> tuple[Board, str]:
    if isinstance(board, CodedBoard | GridBoard):
        return board, "the board"
    from labauto.calibration.boards_io import read_board

    return read_board(board), str(board)


def board_views(
    board: Board, images: Sequence[Image], names: Sequence[str] | None = None
) -> tuple[list[ViewPoints], tuple[int, int], list]:
    """Every image's board points, the common image size and the raw board views."""
    from labauto.vision.board_points import find_board_points

    if not images:
        raise CalibrationError("no images given")
    if names is not None and len(names) != len(images):
        raise CalibrationError(f"{len(names)} names for {len(images)} images")
    labels = (
        list(names)
        if names is not None
        else [
            str(im) if isinstance(im, str | Path) else f"image {k}" for k, im in enumerate(images)
        ]
    )
    views, found, size = [], [], None
    for label, image in zip(labels, images, strict=True):
        pixels = read_image(image) if isinstance(image, str | Path) else np.asarray(image)
        h, w = pixels.shape[:2]
        if size is None:
            size = (w, h)
        elif size != (w, h):
            raise CalibrationError(
                f"{label}: {w}x{h} pixels, but the first image is {size[0]}x{size[1]}; "
                "one calibration needs images of one camera mode"
            )
        view = find_board_points(pixels, board)
        found.append(view)
        views.append(ViewPoints(label, view.image_points, view.object_points, view.reason))
    assert size is not None
    return views, size, found


def _check_match(board: Board, where: str, found: list) -> None:
    """Refuse a board description that the images plainly do not show."""
    if not isinstance(board, CodedBoard):
        return
    foreign = sum(v.foreign for v in found)
    mine = sum(len(v) for v in found)
    if foreign and foreign > 3 * mine:
        ids = board.ids
        raise CalibrationError(
            f"{where} does not match the images: {foreign} markers seen are not on it and only "
            f"{mine} are (the board has ids {int(ids.min())}..{int(ids.max())})"
        )


def calibrate_camera(
    board: Board | str | Path,
    images: Sequence[Image],
    *,
    names: Sequence[str] | None = None,
    min_points: int = 8,
    min_views: int = 3,
    max_view_rms_px: float = 1.0,
) -> CameraCalibration:
    """Calibrate a camera from images of a board (coded, circle-grid or ring-grid).

    Parameters
    ----------
    board : Board or path
        The board, or its YAML description.
    images : sequence of arrays or paths
        The views (at least ``min_views`` usable ones).
    names : sequence of str, optional
        Names of the views in the result (default: the paths).
    min_points, min_views, max_view_rms_px
        As :func:`labauto.vision.calibration.calibrate_camera`.

    Returns
    -------
    CameraCalibration
        ``to_dict()`` is the ``labauto calibrate camera --json`` document.

    Raises
    ------
    CalibrationError
        No images, images of different sizes, a board that does not match, too few usable views.
    """
    the_board, where = _board(board)
    views, size, found = board_views(the_board, images, names)
    _check_match(the_board, where, found)
    radius = None
    if isinstance(the_board, GridBoard):
        min_points = the_board.rows * the_board.cols
        if the_board.type == "circle-grid":
            radius = the_board.diameter_mm / 2
    try:
        return _calibrate(
            views,
            size,
            min_points=min_points,
            min_views=min_views,
            max_view_rms_px=max_view_rms_px,
            circle_radius_mm=radius,
        )
    except CalibrationFailed as exc:
        raise CalibrationError(str(exc)) from None
