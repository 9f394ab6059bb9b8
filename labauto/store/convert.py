"""Rows for the store from labauto's stable JSON results (``to_dict()`` / ``--json``).

The orchestrator has a ``DetectionResult`` or ``PlateResult`` from the vision layer; these turn
their documented JSON forms into the rows :meth:`Store.add_detections` and
:meth:`Store.add_colonies` take. Detection rows are built in one place, :func:`detection_rows`;
a plate result's colonies become detections by :func:`plate_detection_rows`, which states what
a colony says about each detection field. Only the documented keys are read, so keys added to
the JSON later are ignored rather than refused.

Example::

    result = labauto.detect(image)
    rows = detection_rows(result.to_dict())
    ids = store.add_detections(run_id, image_id, rows)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from .errors import InvalidValue

_DETECTION_COPIED = (
    "n_points", "closed", "d_alpha_median", "d_alpha_mean", "centroid_inside", "is_des",
    "shape", "ellipse", "area_px",
)  # fmt: skip
_COLONY_AS_OBJECT = ("id", "centroid", "d_alpha_median", "area_px")
_COLONY_COPIED = ("area_px", "d_alpha_median", "estimated_count", "mix_score", "contour")


def _centroid(obj: Mapping[str, Any], where: str) -> tuple[float, float]:
    try:
        x, y = obj["centroid"]
    except (KeyError, TypeError, ValueError) as exc:
        raise InvalidValue(f"{where}: 'centroid' must be [x, y]") from exc
    return x, y


def _indexed_centroid(obj: Mapping[str, Any], where: str) -> tuple[Any, float, float]:
    """An object's ``id`` and ``centroid`` (x, y); InvalidValue naming ``where`` otherwise."""
    if "id" not in obj:
        raise InvalidValue(f"{where}: missing 'id'")
    x, y = _centroid(obj, where)
    return obj["id"], x, y


def detection_rows(result: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Rows for :meth:`Store.add_detections` from a detection result's JSON.

    Parameters
    ----------
    result : mapping
        ``{"method": str, "objects": [{"id", "centroid": [x, y], "n_points", "closed",
        "d_alpha_median", "d_alpha_mean", "centroid_inside", "is_des", "shape",
        "ellipse": {...} | None}, ...]}`` (``DetectionResult.to_dict()``). An object's
        ``id`` becomes ``object_index``; ``area_px`` is copied when present.

    Returns
    -------
    list of dict
        One row per object, in the order of ``objects``.

    Raises
    ------
    InvalidValue
        If ``method`` or ``objects`` is missing, or an object lacks ``id`` or ``centroid``.
    """
    try:
        method, objects = result["method"], result["objects"]
    except (KeyError, TypeError) as exc:
        raise InvalidValue("detection result must have 'method' and 'objects'") from exc
    rows = []
    for position, obj in enumerate(objects):
        index, x, y = _indexed_centroid(obj, f"detection result object {position}")
        row = {"object_index": index, "method": method, "centroid_x": x, "centroid_y": y}
        row.update((key, obj[key]) for key in _DETECTION_COPIED if key in obj)
        rows.append(row)
    return rows


def plate_detection_rows(plate: Mapping[str, Any], method: str) -> list[dict[str, Any]]:
    """Rows for :meth:`Store.add_detections` from a plate result's JSON: one per colony.

    Each colony is turned into an object of the detection JSON and passed to
    :func:`detection_rows`: ``n_points`` is the length of its contour, ``closed`` is true (a
    colony's contour is the outline of a region, closed by construction), ``is_des`` is true
    for the classes the plate analysis took as single deformed ellipses (authentic, mixed)
    and false for merged bodies. ``centroid_inside``, ``d_alpha_mean``, ``shape`` and
    ``ellipse`` are not reported by the plate analysis and stay NULL.

    Parameters
    ----------
    plate : mapping
        ``PlateResult.to_dict()`` (see :func:`colony_rows`).
    method : str
        What found them, e.g. ``"plate:canny"``.
    """
    if "colonies" not in plate:
        raise InvalidValue("plate result must have 'colonies'")
    objects = [
        {
            **{key: colony[key] for key in _COLONY_AS_OBJECT if key in colony},
            "n_points": len(colony.get("contour") or ()),
            "closed": True,
            "is_des": colony.get("class") != "merged",
        }
        for colony in plate["colonies"]
    ]
    return detection_rows({"method": method, "objects": objects})


def colony_rows(
    colonies: Sequence[Mapping[str, Any]] | Mapping[str, Any],
    detection_ids: Mapping[int, int] | None = None,
) -> list[dict[str, Any]]:
    """Rows for :meth:`Store.add_colonies` from a plate result's JSON.

    Parameters
    ----------
    colonies : sequence of mappings, or a mapping with ``"colonies"``
        ``PlateResult.to_dict()`` or its ``"colonies"`` list: ``[{"id", "centroid": [x, y],
        "class", "area_px", "d_alpha_median", "estimated_count", "mix_score",
        "contour"}, ...]``. A colony's ``id`` becomes ``colony_index`` and its ``class`` the
        column ``klass``.
    detection_ids : mapping of int to int, optional
        Colony ``id`` -> stored detection id, to link colonies to their detections.

    Returns
    -------
    list of dict
        One row per colony, in the given order.
    """
    if isinstance(colonies, Mapping):
        if "colonies" not in colonies:
            raise InvalidValue("plate result must have 'colonies'")
        colonies = colonies["colonies"]
    rows = []
    for position, colony in enumerate(colonies):
        where = f"plate result colony {position}"
        index, x, y = _indexed_centroid(colony, where)
        if "class" not in colony:
            raise InvalidValue(f"{where}: missing 'class'")
        row = {
            "colony_index": index,
            "klass": colony["class"],
            "centroid_x": x,
            "centroid_y": y,
        }
        row.update((key, colony[key]) for key in _COLONY_COPIED if key in colony)
        if detection_ids is not None and colony["id"] in detection_ids:
            row["detection_id"] = detection_ids[colony["id"]]
        rows.append(row)
    return rows
