"""The run and pick state machines, and the colony classes.

Pure Python, no database: the repository checks every state change against the tables here, and
the orchestrator may use them to decide what to do next.

Run states (the style of Opentrons' engine and Bluesky's RunEngine)::

    idle -> running -> paused -> running          (pause at a safe checkpoint, resume)
            running -> stopping -> stopped        (stop with cleanup; also from paused)
            running -> succeeded                  (every pick analysed)
            running -> completed_with_errors      (all work done, some picks failed/unknown)
            running -> running                    (resume a run that crashed while running)
    idle | running | paused | stopping -> failed  (an error can happen in any live state)
    failed -> running                             (the operator resumes it: --resume ID)

Choice: ``failed`` is reachable from every unfinished state (not only from
``running``), so a fault during a pause, during cleanup or before the start can be recorded as
what it is. ``stopped``, ``succeeded`` and ``completed_with_errors`` are final; ``failed`` is
final for the automatic resume (a new ``labauto run`` never resumes it silently) but the
operator may resume it explicitly, which moves it back to ``running``.

Pick states::

    planned -> moving -> picked -> delivered -> analyzed
    planned | moving | picked | delivered | unknown -> failed
    moving | picked | delivered -> unknown        (crash recovery: the outcome is not known)
    unknown -> planned                            (the operator confirmed the colony is untouched)

Choice: ``unknown -> planned`` lets the operator release a flagged pick for a
retry after checking the plate; nothing else leaves ``unknown`` except ``failed``. ``analyzed``
and ``failed`` are final.
"""

from __future__ import annotations

from enum import StrEnum
from typing import TypeVar

from .errors import InvalidValue


class RunState(StrEnum):
    """State of a run. Stored as its lowercase string value."""

    IDLE = "idle"
    RUNNING = "running"
    PAUSED = "paused"
    STOPPING = "stopping"
    STOPPED = "stopped"
    FAILED = "failed"
    SUCCEEDED = "succeeded"
    COMPLETED_WITH_ERRORS = "completed_with_errors"


class PickState(StrEnum):
    """State of one pick (one colony taken to the analyzer). Stored as its string value."""

    PLANNED = "planned"
    MOVING = "moving"
    PICKED = "picked"
    DELIVERED = "delivered"
    ANALYZED = "analyzed"
    FAILED = "failed"
    UNKNOWN = "unknown"


class ColonyClass(StrEnum):
    """Class of a colony: an authentic single colony, merged colonies, or a mixed colony."""

    AUTHENTIC = "authentic"
    MERGED = "merged"
    MIXED = "mixed"


RUN_TRANSITIONS: dict[RunState, frozenset[RunState]] = {
    RunState.IDLE: frozenset({RunState.RUNNING, RunState.FAILED}),
    RunState.RUNNING: frozenset(
        {
            RunState.RUNNING,  # resume after a crash
            RunState.PAUSED,
            RunState.STOPPING,
            RunState.FAILED,
            RunState.SUCCEEDED,
            RunState.COMPLETED_WITH_ERRORS,
        }
    ),
    RunState.PAUSED: frozenset({RunState.RUNNING, RunState.STOPPING, RunState.FAILED}),
    RunState.STOPPING: frozenset({RunState.STOPPED, RunState.FAILED}),
    RunState.STOPPED: frozenset(),
    RunState.FAILED: frozenset({RunState.RUNNING}),  # resumed by the operator (--resume ID)
    RunState.SUCCEEDED: frozenset(),
    RunState.COMPLETED_WITH_ERRORS: frozenset(),
}
"""For each run state, the states it may move to."""

RUN_FINAL_STATES: frozenset[RunState] = frozenset(
    {RunState.STOPPED, RunState.FAILED, RunState.SUCCEEDED, RunState.COMPLETED_WITH_ERRORS}
)
"""Run states that end a run: stopped, failed, succeeded, completed_with_errors.

All but ``failed`` are never left; a failed run can be resumed by the operator
(:data:`RUN_RESUMABLE_STATES`)."""

RUN_RESUMABLE_STATES: frozenset[RunState] = frozenset(
    {RunState.IDLE, RunState.RUNNING, RunState.PAUSED, RunState.STOPPING, RunState.FAILED}
)
"""Run states from which ``labauto run --resume ID`` may go on."""

PICK_TRANSITIONS: dict[PickState, frozenset[PickState]] = {
    PickState.PLANNED: frozenset({PickState.MOVING, PickState.FAILED}),
    PickState.MOVING: frozenset({PickState.PICKED, PickState.FAILED, PickState.UNKNOWN}),
    PickState.PICKED: frozenset({PickState.DELIVERED, PickState.FAILED, PickState.UNKNOWN}),
    PickState.DELIVERED: frozenset({PickState.ANALYZED, PickState.FAILED, PickState.UNKNOWN}),
    PickState.UNKNOWN: frozenset({PickState.FAILED, PickState.PLANNED}),
    PickState.ANALYZED: frozenset(),
    PickState.FAILED: frozenset(),
}
"""For each pick state, the states it may move to."""

PICKS_IN_FLIGHT: frozenset[PickState] = frozenset(
    {PickState.MOVING, PickState.PICKED, PickState.DELIVERED}
)
"""Pick states in which a colony has been touched but its probe has not reached the analyzer."""


E = TypeVar("E", bound=StrEnum)


def member_of(choices: type[E], value: E | str, what: str) -> E:
    """``value`` as a member of ``choices`` (:class:`RunState`, :class:`PickState`, ...).

    Raises
    ------
    InvalidValue
        ``value`` is none of them (the message names ``what``, e.g. ``"run state"``, and the
        allowed values).
    """
    try:
        return choices(value)
    except ValueError:
        raise InvalidValue(f"{what} {value!r} is not one of {[c.value for c in choices]}") from None


def can_transition_run(current: RunState | str, new: RunState | str) -> bool:
    """Return whether a run may move from ``current`` to ``new``.

    Parameters
    ----------
    current, new : RunState or str
        Run states (enum members or their string values).

    Raises
    ------
    ValueError
        If either value is not a run state.
    """
    return RunState(new) in RUN_TRANSITIONS[RunState(current)]


def can_transition_pick(current: PickState | str, new: PickState | str) -> bool:
    """Return whether a pick may move from ``current`` to ``new``.

    Parameters
    ----------
    current, new : PickState or str
        Pick states (enum members or their string values).

    Raises
    ------
    ValueError
        If either value is not a pick state.
    """
    return PickState(new) in PICK_TRANSITIONS[PickState(current)]
