"""Picks and their analyzer results: plan, move through the pick state machine, recover.

Part of :class:`~labauto.store.Store` (see :mod:`labauto.store.repository` for the rules every
method follows).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from .base import StoreBase
from .errors import InvalidTransition, InvalidValue
from .models import AnalyzerResult, Colony, Event, Pick, Run
from .records import AnalyzerResultRecord, PickRecord, to_record
from .rows import RowShape, json_data, plain_scalar
from .states import PICK_TRANSITIONS, PICKS_IN_FLIGHT, PickState, member_of
from .types import utcnow

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


_PICK_FIELD_TYPES: dict[str, type] = {
    "colony_id": int,
    "sequence": int,
    "deck_x_mm": float,
    "deck_y_mm": float,
    "sample_id": str,
    "needs_attention": bool,
    "error": str,
}


def pick_fields(values: Mapping[str, Any], where: str) -> dict[str, Any]:
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


def next_sequence(session: Session, run_id: int) -> int:
    """The pick order number that comes after every pick of the run (0 for the first)."""
    last = session.scalar(select(func.max(Pick.sequence)).where(Pick.run_id == run_id))
    return 0 if last is None else last + 1


class PickStore(StoreBase):
    """Picks and analyzer results."""

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
            pick_fields(PICK_ROW.normalise(i, row, fixed), f"picks row {i}")
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
            sequence = next_sequence(session, run_id)
            now = utcnow()
            for row in prepared:
                if row["sequence"] is None:
                    row["sequence"] = sequence
                sequence = max(sequence, row["sequence"]) + 1
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
        new = member_of(PickState, new_state, "pick state")
        unknown_fields = set(fields) - PICK_UPDATABLE_FIELDS
        if unknown_fields:
            raise InvalidValue(
                f"set_pick_state: unknown field(s) {sorted(unknown_fields)}; "
                f"allowed: {sorted(PICK_UPDATABLE_FIELDS)}"
            )
        fields = pick_fields(
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
