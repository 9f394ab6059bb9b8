"""The run and pick state machines, checked for every (from, to) pair on a real database.

The expected tables are written out here, not read from labauto.store.states, so a change to
the rules must be made in both places on purpose.
"""

from __future__ import annotations

import itertools

import pytest

from labauto.store import InvalidTransition, InvalidValue, PickState, RunState, Store

RUN_ALLOWED = {
    "idle": {"running", "failed"},
    "running": {"running", "paused", "stopping", "failed", "succeeded", "completed_with_errors"},
    "paused": {"running", "stopping", "failed"},
    "stopping": {"stopped", "failed"},
    "stopped": set(),
    "failed": {"running"},  # the operator resumes a failed run (--resume ID)
    "succeeded": set(),
    "completed_with_errors": set(),
}
RUN_PATH = {  # how to reach each state from idle
    "idle": [],
    "running": ["running"],
    "paused": ["running", "paused"],
    "stopping": ["running", "stopping"],
    "stopped": ["running", "stopping", "stopped"],
    "failed": ["failed"],
    "succeeded": ["running", "succeeded"],
    "completed_with_errors": ["running", "completed_with_errors"],
}
PICK_ALLOWED = {
    "planned": {"moving", "failed"},
    "moving": {"picked", "failed", "unknown"},
    "picked": {"delivered", "failed", "unknown"},
    "delivered": {"analyzed", "failed", "unknown"},
    "analyzed": set(),
    "failed": set(),
    "unknown": {"failed", "planned"},
}
PICK_PATH = {
    "planned": [],
    "moving": ["moving"],
    "picked": ["moving", "picked"],
    "delivered": ["moving", "picked", "delivered"],
    "analyzed": ["moving", "picked", "delivered", "analyzed"],
    "failed": ["failed"],
    "unknown": ["moving", "unknown"],
}


def test_tables_cover_every_state():
    assert set(RUN_ALLOWED) == {s.value for s in RunState}
    assert set(PICK_ALLOWED) == {s.value for s in PickState}


def test_every_run_transition(store: Store):
    for current, new in itertools.product(RUN_ALLOWED, repeat=2):
        run_id = store.create_run(f"{current}->{new}")
        for step in RUN_PATH[current]:
            store.set_run_state(run_id, step)
        assert store.get_run(run_id).state == current
        if new in RUN_ALLOWED[current]:
            assert store.set_run_state(run_id, new).state == new, (current, new)
        else:
            with pytest.raises(InvalidTransition) as info:
                store.set_run_state(run_id, new)
            assert info.value.current == current and info.value.requested == new
            assert f"run {run_id}: cannot go from {current!r} to {new!r}" in str(info.value)
            assert store.get_run(run_id).state == current, (current, new)


def test_every_pick_transition(store: Store, scene, colony_row):
    pairs = list(itertools.product(PICK_ALLOWED, repeat=2))
    colony_ids = store.add_colonies(
        scene.run_id, scene.image_id, [colony_row(i) for i in range(len(pairs))]
    )
    pick_ids = store.plan_picks(scene.run_id, [{"colony_id": c} for c in colony_ids])
    for pick_id, (current, new) in zip(pick_ids, pairs, strict=True):
        for step in PICK_PATH[current]:
            store.set_pick_state(pick_id, step)
        assert store.get_pick(pick_id).state == current
        if new in PICK_ALLOWED[current]:
            assert store.set_pick_state(pick_id, new).state == new, (current, new)
        else:
            with pytest.raises(InvalidTransition, match=f"pick {pick_id}: cannot go from"):
                store.set_pick_state(pick_id, new)
            assert store.get_pick(pick_id).state == current, (current, new)


def test_run_timestamps_and_error(store: Store):
    run_id = store.create_run("r")
    assert store.get_run(run_id).started_at is None
    started = store.set_run_state(run_id, "running").started_at
    store.set_run_state(run_id, "paused")
    resumed = store.set_run_state(run_id, "running")
    assert resumed.started_at == started  # the first start is kept
    assert resumed.finished_at is None
    failed = store.set_run_state(run_id, "failed", error="robot: ALARM:2 soft limit")
    assert failed.error == "robot: ALARM:2 soft limit"
    assert failed.finished_at is not None and failed.finished_at >= started


def test_resume_of_a_crashed_running_run_is_audited(store: Store):
    run_id = store.create_run("r")
    store.set_run_state(run_id, "running")
    store.set_run_state(run_id, "running")  # the process restarted while the run was running
    events = store.events(run_id, "run.state")
    assert [(e.data["from"], e.data["to"]) for e in events] == [
        ("idle", "running"),
        ("running", "running"),
    ]
    assert events[1].message.endswith("(resumed)")


def test_state_change_writes_one_event_in_the_same_transaction(store: Store, scene, colony_row):
    [colony_id] = store.add_colonies(scene.run_id, scene.image_id, [colony_row(0)])
    [pick_id] = store.plan_picks(scene.run_id, [{"colony_id": colony_id}])
    store.set_pick_state(pick_id, "moving", deck_x_mm=12.5, deck_y_mm=40.0)
    with pytest.raises(InvalidTransition):
        store.set_pick_state(pick_id, "analyzed")
    events = store.events(scene.run_id, "pick.state")
    assert len(events) == 1  # the refused change left no event
    assert events[0].data == {
        "pick_id": pick_id,
        "from": "planned",
        "to": "moving",
        "deck_x_mm": 12.5,
        "deck_y_mm": 40.0,
    }


def test_unknown_state_names_are_refused(store: Store, scene, colony_row):
    run_id = store.create_run("r")
    with pytest.raises(InvalidValue, match="run state 'exploded' is not one of"):
        store.set_run_state(run_id, "exploded")
    [colony_id] = store.add_colonies(scene.run_id, scene.image_id, [colony_row(0)])
    [pick_id] = store.plan_picks(scene.run_id, [{"colony_id": colony_id}])
    with pytest.raises(InvalidValue, match="pick state 'lost' is not one of"):
        store.set_pick_state(pick_id, "lost")
    with pytest.raises(InvalidValue, match=r"unknown field\(s\) \['colour'\]"):
        store.set_pick_state(pick_id, "moving", colour="red")
    assert store.get_pick(pick_id).state == "planned"
