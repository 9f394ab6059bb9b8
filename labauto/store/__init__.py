"""labauto's storage layer: SQLAlchemy 2 models, Alembic migrations and the :class:`Store`.

Typical use by the orchestrator::

    from labauto.store import Store

    store = Store.open("sqlite:///runs/labauto.db")   # migrates to the newest schema
    run_id = store.create_run("plate batch 7", config)
    store.set_run_state(run_id, "running")
    deck = store.latest_calibration("deck", "deck")   # the calibration in force, or None
    ...

See :mod:`labauto.store.repository` for the rules every method follows (commit per write,
frozen records, audited state changes) and :mod:`labauto.store.states` for the state machines.
"""

from .calibrations import StoredCalibration
from .convert import colony_rows, detection_rows, plate_detection_rows
from .db import (
    current_revision,
    downgrade,
    head_revision,
    make_engine,
    migrations_dir,
    safe_url,
    upgrade,
)
from .errors import (
    DatabaseUnavailable,
    IntegrityViolation,
    InvalidTransition,
    InvalidValue,
    MigrationError,
    NotFound,
    StoreError,
)
from .models import (
    AnalyzerResult,
    Base,
    CalibrationRecord,
    Colony,
    Detection,
    Event,
    Image,
    Pick,
    Plate,
    Run,
)
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
)
from .repository import Store
from .states import (
    PICK_TRANSITIONS,
    PICKS_IN_FLIGHT,
    RUN_FINAL_STATES,
    RUN_TRANSITIONS,
    ColonyClass,
    PickState,
    RunState,
    can_transition_pick,
    can_transition_run,
)
from .types import UTCDateTime, utcnow

__all__ = [
    "PICKS_IN_FLIGHT",
    "PICK_TRANSITIONS",
    "RUN_FINAL_STATES",
    "RUN_TRANSITIONS",
    "AnalyzerResult",
    "AnalyzerResultRecord",
    "Base",
    "CalibrationRecord",
    "Colony",
    "ColonyClass",
    "ColonyRecord",
    "DatabaseUnavailable",
    "Detection",
    "DetectionRecord",
    "Event",
    "EventRecord",
    "Image",
    "ImageRecord",
    "IntegrityViolation",
    "InvalidTransition",
    "InvalidValue",
    "MigrationError",
    "NotFound",
    "Pick",
    "PickRecord",
    "PickState",
    "Plate",
    "PlateRecord",
    "Run",
    "RunRecord",
    "RunState",
    "RunSummary",
    "Store",
    "StoreError",
    "StoredCalibration",
    "UTCDateTime",
    "can_transition_pick",
    "can_transition_run",
    "colony_rows",
    "current_revision",
    "detection_rows",
    "downgrade",
    "head_revision",
    "make_engine",
    "migrations_dir",
    "plate_detection_rows",
    "safe_url",
    "upgrade",
    "utcnow",
]
