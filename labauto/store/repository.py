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

The methods live with their aggregate, each a class over :class:`~labauto.store.base.StoreBase`:
runs and their lease (:mod:`.runs`), plates and images (:mod:`.plates`), detections and
colonies (:mod:`.detections`), picks and analyzer results (:mod:`.picks`), events
(:mod:`.events`), camera and deck calibrations (:mod:`.calibrations`). :class:`Store` is all of
them on one engine.
"""

from __future__ import annotations

from .calibrations import CalibrationStore
from .detections import COLONY_ROW, DETECTION_ROW, DetectionStore
from .events import EventStore
from .picks import PICK_ROW, PICK_UPDATABLE_FIELDS, PickStore
from .plates import PlateStore
from .runs import RunStore

__all__ = [
    "COLONY_ROW",
    "DETECTION_ROW",
    "PICK_ROW",
    "PICK_UPDATABLE_FIELDS",
    "Store",
]


class Store(RunStore, PlateStore, DetectionStore, PickStore, EventStore, CalibrationStore):
    """Storage of runs, plates, images, detections, colonies, picks, results, events and
    calibrations.

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
