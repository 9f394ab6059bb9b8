"""Calibration boards: their geometry and their YAML description (pure; no file access).

Three kinds, each a plane with its origin at the board's top-left corner, x right and y down,
in millimetres (object points have z = 0):

* ``type: coded``: coded markers (:mod:`labauto.vision.marker_codes`) at known places,
  ``markers: [{id, center_mm: [x, y]}, ...]``, every marker's centre circle of radius
  ``marker_radius_mm``. Any subset of the markers seen in a view is usable, because each one
  names itself; :func:`coded_board` lays out ``rows x cols`` of them at ``pitch_mm``.
* ``type: circle-grid``: OpenCV's grid of filled circles, ``cols`` x ``rows`` centres at
  ``spacing_mm``, circles of ``diameter_mm``; ``asymmetric: true`` gives OpenCV's
  asymmetric grid (row ``i``'s centres at x = ``(2 j + i mod 2) * spacing_mm``). Only a view
  that shows the whole grid is usable (the points are identified by their order).
* ``type: ring-grid``: the same grids of concentric rings (annuli) of ``inner_diameter_mm`` and
  ``outer_diameter_mm``, whose two edges give the perspective-free centre.

``polarity`` is ``dark-on-light`` (default: black print on white) or ``light-on-dark``.
Grid points are ordered as OpenCV orders them (row by row), so a grid found by
``cv2.findCirclesGrid`` pairs with :meth:`GridBoard.object_points` directly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from labauto.vision.marker_codes import QUIET_RADIUS, n_codes

POLARITIES = ("dark-on-light", "light-on-dark")
#: A coded board's marker centre radius as a share of its pitch: the quiet zone (3.6 radii)
#: then fills 90 % of the pitch.
RADIUS_PER_PITCH = 0.45 / QUIET_RADIUS


class BoardError(ValueError):
    """A board description is invalid; the message names the field."""


@dataclass(frozen=True)
class CodedBoard:
    """A board of coded markers.

    Attributes
    ----------
    ids : np.ndarray
        (n,) marker ids.
    centers_mm : np.ndarray
        (n, 2) marker centres.
    marker_radius_mm : float
        Radius of each marker's centre circle.
    width_mm, height_mm : float
        Size of the board (the printed page).
    polarity : str
        ``dark-on-light`` or ``light-on-dark``.
    """

    ids: np.ndarray
    centers_mm: np.ndarray
    marker_radius_mm: float
    width_mm: float
    height_mm: float
    polarity: str = "dark-on-light"
    extra: dict = field(default_factory=dict, compare=False)

    type = "coded"

    def object_points(self, ids: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) board points (z = 0) of ``ids`` (default all), in the order given."""
        if ids is None:
            return np.column_stack((self.centers_mm, np.zeros(len(self.ids))))
        where = {int(i): k for k, i in enumerate(self.ids.tolist())}
        rows = [where[int(i)] for i in np.asarray(ids).tolist()]
        return np.column_stack((self.centers_mm[rows], np.zeros(len(rows))))

    def to_dict(self) -> dict:
        """The YAML description."""
        return {
            "type": "coded",
            "units": "mm",
            "width_mm": float(self.width_mm),
            "height_mm": float(self.height_mm),
            "marker_radius_mm": float(self.marker_radius_mm),
            "ring_radii": {"inner": 2.0, "outer": 3.0, "quiet": QUIET_RADIUS},
            "polarity": self.polarity,
            **self.extra,
            "markers": [
                {"id": int(i), "center_mm": [float(x), float(y)]}
                for i, (x, y) in zip(self.ids.tolist(), self.centers_mm.tolist(), strict=True)
            ],
        }


