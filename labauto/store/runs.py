"""Runs and their lease: create, find, move through the run state machine, own.

Part of :class:`~labauto.store.Store` (see :mod:`labauto.store.repository` for the rules every
method follows).
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from .base import StoreBase
from .errors import InvalidTransition
from .leases import LeaseHeld, LeaseLost, LeaseOwner, StaleCheck, heartbeat_age
from .models import Event, Pick, Run
from .records import RunRecord, RunSummary, to_record
from .rows import json_data
from .states import RUN_FINAL_STATES, RUN_TRANSITIONS, PickState, RunState, member_of
from .types import utcnow


class RunStore(StoreBase):
    """Runs: their config, state and lease."""

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
        new = member_of(RunState, state, "run state")
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
