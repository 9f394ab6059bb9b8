"""The repository the orchestrator uses: one :class:`Store` per database.

Rules that hold for every method
--------------------------------
* **Every write commits before the method returns**, in one transaction of its own, so a killed
  process loses at most the write in progress. Bulk writes (``add_detections``,
  ``add_colonies``, ``plan_picks``) are all-or-nothing.
* **Reads return frozen records** (:mod:`labauto.store.records`, each with ``to_dict()``), never
  live ORM objects. Writes that create rows return their ids (bulk writes: in the order of the
  given rows); the idempotent ``add_plate`` and ``add_image`` return the stored record.
* **State changes are audited**: ``set_run_state``, ``set_pick_state`` and
  ``flag_picks_in_flight`` write a ``run.state`` / ``pick.state`` event in the same transaction
  as the change (source ``"store"``, ``data`` holding ``from``/``to``), so the audit log and
  the state can never disagree. The orchestrator need not record these events itself.
* Errors are :class:`~labauto.store.errors.StoreError` subclasses: ``NotFound`` (unknown id),
  ``InvalidTransition`` (state machine), ``InvalidValue`` (bad argument, names the field),
  ``IntegrityViolation`` (a database constraint, e.g. a foreign key), ``DatabaseUnavailable``.
* A ``Store`` may be shared by threads (each call uses its own session). On SQLite, writes take
  the write lock at ``BEGIN IMMEDIATE`` and wait up to the busy timeout for other writers.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from datetime import datetime
from typing import Any, Self

from sqlalchemy import Engine, and_, func, insert, select
from sqlalchemy.engine import URL
from sqlalchemy.exc import IntegrityError, OperationalError, StatementError
from sqlalchemy.orm import Session, sessionmaker

from .db import BEGIN_OPTION, check_connection, make_engine, safe_url, upgrade
from .errors import IntegrityViolation, InvalidTransition, InvalidValue, NotFound, StoreError
from .leases import LeaseHeld, LeaseLost, LeaseOwner, StaleCheck, heartbeat_age
from .models import AnalyzerResult, Colony, Detection, Event, Image, Pick, Plate, Run
from .records import (
    AnalyzerResultRecord,
    ColonyRecord,
    DetectionRecord,
    EventRecord,
    ImageRecord,
    PickRecord,
    PlateRecord,
    RunRecord,
    RunSummary,
    StoredPlate,
    to_record,
)
from .rows import RowShape, json_data, plain_scalar
from .states import (
    PICK_TRANSITIONS,
    PICKS_IN_FLIGHT,
    RUN_FINAL_STATES,
    RUN_TRANSITIONS,
    ColonyClass,
    PickState,
    RunState,
)
from .types import utcnow

_SHA256 = re.compile(r"[0-9a-f]{64}")

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

PICK_ROW = RowShape(
    "picks",
    required=("colony_id",),
    optional={"sequence": None, "deck_x_mm": None, "deck_y_mm": None, "sample_id": None},
)
"""Fields of a planned pick row (besides ``run_id``, given per call)."""

PICK_UPDATABLE_FIELDS = frozenset(
    {"deck_x_mm", "deck_y_mm", "sample_id", "needs_attention", "error"}
)
"""Fields :meth:`Store.set_pick_state` may change together with the state."""


def _run_state(value: RunState | str) -> RunState:
    try:
        return RunState(value)
    except ValueError:
        raise InvalidValue(
            f"run state {value!r} is not one of {[s.value for s in RunState]}"
        ) from None


def _pick_state(value: PickState | str) -> PickState:
    try:
        return PickState(value)
    except ValueError:
        raise InvalidValue(
            f"pick state {value!r} is not one of {[s.value for s in PickState]}"
        ) from None


_PICK_FIELD_TYPES: dict[str, type] = {
    "colony_id": int,
    "sequence": int,
    "deck_x_mm": float,
    "deck_y_mm": float,
    "sample_id": str,
    "needs_attention": bool,
    "error": str,
}


def _pick_fields(values: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Check the types of pick fields (None passes); ints are accepted as floats."""
    checked = {}
    for name, value in values.items():
        expected = _PICK_FIELD_TYPES.get(name)
        if value is not None and expected is not None:
            if expected is float and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            elif not isinstance(value, expected) or (expected is int and isinstance(value, bool)):
                raise InvalidValue(
                    f"{where}: field {name!r} must be {expected.__name__} or None, "
                    f"got {type(value).__name__} {value!r}"
                )
        checked[name] = value
    return checked