@dataclass(frozen=True)
class GridBoard:
    """An OpenCV-style grid of circles or rings.

    Attributes
    ----------
    type : str
        ``circle-grid`` or ``ring-grid``.
    cols, rows : int
        Centres per row and rows (OpenCV's pattern size is ``(cols, rows)``).
    spacing_mm : float
        Distance between neighbouring centres of a row.
    asymmetric : bool
        OpenCV's asymmetric layout.
    diameter_mm : float
        Circle diameter (circle-grid) or the ring's outer diameter (ring-grid).
    inner_diameter_mm : float
        The ring's inner diameter (ring-grid; 0 for circles).
    polarity : str
        ``dark-on-light`` or ``light-on-dark``.
    """

    type: str
    cols: int
    rows: int
    spacing_mm: float
    asymmetric: bool = False
    diameter_mm: float = 0.0
    inner_diameter_mm: float = 0.0
    polarity: str = "dark-on-light"

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)`` as ``cv2.findCirclesGrid`` wants it."""
        return self.cols, self.rows

    def object_points(self) -> np.ndarray:
        """(rows * cols, 3) centres in OpenCV's order (row by row), z = 0."""
        i, j = np.divmod(np.arange(self.rows * self.cols), self.cols)
        x = (2 * j + i % 2) * self.spacing_mm if self.asymmetric else j * self.spacing_mm
        return np.column_stack((x, i * self.spacing_mm, np.zeros(i.size))).astype(np.float64)

    @property
    def size_mm(self) -> tuple[float, float]:
        """Width and height of the printed board (centres plus a margin of one spacing)."""
        pts = self.object_points()
        return (
            float(pts[:, 0].max() + 2 * self.spacing_mm),
            float(pts[:, 1].max() + 2 * self.spacing_mm),
        )

    def to_dict(self) -> dict:
        """The YAML description."""
        doc: dict[str, Any] = {
            "type": self.type,
            "cols": self.cols,
            "rows": self.rows,
            "spacing_mm": self.spacing_mm,
            "asymmetric": self.asymmetric,
            "polarity": self.polarity,
        }
        if self.type == "circle-grid":
            doc["diameter_mm"] = self.diameter_mm
        else:
            doc["outer_diameter_mm"] = self.diameter_mm
            doc["inner_diameter_mm"] = self.inner_diameter_mm
        return doc


Board = CodedBoard | GridBoard


def coded_board(
    rows: int, cols: int, pitch_mm: float, first_id: int = 0, polarity: str = "dark-on-light"
) -> CodedBoard:
    """``rows x cols`` markers with ids ``first_id, first_id + 1, ...`` row by row.

    Centres are at ``(pitch * (j + 1), pitch * (i + 1))``: a margin of one pitch all round.
    """
    if rows < 1 or cols < 1:
        raise BoardError(f"rows and cols must be >= 1, got {rows} x {cols}")
    if not pitch_mm > 0:
        raise BoardError(f"pitch_mm must be > 0, got {pitch_mm}")
    last = first_id + rows * cols - 1
    if first_id < 0 or last >= n_codes():
        raise BoardError(
            f"ids {first_id}..{last} do not exist: there are {n_codes()} codes (0..{n_codes() - 1})"
        )
    i, j = np.divmod(np.arange(rows * cols), cols)
    centres = np.column_stack(((j + 1) * pitch_mm, (i + 1) * pitch_mm)).astype(np.float64)
    return CodedBoard(
        ids=np.arange(first_id, last + 1),
        centers_mm=centres,
        marker_radius_mm=pitch_mm * RADIUS_PER_PITCH,
        width_mm=(cols + 1) * pitch_mm,
        height_mm=(rows + 1) * pitch_mm,
        polarity=_polarity({"polarity": polarity}),
        extra={"rows": rows, "cols": cols, "pitch_mm": pitch_mm},
    )


# ---------------------------------------------------------------------------- from YAML


