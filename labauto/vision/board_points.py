"""Board points in an image: image positions paired with board positions, for calibration.

* **Coded board**: :func:`labauto.vision.markers.detect_markers`; every marker whose id is on
  the board gives one pair (its bias-free centre and its ``center_mm``). Markers of other ids
  are counted (``foreign``): a view full of them means the images and the board YAML do not
  match.
* **Circle grid**: our DES detector with the geometric ellipse fit gives the circles' centres
  (their ellipse centres, which carry the perspective bias; :mod:`labauto.vision.calibration`
  removes it from the pose once it is known).
* **Ring grid**: concentric pairs of DES ellipses (two ellipses whose centres are within a
  fifth of the smaller's minor axis) give the perspective-free centre of each ring
  (:func:`labauto.vision.concentric.projected_center`).

A grid is identified by its order alone, so only a view with every point is usable. The order
is OpenCV's: the centres found are drawn as dots on a blank image and ``cv2.findCirclesGrid``
orders them (it does that job well; its own blob centres are not used), then each ordered dot
is replaced by our centre it was drawn from.

:func:`opencv_circle_grid` is the baseline: ``cv2.findCirclesGrid`` on the image itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from labauto.vision.boards import Board, CodedBoard, GridBoard
from labauto.vision.concentric import projected_center
from labauto.vision.detector import DetectorParams, detect
from labauto.vision.ellipse import Ellipse
from labauto.vision.image import as_grey
from labauto.vision.markers import detect_markers


@dataclass(frozen=True)
class BoardView:
    """What one image shows of a board.

    Attributes
    ----------
    image_points : np.ndarray
        (n, 2) pixel positions.
    object_points : np.ndarray
        (n, 3) board positions (mm, z = 0) of the same points.
    ids : np.ndarray
        (n,) marker ids (coded boards) or grid indices.
    found : int
        Markers (coded) or circles (grids) seen in all, on the board or not.
    foreign : int
        Coded markers seen whose id is not on the board.
    reason : str or None
        Why the view has no points (None when it has).
    """

    image_points: np.ndarray
    object_points: np.ndarray
    ids: np.ndarray
    found: int
    foreign: int = 0
    reason: str | None = None

    def __len__(self) -> int:
        return int(self.image_points.shape[0])


def _empty(found: int, reason: str, foreign: int = 0) -> BoardView:
    return BoardView(
        np.empty((0, 2)), np.empty((0, 3)), np.empty(0, np.int64), found, foreign, reason
    )


def find_board_points(image: np.ndarray, board: Board) -> BoardView:
    """Find ``board``'s points in ``image`` (see the module docstring)."""
    grey = as_grey(image)
    if isinstance(board, CodedBoard):
        return _coded(grey, board)
    centres = _grid_centres(grey, board)
    if len(centres) == 0:
        return _empty(0, "no board found (no circles)")
    ordered = order_grid(centres, board)
    if ordered is None:
        n = board.rows * board.cols
        return _empty(
            len(centres),
            f"no {board.cols}x{board.rows} {board.type} found "
            f"({len(centres)} circles seen, {n} needed)",
        )
    return BoardView(ordered, board.object_points(), np.arange(len(ordered)), len(centres))


def _coded(grey: np.ndarray, board: CodedBoard) -> BoardView:
    markers = detect_markers(grey)
    on_board = set(board.ids.tolist())
    mine = [m for m in markers if m.id in on_board]
    foreign = len(markers) - len(mine)
    if not mine:
        if foreign:
            return _empty(
                len(markers), f"{foreign} markers seen, none of them on the board", foreign
            )
        return _empty(0, "no board found (no markers)")
    ids = np.array([m.id for m in mine], np.int64)
    pts = np.array([m.center for m in mine], np.float64)
    return BoardView(pts, board.object_points(ids), ids, len(markers), foreign)


def _des_ellipses(grey: np.ndarray) -> list[Ellipse]:
    result = detect(grey, DetectorParams(classify=False, canny_low=30.0, canny_high=80.0))
    return [o.ellipse for o in result.objects if o.is_des and o.closed and o.ellipse is not None]