def _flatten_ellipse(row: Mapping[str, Any]) -> Mapping[str, Any]:
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


class Store:
    """Storage of runs, plates, images, detections, colonies, picks, results and events.

    Parameters
    ----------
    engine : sqlalchemy.Engine
        An engine from :func:`labauto.store.db.make_engine` (so SQLite gets WAL, foreign keys
        and real transactions). The schema must exist; :meth:`open` migrates it.

    Examples
    --------
    >>> store = Store.open("sqlite:///labauto.db")            # doctest: +SKIP
    >>> run_id = store.create_run("morning plates", {"robot": "sim"})   # doctest: +SKIP
    >>> store.set_run_state(run_id, "running")                # doctest: +SKIP
    """

    def __init__(self, engine: Engine) -> None:
        self._engine = engine
        self._reads = sessionmaker(engine, expire_on_commit=False)
        writer = engine.execution_options(**{BEGIN_OPTION: "IMMEDIATE"})
        self._writes = sessionmaker(writer, expire_on_commit=False)

    # ------------------------------------------------------------------ lifecycle

    @classmethod
    def open(
        cls, url: str | URL, *, migrate: bool = True, busy_timeout_s: float | None = None
    ) -> Self:
        """Open a database, migrating it to the newest schema first unless ``migrate=False``.

        Parameters
        ----------
        url : str or URL
            Any SQLAlchemy URL; ``"sqlite:///path/labauto.db"`` creates the file if needed.
            ``"sqlite://"`` is an in-memory database (migrated through the same engine).
        migrate : bool
            Run the Alembic migrations up to ``head`` (a no-op when already there).
        busy_timeout_s : float, optional
            SQLite: seconds a write waits for another writer (default 10 s).

        Raises
        ------
        DatabaseUnavailable
            Malformed URL, missing driver, or a database that cannot be opened.
        MigrationError
            A migration failed.
        """
        kwargs = {} if busy_timeout_s is None else {"busy_timeout_s": busy_timeout_s}
        engine = make_engine(url, **kwargs)
        try:
            check_connection(engine)
            if migrate:
                upgrade(engine)
        except BaseException:
            engine.dispose()
            raise
        return cls(engine)

    @property
    def engine(self) -> Engine:
        """The engine (for tests, tools and ad-hoc queries)."""
        return self._engine

    def close(self) -> None:
        """Close every pooled connection. The store must not be used afterwards."""
        self._engine.dispose()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Store({safe_url(self._engine.url)!r})"

    @contextmanager
    def _write(self, operation: str) -> Iterator[Session]:
        """One committed write transaction; database errors become StoreErrors naming it."""
        try:
            with self._writes.begin() as session:
                yield session
        except IntegrityError as exc:
            raise IntegrityViolation(f"{operation}: {exc.orig}") from exc
        except OperationalError as exc:
            raise StoreError(
                f"{operation} on {safe_url(self._engine.url)!r} failed: {exc.orig}"
            ) from exc
        except StatementError as exc:  # e.g. a value the driver cannot bind
            cause = exc.orig if exc.orig is not None else exc
            raise InvalidValue(f"{operation}: {type(cause).__name__}: {cause}") from exc

    @contextmanager
    def _read(self) -> Iterator[Session]:
        with self._reads() as session:
            yield session

    # ------------------------------------------------------------------ runs

    def create_run(
        self,
        name: str,
        config: Any = None,
        *,
        config_hash: str | None = None,
        lease: LeaseOwner | None = None,
    ) -> int:
        """Store a new run in state ``idle`` and return its id.

        Parameters
        ----------
        name : str
            A name for people (need not be unique).
        config : JSON-able, optional
            The run's configuration (dict, pydantic model, ...), stored as JSON for the audit.
        config_hash : str, optional
            SHA-256 of the effective config (what a resume is compared against).
        lease : LeaseOwner, optional
            The process that owns the new run, written in the same transaction.
        """
        config_data = json_data(config, "run config")
        with self._write("create_run") as session:
            run = Run(name=name, state=RunState.IDLE, config=config_data, config_hash=config_hash)
            if lease is not None:
                self._set_lease(run, lease, utcnow())
            session.add(run)
            session.flush()
            return run.id

    def set_run_config(self, run_id: int, config: Any, config_hash: str) -> None:
        """Replace a run's stored config and hash (the operator resumed it with another)."""
        config_data = json_data(config, "run config")
        with self._write("set_run_config") as session:
            run = self._get(session, Run, run_id, lock=True)
            run.config, run.config_hash = config_data, config_hash

    def latest_run(self, name: str) -> RunRecord | None:
        """Return the newest run of this name, whatever its state, or ``None``."""
        query = select(Run).where(Run.name == name).order_by(Run.id.desc()).limit(1)
        with self._read() as session:
            run = session.scalars(query).first()
            return None if run is None else to_record(RunRecord, run)

    # ------------------------------------------------------------------ the run lease

    @staticmethod
    def _set_lease(run: Run, owner: LeaseOwner | None, now: Any) -> None:
        run.lease_token = None if owner is None else owner.token
        run.lease_pid = None if owner is None else owner.pid
        run.lease_host = None if owner is None else owner.host
        run.lease_heartbeat_at = None if owner is None else now

    def take_lease(self, run_id: int, owner: LeaseOwner, stale: StaleCheck) -> str | None:
        """Make ``owner`` the owner of a run, in one transaction (see :mod:`.leases`).

        Returns
        -------
        str or None
            ``None`` if the lease was free or already ``owner``'s; otherwise the description of
            the stale owner it was taken from (also written as a ``run.lease`` event).

        Raises
        ------
        LeaseHeld
            Another process holds a lease that is not stale.
        """
        with self._write("take_lease") as session:
            run = self._get(session, Run, run_id, lock=True)
            now = utcnow()
            previous = None
            if run.lease_token is not None and run.lease_token != owner.token:
                is_stale, why = stale.verdict(
                    run.lease_pid, run.lease_host, run.lease_heartbeat_at, now
                )
                if not is_stale:
                    raise LeaseHeld(
                        run_id,
                        run.lease_pid,
                        run.lease_host,
                        heartbeat_age(run.lease_heartbeat_at, now),
                    )
                previous = f"pid {run.lease_pid} on host {run.lease_host}"
                session.add(
                    Event(
                        run_id=run_id,
                        ts=now,
                        kind="run.lease",
                        source="store",
                        message=f"lease taken over from {previous} by {owner.describe()}: {why}",
                        data={
                            "from": {"pid": run.lease_pid, "host": run.lease_host},
                            "to": {"pid": owner.pid, "host": owner.host},
                            "reason": why,
                        },
                    )
                )
            self._set_lease(run, owner, now)
            return previous

    def heartbeat(self, run_id: int, owner: LeaseOwner) -> None:
        """Refresh the owner's heartbeat.

        Raises
        ------
        LeaseLost
            Another process has taken the lease.
        """
        with self._write("heartbeat") as session:
            run = self._get(session, Run, run_id, lock=True)
            if run.lease_token != owner.token:
                raise LeaseLost(
                    f"run {run_id}: the lease of {owner.describe()} was taken over by "
                    f"pid {run.lease_pid} on host {run.lease_host}"
                )
            run.lease_heartbeat_at = utcnow()

    def release_lease(self, run_id: int, owner: LeaseOwner) -> None:
        """Give the lease up (a no-op if ``owner`` does not hold it)."""
        with self._write("release_lease") as session:
            run = self._get(session, Run, run_id, lock=True)
            if run.lease_token == owner.token:
                self._set_lease(run, None, None)

    def get_run(self, run_id: int) -> RunRecord:
        """Return the run ``run_id``; raise :class:`NotFound` if there is none."""
        with self._read() as session:
            return to_record(RunRecord, self._get(session, Run, run_id))

    def set_run_state(
        self, run_id: int, state: RunState | str, error: str | None = None
    ) -> RunRecord:
        """Move a run to ``state``, enforcing the run state machine, and audit the change.

        Allowed moves are :data:`labauto.store.states.RUN_TRANSITIONS`: idle->running,
        running->paused/stopping/failed/succeeded, paused->running/stopping,
        stopping->stopped, running->running (resuming a run that crashed), and ->failed from
        any unfinished state. Entering ``running`` the first time sets ``started_at``; entering
        a final state sets ``finished_at``. ``error`` (if given) is stored on the run.

        Returns
        -------
        RunRecord
            The run after the change.

        Raises
        ------
        NotFound
            No such run.
        InvalidTransition
            The move is not allowed (the message lists the allowed ones).
        """
        new = _run_state(state)
        with self._write("set_run_state") as session:
            run = self._get(session, Run, run_id, lock=True)
            old = run.state
            allowed = RUN_TRANSITIONS[old]
            if new not in allowed:
                raise InvalidTransition(
                    "run", run_id, old.value, new.value, [s.value for s in sorted(allowed)]
                )
            now = utcnow()
            run.state = new
            if new is RunState.RUNNING and run.started_at is None:
                run.started_at = now
            if new in RUN_FINAL_STATES:
                run.finished_at = now
            if error is not None:
                run.error = error
            message = f"run {run_id}: {old} -> {new}" + (" (resumed)" if old is new else "")
            if error is not None:
                message += f": {error}"
            session.add(
                Event(
                    run_id=run_id,
                    ts=now,
                    kind="run.state",
                    source="store",
                    message=message,
                    data={"from": old.value, "to": new.value, "error": error},
                )
            )
            session.flush()
            return to_record(RunRecord, run)

    def list_runs(self, limit: int | None = None) -> list[RunSummary]:
        """Return runs, newest first, each with its number of picks in each state.

        Parameters
        ----------
        limit : int, optional
            Return at most this many runs.
        """
        with self._read() as session:
            query = select(Run).order_by(Run.id.desc())
            if limit is not None:
                query = query.limit(limit)
            runs = session.scalars(query).all()
            counts = self._picks_by_state(session, [run.id for run in runs])
            return [RunSummary(to_record(RunRecord, run), counts[run.id]) for run in runs]

    def run_summary(self, run_id: int) -> RunSummary:
        """Return one run with its number of picks in each state; :class:`NotFound` if none."""
        with self._read() as session:
            run = self._get(session, Run, run_id)
            counts = self._picks_by_state(session, [run_id])
            return RunSummary(to_record(RunRecord, run), counts[run_id])

    def latest_unfinished_run(self, name: str | None = None) -> RunRecord | None:
        """Return the newest run not in a final state (idle, running, paused, stopping), if any.

        After a crash this is the run to resume.

        Parameters
        ----------
        name : str, optional
            Only runs of this name (e.g. the config's name).
        """
        query = select(Run).where(Run.state.not_in(RUN_FINAL_STATES))
        if name is not None:
            query = query.where(Run.name == name)
        with self._read() as session:
            run = session.scalars(query.order_by(Run.id.desc()).limit(1)).first()
            return None if run is None else to_record(RunRecord, run)

    @staticmethod
    def _picks_by_state(session: Session, run_ids: list[int]) -> dict[int, dict[PickState, int]]:
        counts: dict[int, dict[PickState, int]] = {run_id: {} for run_id in run_ids}
        if run_ids:
            rows = session.execute(
                select(Pick.run_id, Pick.state, func.count())
                .where(Pick.run_id.in_(run_ids))
                .group_by(Pick.run_id, Pick.state)
            )
            for run_id, state, count in rows:
                counts[run_id][state] = count
        return counts

    # ------------------------------------------------------------------ plates and images

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
            plate = session.scalars(select(Plate).where(Plate.name == name)).first()
            if plate is None:
                plate = Plate(name=name, source=source)
                session.add(plate)
                session.flush()
            return to_record(PlateRecord, plate)

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
            DETECTION_ROW.normalise(i, _flatten_ellipse(row), {"run_id": run_id, "image_id": 0})
            for i, row in enumerate(detections)
        ]
        colony_rows, detection_refs = [], []
        for i, row in enumerate(colonies):
            row = dict(row)
            detection_refs.append(row.pop("detection", None))
            colony_rows.append(_colony_values(i, row, {"run_id": run_id, "image_id": 0}))
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
            plate = session.scalars(select(Plate).where(Plate.name == name)).first()
            if plate is None:
                plate = Plate(name=name, source=source)
                session.add(plate)
                session.flush()
            image = self._add_image(
                session, plate.id, path, width, height, digest, run_id, None, position
            )
            for row in detection_rows:
                row["image_id"] = image.id
            detection_ids = (
                self._insert_returning_ids(session, Detection, detection_rows)
                if detection_rows
                else []
            )
            for row, ref in zip(colony_rows, detection_refs, strict=True):
                row["image_id"] = image.id
                if ref is not None:
                    row["detection_id"] = detection_ids[ref]
            colony_ids = (
                self._insert_returning_ids(session, Colony, colony_rows) if colony_rows else []
            )
            last = session.scalar(select(func.max(Pick.sequence)).where(Pick.run_id == run_id))
            sequence = 0 if last is None else last + 1
            now = utcnow()
            pick_rows = []
            for i, (row, ref) in enumerate(zip(picks, pick_refs, strict=True)):
                fields = {k: v for k, v in row.items() if k not in ("colony", "sequence")}
                values = PICK_ROW.normalise(
                    i,
                    {**fields, "colony_id": colony_ids[ref]},
                    {"run_id": run_id, "state": PickState.PLANNED, "needs_attention": False},
                )
                values = _pick_fields(values, f"picks row {i}")
                values.update(sequence=sequence, created_at=now, updated_at=now)
                sequence += 1
                pick_rows.append(values)
            pick_ids = self._insert_returning_ids(session, Pick, pick_rows) if pick_rows else []
            for event in events:
                session.add(
                    Event(
                        run_id=run_id,
                        ts=now,
                        kind=event["kind"],
                        source=event.get("source", "orchestrator"),
                        message=event["message"],
                        data=json_data(event.get("data"), f"event {event['kind']!r} data"),
                    )
                )
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

    # ------------------------------------------------------------------ detections and colonies

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
            DETECTION_ROW.normalise(i, _flatten_ellipse(row), fixed) for i, row in enumerate(rows)
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
            prepared.append(_colony_values(i, row, fixed))
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

    # ------------------------------------------------------------------ picks

    def plan_picks(self, run_id: int, rows: Sequence[Mapping[str, Any]]) -> list[int]:
        """Plan picks (state ``planned``) for colonies of a run; return their ids in row order.

        All or nothing: if any colony is not of this run, or is already planned in it (or
        appears twice in ``rows``), nothing is stored.

        Parameters
        ----------
        run_id : int
            The run.
        rows : sequence of mappings
            Required: ``colony_id``. Optional: ``sequence`` (pick order; by default the rows
            continue the run's existing sequence in the order given), ``deck_x_mm``,
            ``deck_y_mm``, ``sample_id``.

        Raises
        ------
        NotFound
            No such run.
        InvalidValue
            A colony of another run or no colony at all, or a colony planned twice (names
            the colony ids).
        """
        fixed = {"run_id": run_id, "state": PickState.PLANNED, "needs_attention": False}
        prepared = [
            _pick_fields(PICK_ROW.normalise(i, row, fixed), f"picks row {i}")
            for i, row in enumerate(rows)
        ]
        if not prepared:
            return []
        colony_ids = [row["colony_id"] for row in prepared]
        repeated = sorted({c for c in colony_ids if colony_ids.count(c) > 1})
        if repeated:
            raise InvalidValue(f"plan_picks: colony id(s) {repeated} given more than once")
        with self._write("plan_picks") as session:
            self._get(session, Run, run_id)
            own = set(
                session.scalars(
                    select(Colony.id).where(Colony.run_id == run_id, Colony.id.in_(colony_ids))
                )
            )
            foreign = sorted(set(colony_ids) - own)
            if foreign:
                raise InvalidValue(
                    f"plan_picks: colony id(s) {foreign} are not colonies of run {run_id}"
                )
            planned = sorted(
                session.scalars(
                    select(Pick.colony_id).where(
                        Pick.run_id == run_id, Pick.colony_id.in_(colony_ids)
                    )
                )
            )
            if planned:
                raise InvalidValue(
                    f"plan_picks: colony id(s) {planned} are already planned in run {run_id}"
                )
            last = session.scalar(select(func.max(Pick.sequence)).where(Pick.run_id == run_id))
            next_sequence = 0 if last is None else last + 1
            now = utcnow()
            for row in prepared:
                if row["sequence"] is None:
                    row["sequence"] = next_sequence
                next_sequence = max(next_sequence, row["sequence"]) + 1
                row["created_at"] = row["updated_at"] = now
            return self._insert_returning_ids(session, Pick, prepared)

    def get_pick(self, pick_id: int) -> PickRecord:
        """Return the pick ``pick_id``; raise :class:`NotFound` if there is none."""
        with self._read() as session:
            return to_record(PickRecord, self._get(session, Pick, pick_id))

    def set_pick_state(self, pick_id: int, new_state: PickState | str, **fields: Any) -> PickRecord:
        """Move a pick to ``new_state``, enforcing the pick state machine, and audit the change.

        Allowed moves are :data:`labauto.store.states.PICK_TRANSITIONS`:
        planned->moving->picked->delivered->analyzed; any unfinished state->failed;
        moving/picked/delivered->unknown (crash recovery); unknown->planned (the operator
        released it). Moving to ``unknown`` sets ``needs_attention=True`` unless given.

        Parameters
        ----------
        pick_id : int
            The pick.
        new_state : PickState or str
            The state to enter.
        **fields
            Columns to change in the same write: ``deck_x_mm, deck_y_mm, sample_id,
            needs_attention, error``.

        Returns
        -------
        PickRecord
            The pick after the change.

        Raises
        ------
        NotFound, InvalidTransition, InvalidValue
            Unknown pick, a move not allowed, an unknown field.
        """
        new = _pick_state(new_state)
        unknown_fields = set(fields) - PICK_UPDATABLE_FIELDS
        if unknown_fields:
            raise InvalidValue(
                f"set_pick_state: unknown field(s) {sorted(unknown_fields)}; "
                f"allowed: {sorted(PICK_UPDATABLE_FIELDS)}"
            )
        fields = _pick_fields(
            {name: plain_scalar(value) for name, value in fields.items()}, f"pick {pick_id}"
        )
        if new is PickState.UNKNOWN:
            fields.setdefault("needs_attention", True)
        with self._write("set_pick_state") as session:
            pick = self._get(session, Pick, pick_id, lock=True)
            self._move_pick(session, pick, new, fields)
            session.flush()
            return to_record(PickRecord, pick)

    def picks_for_run(self, run_id: int) -> list[PickRecord]:
        """Return every pick of a run in pick order (``sequence``)."""
        return self._picks(run_id, None)

    def picks_in_flight(self, run_id: int) -> list[PickRecord]:
        """Return the picks of a run that are moving, picked or delivered, in pick order."""
        return self._picks(run_id, PICKS_IN_FLIGHT)

    def flag_picks_in_flight(
        self, run_id: int, reason: str = "outcome unknown after restart"
    ) -> list[PickRecord]:
        """Crash recovery: settle every in-flight pick of a run, in one transaction.

        A ``delivered`` pick whose analyzer result is already stored (the process died between
        ``add_analyzer_result`` and ``set_pick_state(..., "analyzed")``) becomes ``analyzed``:
        its outcome is known. Every other moving/picked/delivered pick becomes ``unknown``
        with ``needs_attention=True`` and ``error=reason``. Each change writes its
        ``pick.state`` event. Call this when resuming a run, so that no pick whose outcome is
        unknown is repeated blindly.

        Returns
        -------
        list of PickRecord
            The picks changed, after the change, in pick order.
        """
        with self._write("flag_picks_in_flight") as session:
            picks = session.scalars(
                select(Pick)
                .where(Pick.run_id == run_id, Pick.state.in_(PICKS_IN_FLIGHT))
                .order_by(Pick.sequence, Pick.id)
                .with_for_update()
            ).all()
            with_result = set(
                session.scalars(
                    select(AnalyzerResult.pick_id).where(
                        AnalyzerResult.pick_id.in_([p.id for p in picks])
                    )
                )
            )
            for pick in picks:
                if pick.state is PickState.DELIVERED and pick.id in with_result:
                    self._move_pick(session, pick, PickState.ANALYZED, {})
                else:
                    flags = {"needs_attention": True, "error": reason}
                    self._move_pick(session, pick, PickState.UNKNOWN, flags)
            session.flush()
            return [to_record(PickRecord, pick) for pick in picks]

    # ------------------------------------------------------------------ analyzer results

    def add_analyzer_result(
        self, pick_id: int, sample_id: str, values: Any, error_code: int | None = None
    ) -> int:
        """Store the analyzer's result for a delivered pick; return the result's id.

        The pick's state is not changed: call ``set_pick_state(pick_id, "analyzed")`` next.
        (If the process dies in between, :meth:`flag_picks_in_flight` finds the result and
        marks the pick analyzed.) At most one result is stored per pick.

        Parameters
        ----------
        pick_id : int
            A pick in state ``delivered``.
        sample_id : str
            The sample id the analyzer reported.
        values : JSON-able
            The result values (e.g. ``{"od600": 0.42}``); numpy values are accepted.
        error_code : int, optional
            The analyzer's error code, if it reported one.

        Raises
        ------
        NotFound
            No such pick.
        InvalidValue
            The pick is not ``delivered``, or already has a result.
        """
        values_data = json_data(values, "analyzer result values")
        with self._write("add_analyzer_result") as session:
            pick = self._get(session, Pick, pick_id, lock=True)
            if pick.state is not PickState.DELIVERED:
                raise InvalidValue(
                    f"pick {pick_id} is {pick.state.value!r}: analyzer results are stored "
                    "for delivered picks only"
                )
            already = session.scalar(
                select(AnalyzerResult.id).where(AnalyzerResult.pick_id == pick_id)
            )
            if already is not None:
                raise InvalidValue(f"pick {pick_id} already has analyzer result {already}")
            result = AnalyzerResult(
                pick_id=pick_id,
                sample_id=str(sample_id),
                values=values_data,
                error_code=None if error_code is None else int(error_code),
            )
            session.add(result)
            session.flush()
            return result.id

    def analyzer_result(self, pick_id: int) -> AnalyzerResultRecord | None:
        """Return the analyzer result of a pick, or ``None`` if it has none."""
        with self._read() as session:
            result = session.scalars(
                select(AnalyzerResult).where(AnalyzerResult.pick_id == pick_id)
            ).first()
            return None if result is None else to_record(AnalyzerResultRecord, result)

    def analyzer_results(self, run_id: int) -> list[AnalyzerResultRecord]:
        """Return the analyzer results of a run's picks, in the order they were stored."""
        query = (
            select(AnalyzerResult)
            .join(Pick, Pick.id == AnalyzerResult.pick_id)
            .where(Pick.run_id == run_id)
            .order_by(AnalyzerResult.id)
        )
        with self._read() as session:
            return [to_record(AnalyzerResultRecord, r) for r in session.scalars(query)]

    # ------------------------------------------------------------------ events

    def record_event(
        self,
        run_id: int | None,
        kind: str,
        message: str,
        source: str = "orchestrator",
        data: Any = None,
    ) -> int:
        """Append an event to the audit log and return its id.

        Parameters
        ----------
        run_id : int or None
            The run it belongs to (``None``: not part of a run).
        kind : str
            Dotted kind, e.g. ``"plate.analyzed"``, ``"robot.tx"``, ``"analyzer.rx"``.
        message : str
            Human-readable text (for a device exchange: the line sent or received).
        source : str
            Who wrote it (component or device name).
        data : JSON-able, optional
            Structured details.
        """
        if not kind:
            raise InvalidValue("event kind must not be empty")
        data_value = json_data(data, f"event {kind!r} data")
        with self._write("record_event") as session:
            event = Event(
                run_id=run_id,
                kind=kind,
                source=source,
                message=message,
                data=data_value,
                ts=utcnow(),
            )
            session.add(event)
            session.flush()
            return event.id

    def record_events(self, run_id: int | None, events: Sequence[Mapping[str, Any]]) -> None:
        """Append many events in one transaction (e.g. a step's buffered device exchanges).

        Parameters
        ----------
        run_id : int or None
            The run they belong to.
        events : sequence of mappings
            Each with ``kind``, ``message``, ``source`` and optionally ``ts`` (an aware
            datetime: when it happened; default now) and ``data``.
        """
        if not events:
            return
        rows = []
        for position, event in enumerate(events):
            if not event.get("kind"):
                raise InvalidValue(f"event {position}: kind must not be empty")
            rows.append(
                {
                    "run_id": run_id,
                    "kind": event["kind"],
                    "source": event.get("source", "orchestrator"),
                    "message": event["message"],
                    "data": json_data(event.get("data"), f"event {position} data"),
                    "ts": event.get("ts") or utcnow(),
                }
            )
        with self._write("record_events") as session:
            session.execute(insert(Event), rows)

    def events(
        self, run_id: int | None, kind: str | None = None, *, after_id: int | None = None
    ) -> list[EventRecord]:
        """Return the events of a run in the order they were written.

        Parameters
        ----------
        run_id : int or None
            The run; ``None`` returns the events that belong to no run.
        kind : str, optional
            Only events of this kind; a kind ending in ``"."`` (e.g. ``"robot."``) selects
            every kind that starts with it.
        after_id : int, optional
            Only events with a larger id (to follow the log as it grows).
        """
        query = select(Event).where(self._event_filter(run_id, kind))
        if after_id is not None:
            query = query.where(Event.id > after_id)
        with self._read() as session:
            return [to_record(EventRecord, e) for e in session.scalars(query.order_by(Event.id))]

    def events_after(
        self, run_id: int | None, after_id: int | None, kind_prefix: str | None = None
    ) -> list[EventRecord]:
        """Return a run's events with an id above ``after_id`` (all if None), oldest first.

        For following the log as it grows. ``kind_prefix`` keeps the kinds that start with it
        (e.g. ``"control."``).
        """
        query = select(Event).where(self._event_filter(run_id, kind_prefix, prefix=True))
        if after_id is not None:
            query = query.where(Event.id > after_id)
        with self._read() as session:
            return [to_record(EventRecord, e) for e in session.scalars(query.order_by(Event.id))]

    def last_event_id(self, run_id: int | None, kind_prefix: str | None = None) -> int | None:
        """Return the id of a run's newest event (whose kind starts with ``kind_prefix``)."""
        filter_ = self._event_filter(run_id, kind_prefix, prefix=True)
        with self._read() as session:
            return session.scalar(select(func.max(Event.id)).where(filter_))

    def latest_events(self, run_id: int | None, n: int) -> list[EventRecord]:
        """Return a run's newest ``n`` events, oldest first."""
        query = (
            select(Event).where(self._event_filter(run_id, None)).order_by(Event.id.desc())
        ).limit(max(0, int(n)))
        with self._read() as session:
            return [to_record(EventRecord, e) for e in session.scalars(query)][::-1]

    # ------------------------------------------------------------------ helpers

    @staticmethod
    def _event_filter(run_id: int | None, kind: str | None, *, prefix: bool = False) -> Any:
        """WHERE clause for a run's events (``None``: no run) of a kind.

        ``kind`` matches exactly, or as a prefix if ``prefix`` or if it ends with ``"."``.
        """
        clause = Event.run_id.is_(None) if run_id is None else Event.run_id == run_id
        if kind is None:
            return clause
        if prefix or kind.endswith("."):
            return and_(clause, Event.kind.startswith(kind, autoescape=True))
        return and_(clause, Event.kind == kind)

    @staticmethod
    def _get(session: Session, model: type, row_id: int, *, lock: bool = False) -> Any:
        """Load one row by id (``lock``: SELECT ... FOR UPDATE where the backend has it)."""
        row = session.get(model, row_id, with_for_update=lock)
        if row is None:
            raise NotFound(f"{model.__tablename__}: no row with id {row_id!r}")
        return row

    @staticmethod
    def _move_pick(session: Session, pick: Pick, new: PickState, fields: Mapping[str, Any]) -> None:
        """Check and apply one pick transition with its fields, and add its event."""
        old = pick.state
        allowed = PICK_TRANSITIONS[old]
        if new not in allowed:
            raise InvalidTransition(
                "pick", pick.id, old.value, new.value, [s.value for s in sorted(allowed)]
            )
        now = utcnow()
        pick.state = new
        pick.updated_at = now
        for name, value in fields.items():
            setattr(pick, name, value)
        details = {name: json_data(value, name) for name, value in fields.items()}
        session.add(
            Event(
                run_id=pick.run_id,
                ts=now,
                kind="pick.state",
                source="store",
                message=f"pick {pick.id} (colony {pick.colony_id}): {old} -> {new}",
                data={"pick_id": pick.id, "from": old.value, "to": new.value, **details},
            )
        )

    def _picks(self, run_id: int, states: frozenset[PickState] | None) -> list[PickRecord]:
        query = select(Pick).where(Pick.run_id == run_id)
        if states is not None:
            query = query.where(Pick.state.in_(states))
        with self._read() as session:
            found = session.scalars(query.order_by(Pick.sequence, Pick.id))
            return [to_record(PickRecord, p) for p in found]

    def _bulk_insert(self, operation: str, model: type, rows: list[dict]) -> list[int]:
        if not rows:
            return []
        with self._write(operation) as session:
            return self._insert_returning_ids(session, model, rows)

    @staticmethod
    def _insert_returning_ids(session: Session, model: Any, rows: list[dict]) -> list[int]:
        """Insert ``rows`` with one executemany and return their ids in the order of ``rows``.

        On SQLite this is a plain Core executemany followed by reading the newest
        ``len(rows)`` ids: SQLite gives each new row the largest rowid so far plus one, and the
        write transaction holds the database's write lock from the first insert to the commit,
        so those ids are exactly the inserted rows, in order. It is about 4x faster than
        ``INSERT ... RETURNING`` with ordered results, which other backends use.
        """
        table = model.__table__
        if session.get_bind().dialect.name != "sqlite":
            statement = insert(model).returning(model.id, sort_by_parameter_order=True)
            return list(session.scalars(statement, rows))
        session.execute(insert(table), rows)
        newest_first = session.scalars(
            select(table.c.id).order_by(table.c.id.desc()).limit(len(rows))
        ).all()
        return newest_first[::-1]


def _colony_values(i: int, row: dict[str, Any], fixed: dict[str, Any]) -> dict[str, Any]:
    """Colony row ``i`` normalised for an insert, its class checked (``InvalidValue`` if bad)."""
    values = COLONY_ROW.normalise(i, row, fixed)
    try:
        values["klass"] = ColonyClass(values["klass"])
    except ValueError:
        raise InvalidValue(
            f"colonies row {i}: klass {values['klass']!r} is not one of "
            f"{[c.value for c in ColonyClass]}"
        ) from None
    return values