def _number(doc: dict, key: str, default: float | None = None, positive: bool = True) -> float:
    if key not in doc:
        if default is None:
            raise BoardError(f"{key}: missing")
        return default
    value = doc[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise BoardError(f"{key}: expected a number, got {value!r}")
    if positive and value <= 0:
        raise BoardError(f"{key}: must be > 0, got {value!r}")
    return float(value)


def _count(doc: dict, key: str) -> int:
    value = doc.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise BoardError(f"{key}: expected a whole number >= 1, got {value!r}")
    return value


def _polarity(doc: dict) -> str:
    value = doc.get("polarity", "dark-on-light")
    if value not in POLARITIES:
        raise BoardError(f"polarity: expected one of {', '.join(POLARITIES)}, got {value!r}")
    return value


def board_from_dict(doc: Any) -> Board:
    """Validate a board description (parsed YAML) and build the board.

    Raises
    ------
    BoardError
        Naming the first missing or invalid field.
    """
    if not isinstance(doc, dict):
        raise BoardError(f"expected a mapping with a 'type', got {type(doc).__name__}")
    kind = doc.get("type")
    if kind == "coded":
        return _coded_from_dict(doc)
    if kind in ("circle-grid", "ring-grid"):
        return _grid_from_dict(doc, kind)
    raise BoardError(f"type: expected coded, circle-grid or ring-grid, got {kind!r}")


def _coded_from_dict(doc: dict) -> CodedBoard:
    markers = doc.get("markers")
    if not isinstance(markers, list) or not markers:
        raise BoardError("markers: expected a non-empty list of {id, center_mm}")
    ids, centres = [], []
    for k, entry in enumerate(markers):
        where = f"markers[{k}]"
        if not isinstance(entry, dict):
            raise BoardError(f"{where}: expected a mapping with id and center_mm")
        marker_id = entry.get("id")
        if isinstance(marker_id, bool) or not isinstance(marker_id, int):
            raise BoardError(f"{where}.id: expected a whole number, got {marker_id!r}")
        if not 0 <= marker_id < n_codes():
            raise BoardError(f"{where}.id: no such code {marker_id} (0..{n_codes() - 1})")
        centre = entry.get("center_mm")
        if (
            not isinstance(centre, list)
            or len(centre) != 2
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in centre)
        ):
            raise BoardError(f"{where}.center_mm: expected [x, y] in mm, got {centre!r}")
        ids.append(marker_id)
        centres.append([float(centre[0]), float(centre[1])])
    if len(set(ids)) != len(ids):
        dup = sorted({i for i in ids if ids.count(i) > 1})
        raise BoardError(f"markers: id(s) {dup} appear more than once")
    centres_mm = np.array(centres)
    extra = {k: doc[k] for k in ("rows", "cols", "pitch_mm") if k in doc}
    return CodedBoard(
        ids=np.array(ids, np.int64),
        centers_mm=centres_mm,
        marker_radius_mm=_number(doc, "marker_radius_mm"),
        width_mm=_number(doc, "width_mm", float(centres_mm[:, 0].max() * 1.1)),
        height_mm=_number(doc, "height_mm", float(centres_mm[:, 1].max() * 1.1)),
        polarity=_polarity(doc),
        extra=extra,
    )


def _grid_from_dict(doc: dict, kind: str) -> GridBoard:
    asym = doc.get("asymmetric", False)
    if not isinstance(asym, bool):
        raise BoardError(f"asymmetric: expected true or false, got {asym!r}")
    spacing = _number(doc, "spacing_mm")
    if kind == "circle-grid":
        outer = _number(doc, "diameter_mm", spacing / 2)
        inner = 0.0
    else:
        outer = _number(doc, "outer_diameter_mm", spacing * 0.6)
        inner = _number(doc, "inner_diameter_mm", outer * 0.5)
        if inner >= outer:
            raise BoardError(
                f"inner_diameter_mm: must be below outer_diameter_mm ({inner} >= {outer})"
            )
    gap = spacing * (np.sqrt(2.0) if asym else 1.0)
    if outer >= gap:
        raise BoardError(f"diameter {outer} mm: circles overlap at a spacing of {spacing} mm")
    return GridBoard(
        type=kind,
        cols=_count(doc, "cols"),
        rows=_count(doc, "rows"),
        spacing_mm=spacing,
        asymmetric=asym,
        diameter_mm=outer,
        inner_diameter_mm=inner,
        polarity=_polarity(doc),
    )