def _grid_centres(grey: np.ndarray, board: GridBoard) -> np.ndarray:
    ellipses = [e for e in _des_ellipses(grey) if e.axes[1] >= 2.0]
    if ellipses:  # the grid's circles are alike; the page itself (a quadrilateral) is a DES too
        typical = float(np.median([e.axes[0] for e in ellipses]))
        ellipses = [e for e in ellipses if typical / 3 < e.axes[0] < typical * 3]
    if board.type == "circle-grid":
        return np.array([e.center for e in ellipses], np.float64).reshape(-1, 2)
    return ring_centres(ellipses, board.inner_diameter_mm / board.diameter_mm)


def ring_centres(ellipses: list[Ellipse], ratio: float) -> np.ndarray:
    """(N, 2) centres of the rings among ``ellipses``: each inner edge paired with the nearest
    larger ellipse about the same centre whose size is ``ratio`` (inner over outer diameter,
    within 0.15) times its own; the centre is the two concentric conics' projected centre.
    A near ellipse of another size (a second contour of the same edge) is passed over, and so
    is one of the right size whose pair gives no projected centre."""
    ellipses = sorted(ellipses, key=lambda e: e.axes[0])
    centres, used = [], set()
    xy = np.array([e.center for e in ellipses]).reshape(-1, 2)
    for i, inner in enumerate(ellipses):
        if i in used:
            continue
        near = np.flatnonzero(np.hypot(*(xy - xy[i]).T) < 0.2 * inner.axes[1])
        for j in near.tolist():
            outer = ellipses[j]
            if j <= i or j in used:
                continue
            if abs(inner.axes[0] / outer.axes[0] - ratio) < 0.15:
                centre = projected_center([inner, outer])
                if centre is not None:
                    centres.append(centre)
                    used.update((i, j))
                    break
    return np.array(centres, np.float64).reshape(-1, 2)


def order_grid(centres: np.ndarray, board: GridBoard) -> np.ndarray | None:
    """Our centres in OpenCV's grid order, or None when they do not form the whole grid."""
    pts = np.asarray(centres, np.float64).reshape(-1, 2)
    n = board.rows * board.cols
    if len(pts) < n:
        return None
    gaps = np.sqrt(np.sort(((pts[:, None] - pts[None]) ** 2).sum(-1), axis=1)[:, 1])
    dot = max(3, int(0.25 * np.median(gaps)))
    lo, hi = pts.min(axis=0) - 4 * dot, pts.max(axis=0) + 4 * dot
    canvas = np.full((int(hi[1] - lo[1]) + 1, int(hi[0] - lo[0]) + 1), 255, np.uint8)
    for x, y in (pts - lo).tolist():
        cv2.circle(canvas, (round(x), round(y)), dot, 0, -1)
    flags = cv2.CALIB_CB_ASYMMETRIC_GRID if board.asymmetric else cv2.CALIB_CB_SYMMETRIC_GRID
    ok, found = cv2.findCirclesGrid(canvas, board.pattern_size, flags=flags)
    if not ok or found is None:
        return None
    found = found.reshape(-1, 2) + lo
    pick = np.argmin(((found[:, None] - pts[None]) ** 2).sum(-1), axis=1)
    if len(set(pick.tolist())) != n or np.max(np.hypot(*(found - pts[pick]).T)) > 1.5:
        return None
    return pts[pick]


def opencv_circle_grid(image: np.ndarray, board: GridBoard) -> np.ndarray | None:
    """The baseline: ``cv2.findCirclesGrid`` on the image (None when it finds no grid)."""
    grey = as_grey(image)
    if board.polarity == "light-on-dark":
        grey = 255 - grey
    flags = cv2.CALIB_CB_ASYMMETRIC_GRID if board.asymmetric else cv2.CALIB_CB_SYMMETRIC_GRID
    ok, found = cv2.findCirclesGrid(grey, board.pattern_size, flags=flags)
    return found.reshape(-1, 2).astype(np.float64) if ok and found is not None else None
