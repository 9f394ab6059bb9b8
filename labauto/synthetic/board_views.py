"""Views of calibration boards by a known camera (intrinsics, distortion, pose), rendered exactly.

:func:`board_poses` draws poses that show the whole board, tilted up to ``max_tilt_deg`` about
a random axis and turned about its normal; :func:`render_board_view` draws the board (paper on a
darker table, then its markers, circles or rings through :func:`labauto.synthetic.markers.
camera_map`, so lens distortion bends them as it would) and returns the image with the true
image position of every board point.
"""

from __future__ import annotations

import cv2
import numpy as np

from labauto.synthetic.grey_look import GreyLook
from labauto.synthetic.markers import (
    PlaneToImage,
    camera_map,
    draw_disc,
    draw_marker,
    draw_ring,
    fill_polygons,
)
from labauto.vision.boards import Board, CodedBoard


def board_extent(board: Board) -> tuple[float, float]:
    """Width and height (mm) of the board's page."""
    if isinstance(board, CodedBoard):
        return board.width_mm, board.height_mm
    return board.size_mm


def _grid_offset(board: Board) -> float:
    return 0.0 if isinstance(board, CodedBoard) else board.spacing_mm


def board_points(board: Board) -> np.ndarray:
    """(n, 3) board points in the page's frame (grids are printed one spacing in)."""
    pts = board.object_points().copy()
    pts[:, :2] += _grid_offset(board)
    return pts


def board_poses(
    rng: np.random.Generator,
    n: int,
    board: Board,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    image_size: tuple[int, int],
    *,
    max_tilt_deg: float = 60.0,
    fill: tuple[float, float] = (0.45, 0.8),
    margin_px: float = 30.0,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` poses ``(rvec, tvec)`` of the page that keep it inside the image.

    The page's centre goes to a random place near the middle of the image at a distance that
    makes its width ``fill`` of the image's width (before tilting); tilts run evenly up to
    ``max_tilt_deg`` over the views so that every calibration sees strong and weak ones.
    """
    w_mm, h_mm = board_extent(board)
    corners = np.array([[0, 0, 0], [w_mm, 0, 0], [w_mm, h_mm, 0], [0, h_mm, 0]], np.float64)
    fx = camera_matrix[0, 0]
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    tilts = np.linspace(max_tilt_deg * 0.15, max_tilt_deg, n)
    rng.shuffle(tilts)
    for tilt in tilts:
        for _ in range(200):
            axis = rng.uniform(0, 2 * np.pi)
            spin = rng.uniform(-30, 30)
            tilt_r, _ = cv2.Rodrigues(
                np.array([np.cos(axis), np.sin(axis), 0.0]) * np.deg2rad(tilt)
            )
            spin_r, _ = cv2.Rodrigues(np.array([0.0, 0.0, np.deg2rad(spin)]))
            rot = tilt_r @ spin_r
            depth = fx * w_mm / (rng.uniform(*fill) * image_size[0])
            shift = rng.uniform(-0.1, 0.1, 2) * depth * np.array(image_size) / fx
            centre = np.array([w_mm / 2, h_mm / 2, 0.0])
            tvec = np.array([shift[0], shift[1], depth]) - rot @ centre
            rvec, _ = cv2.Rodrigues(rot)
            img, _ = cv2.projectPoints(corners, rvec, tvec, camera_matrix, dist_coeffs)
            img = img.reshape(-1, 2)
            inside = (img >= margin_px).all() and (img <= np.array(image_size) - margin_px).all()
            if inside and (rot @ corners.T + tvec[:, None])[2].min() > 0:
                poses.append((rvec.ravel(), tvec.ravel()))
                break
        else:
            raise ValueError(f"no pose at {tilt:.0f} deg tilt keeps the board in the image")
    return poses


def draw_board(
    img: np.ndarray,
    board: Board,
    to_image: PlaneToImage,
    *,
    paper: float = 215.0,
    ink: float = 25.0,
    page: bool = True,
) -> np.ndarray:
    """Draw the board's page (``page``) and its markers, circles or rings into a float image.

    ``to_image`` maps the page's plane (mm from its top-left corner, y down) to pixels.
    ``light-on-dark`` boards swap ``paper`` and ``ink``. Returns the (n, 2) true image
    positions of the board points, in :meth:`object_points` order.
    """
    w_mm, h_mm = board_extent(board)
    if board.polarity == "light-on-dark":
        paper, ink = ink, paper
    if page:
        edge = np.linspace(0, 1, 200, endpoint=False)
        outline = np.concatenate(
            [
                np.column_stack((edge * w_mm, np.zeros_like(edge))),
                np.column_stack((np.full_like(edge, w_mm), edge * h_mm)),
                np.column_stack(((1 - edge) * w_mm, np.full_like(edge, h_mm))),
                np.column_stack((np.zeros_like(edge), (1 - edge) * h_mm)),
            ]
        )
        fill_polygons(img, [to_image(outline)], paper)
    truth = []
    if isinstance(board, CodedBoard):
        for marker_id, centre in zip(board.ids.tolist(), board.centers_mm.tolist(), strict=True):
            r = board.marker_radius_mm
            truth.append(draw_marker(img, marker_id, centre, r, to_image=to_image, ink=ink))
        return np.array(truth)
    for x, y, _ in board_points(board).tolist():
        if board.type == "circle-grid":
            truth.append(
                draw_disc(img, (x, y), board.diameter_mm / 2, to_image=to_image, color=ink)
            )
        else:
            r_in, r_out = board.inner_diameter_mm / 2, board.diameter_mm / 2
            truth.append(draw_ring(img, (x, y), r_in, r_out, to_image=to_image, color=ink))
    return np.array(truth)


def render_board_view(
    board: Board,
    camera_matrix: np.ndarray,
    dist_coeffs: np.ndarray,
    rvec: np.ndarray,
    tvec: np.ndarray,
    image_size: tuple[int, int],
    *,
    rng: np.random.Generator | None = None,
    blur_sigma: float = 0.8,
    noise_sigma: float = 2.0,
    paper: float = 215.0,
    ink: float = 25.0,
    table: float = 90.0,
    light_gain: tuple[float, float] = (0.75, 1.0),
) -> tuple[np.ndarray, np.ndarray]:
    """The view as a grey uint8 image and the true (n, 2) image positions of the board points.

    The board's points are in :meth:`object_points` order; positions are what the lens makes of
    each point (distortion included).
    """
    to_image = camera_map(camera_matrix, dist_coeffs, rvec, tvec)
    look = GreyLook(table, ink, blur_sigma, noise_sigma)
    img = look.canvas(image_size)
    truth = draw_board(img, board, to_image, paper=paper, ink=ink)
    if light_gain != (1.0, 1.0):
        width, height = image_size
        yy, xx = np.mgrid[0:height, 0:width]
        r = np.hypot(xx - width * 0.3, yy - height * 0.4) / np.hypot(width, height)
        img *= light_gain[1] - (light_gain[1] - light_gain[0]) * np.clip(r / 0.8, 0, 1)
    rng = rng if rng is not None else np.random.default_rng(0)
    return look.develop(img, rng), truth
