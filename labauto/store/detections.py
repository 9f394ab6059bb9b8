"""Detections and colonies of an image: bulk inserts and reads.

Part of :class:`~labauto.store.Store` (see :mod:`labauto.store.repository` for the rules every
method follows).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sqlalchemy import func, select

from .base import StoreBase
from .errors import InvalidValue
from .models import Colony, Detection
from .records import ColonyRecord, DetectionRecord, to_record
from .rows import RowShape
from .states import ColonyClass, member_of

DETECTION_ROW = RowShape(
    "detections",
    required=("object_index", "method", "centroid_x", "centroid_y", "n_points", "closed", "is_des"),
    optional=dict.fromkeys(
        (
            "d_alpha_median",
            "d_alpha_mean",
            "centroid_inside",
            "shape",
            "ellipse_cx",
            "ellipse_cy",
            "ellipse_a",
            "ellipse_b",
            "ellipse_angle",
            "area_px",
        )
    ),
)
"""Fields of a detection row (besides ``run_id`` and ``image_id``, given per call)."""

COLONY_ROW = RowShape(
    "colonies",
    required=("colony_index", "klass", "centroid_x", "centroid_y"),
    optional={
        "detection_id": None,
        "area_px": None,
        "d_alpha_median": None,
        "estimated_count": 1,
        "mix_score": None,
        "contour": None,
    },
    json_columns=("contour",),
)
"""Fields of a colony row (besides ``run_id`` and ``image_id``, given per call)."""


def flatten_ellipse(row: Mapping[str, Any]) -> Mapping[str, Any]:
    """Turn DESIGN.md's ``{"ellipse": {"center", "axes", "angle"}}`` into ``ellipse_*`` fields."""
    if "ellipse" not in row:
        return row
    flat = dict(row)
    ellipse = flat.pop("ellipse")
    if ellipse is None:
        return flat
    try:
        (cx, cy), (a, b), angle = ellipse["center"], ellipse["axes"], ellipse["angle"]
    except (KeyError, TypeError, ValueError) as exc:
        raise InvalidValue(
            f"detection field 'ellipse' must be {{'center': [x, y], 'axes': [a, b], "
            f"'angle': deg}} or None, got {ellipse!r}"
        ) from exc
    flat.update(ellipse_cx=cx, ellipse_cy=cy, ellipse_a=a, ellipse_b=b, ellipse_angle=angle)
    return flat


def colony_values(i: int, row: dict[str, Any], fixed: dict[str, Any]) -> dict[str, Any]:
    """Colony row ``i`` normalised for an insert, its class checked (``InvalidValue`` if bad)."""
    values = COLONY_ROW.normalise(i, row, fixed)
    values["klass"] = member_of(ColonyClass, values["klass"], f"colonies row {i}: klass")
    return values


class DetectionStore(StoreBase):
    """Detections and colonies."""

    def add_detections(
        self, run_id: int | None, image_id: int, rows: Sequence[Mapping[str, Any]]
    ) -> list[int]:
        """Store the detections of one image as one bulk insert; return their ids in row order.

        Parameters
        ----------
        run_id : int or None
            The run they belong to (``None`` for a detection outside a run).
        image_id : int
            The image they were found on.
        rows : sequence of mappings
            One per object. Required: ``object_index, method, centroid_x, centroid_y,
            n_points, closed, is_des``. Optional (NULL when absent): ``d_alpha_median,
            d_alpha_mean, centroid_inside, shape, area_px`` and ``ellipse_cx, ellipse_cy,
            ellipse_a, ellipse_b, ellipse_angle`` -- or instead of those five, ``ellipse`` in
            the DESIGN.md form ``{"center": [x, y], "axes": [a, b], "angle": deg}`` (or None).
            numpy scalars are accepted.

        Raises
        ------
        InvalidValue
            A row has an unknown field or lacks a required one (names the row and field).
        IntegrityViolation
            ``run_id`` or ``image_id`` does not exist. Nothing is stored then.
        """
        fixed = {"run_id": run_id, "image_id": image_id}
        prepared = [
            DETECTION_ROW.normalise(i, flatten_ellipse(row), fixed) for i, row in enumerate(rows)
        ]
        return self._bulk_insert("add_detections", Detection, prepared)

    def detections(self, image_id: int, run_id: int | None = None) -> list[DetectionRecord]:
        """Return the detections of an image (of one run, if ``run_id`` is given) by index."""
        query = select(Detection).where(Detection.image_id == image_id)
        if run_id is not None:
            query = query.where(Detection.run_id == run_id)
        with self._read() as session:
            found = session.scalars(query.order_by(Detection.object_index, Detection.id))
            return [to_record(DetectionRecord, d) for d in found]

    def add_colonies(
        self, run_id: int, image_id: int, rows: Sequence[Mapping[str, Any]]
    ) -> list[int]:
        """Store the colonies found on an image in one insert; return their ids in row order.

        Parameters
        ----------
        run_id, image_id : int
            The run and image they belong to.
        rows : sequence of mappings
            Required: ``colony_index, klass ('authentic' | 'merged' | 'mixed'), centroid_x,
            centroid_y``. Optional: ``detection_id, area_px, d_alpha_median, mix_score,
            estimated_count`` (default 1), ``contour`` (``[[x, y], ...]`` or an (N, 2) numpy
            array).

        Raises
        ------
        InvalidValue
            Unknown field, missing field or unknown class (names the row).
        IntegrityViolation
            A referenced run, image or detection does not exist. Nothing is stored then.
        """
        fixed = {"run_id": run_id, "image_id": image_id}
        prepared = []
        for i, row in enumerate(rows):
            prepared.append(colony_values(i, row, fixed))
        return self._bulk_insert("add_colonies", Colony, prepared)

    def colonies(self, run_id: int, image_id: int | None = None) -> list[ColonyRecord]:
        """Return the colonies of a run (of one image, if given), by image and colony index."""
        query = select(Colony).where(Colony.run_id == run_id)
        if image_id is not None:
            query = query.where(Colony.image_id == image_id)
        with self._read() as session:
            found = session.scalars(query.order_by(Colony.image_id, Colony.colony_index))
            return [to_record(ColonyRecord, c) for c in found]

    def colony_ids_for_image(self, run_id: int, image_id: int) -> list[int]:
        """Return the ids of a run's colonies on one image, by colony index (empty if none).

        A resumed run uses this to see that an image's colonies are stored already.
        """
        query = (
            select(Colony.id)
            .where(Colony.run_id == run_id, Colony.image_id == image_id)
            .order_by(Colony.colony_index, Colony.id)
        )
        with self._read() as session:
            return list(session.scalars(query))

    def colony_counts(self, run_id: int) -> dict[ColonyClass, int]:
        """Return the number of a run's colonies in each class (classes without any absent)."""
        query = (
            select(Colony.klass, func.count()).where(Colony.run_id == run_id).group_by(Colony.klass)
        )
        with self._read() as session:
            return {klass: count for klass, count in session.execute(query)}
