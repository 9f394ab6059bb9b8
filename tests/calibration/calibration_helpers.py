"""Helpers of the calibration tests: a known camera and rendered board views."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from labauto.synthetic.board_views import board_poses, render_board_view
from labauto.vision.boards import Board

CAMERA = np.array([[1400.0, 0.0, 652.3], [0.0, 1396.0, 505.7], [0.0, 0.0, 1.0]])
DIST = np.array([-0.25, 0.12, 0.0008, -0.0005, -0.02])
SIZE = (1280, 1024)


@dataclass
class Views:
    board: Board
    images: list[np.ndarray]
    truth: list[np.ndarray]
    poses: list[tuple[np.ndarray, np.ndarray]]


def render_views(board: Board, n: int, seed: int, **kw) -> Views:
    rng = np.random.default_rng(seed)
    poses = board_poses(rng, n, board, CAMERA, DIST, SIZE, max_tilt_deg=60.0)
    images, truth = [], []
    for rvec, tvec in poses:
        img, pts = render_board_view(board, CAMERA, DIST, rvec, tvec, SIZE, rng=rng, **kw)
        images.append(img)
        truth.append(pts)
    return Views(board, images, truth, poses)
