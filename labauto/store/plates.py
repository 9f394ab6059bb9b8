"""Plates and their images, and a run's whole plate stored in one transaction.

Part of :class:`~labauto.store.Store` (see :mod:`labauto.store.repository` for the rules every
method follows).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from datetime import datetime
from typing import Any

from sqlalchemy import func, insert, select
from sqlalchemy.orm import Session

from .base import StoreBase
from .detections import DETECTION_ROW, colony_values, flatten_ellipse
from .errors import InvalidValue
from .events import event_rows
from .models import Colony, Detection, Event, Image, Pick, Plate, Run
from .picks import PICK_ROW, next_sequence, pick_fields
from .records import ImageRecord, PlateRecord, StoredPlate, to_record
from .states import PickState
from .types import utcnow

_SHA256 = re.compile(r"[0-9a-f]{64}")


class PlateStore(StoreBase):
    """Plates, their images, and :meth:`store_plate`."""

    def add_plate(self, name: str, source: str | None = None) -> PlateRecord:
        """Store a plate and return it; a plate of the same name is returned, not duplicated.

        Parameters
        ----------
        name : str
            The plate's label (barcode); unique in the database.
        source : str, optional
            Where its images come from: an image path or a camera id. Kept from the first call.
        """
        if not name:
            raise InvalidValue("plate name must not be empty")
        with self._write("add_plate") as session:
            plate = self._plate_named(session, name, source)
            return to_record(PlateRecord, plate)

    @staticmethod
    def _plate_named(session: Session, name: str, source: str | None) -> Plate:
        """The plate of this name, stored first if there is none."""
        plate = session.scalars(select(Plate).where(Plate.name == name)).first()
        if plate is None:
            plate = Plate(name=name, source=source)
            session.add(plate)
            session.flush()
        return plate

    def get_plate(self, plate_id: int) -> PlateRecord:
        """Return the plate ``plate_id``; raise :class:`NotFound` if there is none."""
        with self._read() as session:
            return to_record(PlateRecord, self._get(session, Plate, plate_id))

    def add_image(
        self,
        plate_id: int,
        path: str,
        width: int,
        height: int,
        sha256: str,
        *,
        run_id: int | None = None,
        captured_at: datetime | None = None,
        position: int | None = None,
    ) -> ImageRecord:
        """Store an image of a plate and return it; idempotent by place or by content.

        With ``position`` (the plate's place in the run), an image already stored at that place
        of the same run is returned and nothing is written. Without it, an image of the same
        content (``sha256``) in the same run (or, with ``run_id=None``, outside any run) is
        returned instead.

        Parameters
        ----------
        plate_id : int
            The plate shown.
        path : str
            Where the image file is.
        width, height : int
            Size in pixels.
        sha256 : str
            Hex SHA-256 of the image (64 hex digits, any case; stored lowercase).
        run_id : int, optional
            The run that captured it.
        captured_at : datetime, optional
            Aware capture time; now by default.
        position : int, optional
            The plate's place in the run (0, 1, ...).
        """
        digest = self._check_image(sha256, width, height)
        with self._write("add_image") as session:
            image = self._add_image(
                session, plate_id, path, width, height, digest, run_id, captured_at, position
            )
            return to_record(ImageRecord, image)

    @staticmethod
    def _check_image(sha256: str, width: int, height: int) -> str:
        digest = str(sha256).lower()
        if not _SHA256.fullmatch(digest):
            raise InvalidValue(f"image sha256 must be 64 hex digits, got {sha256!r}")
        if int(width) <= 0 or int(height) <= 0:
            raise InvalidValue(f"image size must be positive, got {width}x{height}")
        return digest

    @staticmethod
    def _add_image(
        session: Session,
        plate_id: int,
        path: str,
        width: int,
        height: int,
        digest: str,
        run_id: int | None,
        captured_at: datetime | None,
        position: int | None,
    ) -> Image:
        same_run = Image.run_id.is_(None) if run_id is None else Image.run_id == run_id
        same = Image.position == position if position is not None else Image.sha256 == digest
        existing = session.scalars(select(Image).where(same_run, same)).first()
        if existing is not None:
            return existing
        image = Image(
            plate_id=plate_id,
            run_id=run_id,
            path=str(path),
            width=int(width),
            height=int(height),
            sha256=digest,
            captured_at=captured_at or utcnow(),
            position=position,
        )
        session.add(image)
        session.flush()
        return image

    def image_at(self, run_id: int, position: int) -> ImageRecord | None:
        """Return the image stored at a place of a run, or ``None``."""
        query = select(Image).where(Image.run_id == run_id, Image.position == position)
        with self._read() as session:
            image = session.scalars(query).first()
            return None if image is None else to_record(ImageRecord, image)

    def images_with_digest(self, run_id: int, sha256: str) -> list[ImageRecord]:
        """Return a run's images whose pixels have this digest, by place."""
        query = (
            select(Image)
            .where(Image.run_id == run_id, Image.sha256 == str(sha256).lower())
            .order_by(Image.position, Image.id)
        )
        with self._read() as session:
            return [to_record(ImageRecord, i) for i in session.scalars(query)]

    def store_plate(
        self,
        run_id: int,
        *,
        position: int,
        name: str,
        source: str | None,
        path: str,
        width: int,
        height: int,
        sha256: str,
        detections: Sequence[Mapping[str, Any]],
        colonies: Sequence[Mapping[str, Any]],
        picks: Sequence[Mapping[str, Any]],
        events: Sequence[Mapping[str, Any]] = (),
    ) -> StoredPlate:
        """Store one plate of a run in ONE transaction: image, detections, colonies, picks.

        A process killed at any moment leaves either all of it or none of it, so a resumed run
        never finds a plate whose colonies are stored but whose picks are not.

        Parameters
        ----------
        run_id : int
            The run.
        position : int
            The plate's place in the run; a place already stored is refused.
        name, source : str
            The plate's label and where its image came from (see :meth:`add_plate`).
        path, width, height, sha256
            The image (see :meth:`add_image`).
        detections : sequence of mappings
            Detection rows (see :meth:`add_detections`).
        colonies : sequence of mappings
            Colony rows (see :meth:`add_colonies`); ``detection`` (optional) is the index in
            ``detections`` of the colony's detection.
        picks : sequence of mappings
            Planned pick rows (see :meth:`plan_picks`) with ``colony`` (the index in
            ``colonies``) instead of ``colony_id``.
        events : sequence of mappings
            Audit events written in the same transaction (``kind``, ``message``, optional
            ``source`` and ``data``).

        Raises
        ------
        InvalidValue
            A bad row (names it), or the place is already stored.
        """
        if not name:
            raise InvalidValue("plate name must not be empty")
        digest = self._check_image(sha256, width, height)
        detection_rows = [
            DETECTION_ROW.normalise(i, flatten_ellipse(row), {"run_id": run_id, "image_id": 0})
            for i, row in enumerate(detections)
        ]
        colony_rows, detection_refs = [], []
        for i, row in enumerate(colonies):
            row = dict(row)
            detection_refs.append(row.pop("detection", None))
            colony_rows.append(colony_values(i, row, {"run_id": run_id, "image_id": 0}))
        pick_refs = []
        for i, row in enumerate(picks):
            ref = row.get("colony")
            if not isinstance(ref, int) or not 0 <= ref < len(colony_rows):
                raise InvalidValue(f"picks row {i}: 'colony' must index the colonies, got {ref!r}")
            pick_refs.append(ref)
        with self._write("store_plate") as session:
            self._get(session, Run, run_id)
            taken = session.scalar(
                select(Image.id).where(Image.run_id == run_id, Image.position == position)
            )
            if taken is not None:
                raise InvalidValue(f"run {run_id}: plate {position} is stored already")
            plate = self._plate_named(session, name, source)
            image = self._add_image(
                session, plate.id, path, width, height, digest, run_id, None, position
            )
            for row in detection_rows:
                row["image_id"] = image.id
            detection_ids = self._insert_returning_ids(session, Detection, detection_rows)
            for row, ref in zip(colony_rows, detection_refs, strict=True):
                row["image_id"] = image.id
                if ref is not None:
                    row["detection_id"] = detection_ids[ref]
            colony_ids = self._insert_returning_ids(session, Colony, colony_rows)
            sequence = next_sequence(session, run_id)
            now = utcnow()
            pick_rows = []
            for i, (row, ref) in enumerate(zip(picks, pick_refs, strict=True)):
                fields = {k: v for k, v in row.items() if k not in ("colony", "sequence")}
                values = PICK_ROW.normalise(
                    i,
                    {**fields, "colony_id": colony_ids[ref]},
                    {"run_id": run_id, "state": PickState.PLANNED, "needs_attention": False},
                )
                values = pick_fields(values, f"picks row {i}")
                values.update(sequence=sequence, created_at=now, updated_at=now)
                sequence += 1
                pick_rows.append(values)
            pick_ids = self._insert_returning_ids(session, Pick, pick_rows)
            if events:
                session.execute(insert(Event), event_rows(run_id, events, now))
            return StoredPlate(plate.id, image.id, detection_ids, colony_ids, pick_ids)

    def get_image(self, image_id: int) -> ImageRecord:
        """Return the image ``image_id``; raise :class:`NotFound` if there is none."""
        with self._read() as session:
            return to_record(ImageRecord, self._get(session, Image, image_id))

    def plate_names(self, run_id: int) -> list[str]:
        """Return the names of the plates imaged in a run, in the order first imaged."""
        query = (
            select(Plate.name)
            .join(Image, Image.plate_id == Plate.id)
            .where(Image.run_id == run_id)
            .group_by(Plate.id, Plate.name)
            .order_by(func.min(Image.id))
        )
        with self._read() as session:
            return list(session.scalars(query))
