"""The Store's repository methods on a real, migrated SQLite file."""

from __future__ import annotations

import random

import numpy as np
import pytest
from sqlalchemy import func, insert, select
from sqlalchemy.exc import IntegrityError

from labauto.store import (
    ColonyClass,
    Detection,
    IntegrityViolation,
    InvalidValue,
    NotFound,
    Pick,
    PickState,
    RunState,
    Store,
    utcnow,
)

# ---------------------------------------------------------------- plates and images


def test_add_plate_is_idempotent_by_name(store: Store):
    first = store.add_plate("P-17", "/data/p17.png")
    assert store.add_plate("P-17", "camera:1") == first
    assert store.get_plate(first.id) == first
    assert first.source == "/data/p17.png" and first.created_at.tzinfo is not None
    assert store.add_plate("P-18").id != first.id
    with pytest.raises(InvalidValue, match="plate name must not be empty"):
        store.add_plate("")


def test_add_image_is_idempotent_by_run_and_sha256(store: Store):
    plate = store.add_plate("p").id
    run_a, run_b = store.create_run("a"), store.create_run("b")
    digest = "0123456789abcdef" * 4
    image = store.add_image(plate, "a.png", 640, 480, digest, run_id=run_a)
    assert store.add_image(plate, "a.png", 640, 480, digest.upper(), run_id=run_a) == image
    other_run = store.add_image(plate, "a.png", 640, 480, digest, run_id=run_b)
    no_run = store.add_image(plate, "a.png", 640, 480, digest)
    assert len({image.id, other_run.id, no_run.id}) == 3
    assert store.add_image(plate, "a.png", 640, 480, digest) == no_run
    assert store.get_image(image.id) == image
    assert (image.width, image.height, image.run_id, image.sha256) == (640, 480, run_a, digest)
    assert store.plate_names(run_a) == ["p"] and store.plate_names(run_b) == ["p"]


@pytest.mark.parametrize(
    ("sha256", "size", "message"),
    [("abc", (1, 1), "64 hex digits, got 'abc'"), ("0" * 64, (0, 5), "must be positive, got 0x5")],
)
def test_add_image_refuses_bad_values(store: Store, sha256, size, message):
    plate = store.add_plate("p").id
    with pytest.raises(InvalidValue, match=message):
        store.add_image(plate, "a.png", *size, sha256)


def test_unknown_ids_raise_not_found(store: Store):
    with pytest.raises(NotFound, match="runs: no row with id 41"):
        store.get_run(41)
    with pytest.raises(NotFound, match="picks: no row with id 7"):
        store.set_pick_state(7, "moving")
    with pytest.raises(NotFound, match="runs: no row with id 3"):
        store.set_run_state(3, "running")


# ---------------------------------------------------------------- detections


def test_bulk_insert_of_10000_detections(store: Store, scene, detection_row):
    rng = random.Random(5)
    indices = list(range(10_000))
    rng.shuffle(indices)  # ids must follow row order, not object_index order
    rows = [detection_row(i) for i in indices]
    ids = store.add_detections(scene.run_id, scene.image_id, rows)

    assert len(ids) == 10_000 and len(set(ids)) == 10_000
    with store.engine.connect() as connection:
        assert connection.execute(select(func.count()).select_from(Detection)).scalar() == 10_000
        by_id = dict(connection.execute(select(Detection.id, Detection.object_index)).all())
    assert [by_id[i] for i in ids] == indices

    stored = store.detections(scene.image_id, run_id=scene.run_id)
    assert [d.object_index for d in stored] == list(range(10_000))
    d = stored[1234]
    assert (d.centroid_x, d.centroid_y, d.n_points, d.closed, d.is_des) == (
        1244.0,
        637.0,
        40 + 1234 % 7,
        True,
        True,
    )
    assert (d.ellipse_a, d.ellipse_b, d.ellipse_angle, d.area_px) == (6.0, 4.0, 30.0, 75.4)


def test_second_batch_ids_follow_the_first(store: Store, scene, detection_row):
    first = store.add_detections(scene.run_id, scene.image_id, [detection_row(i) for i in range(3)])
    second = store.add_detections(None, scene.image_id, [detection_row(i) for i in (9, 8)])
    assert second[0] > first[-1]
    assert [d.object_index for d in store.detections(scene.image_id)] == [0, 1, 2, 8, 9]
    assert {d.run_id for d in store.detections(scene.image_id) if d.object_index > 2} == {None}


def test_detection_ellipse_in_design_form_and_numpy_values(store: Store, scene, detection_row):
    row = detection_row(0, n_points=np.int64(51), centroid_x=np.float32(3.5), is_des=np.bool_(True))
    for key in ("ellipse_cx", "ellipse_cy", "ellipse_a", "ellipse_b", "ellipse_angle"):
        del row[key]
    row["ellipse"] = {"center": [3.5, 4.0], "axes": [9.0, 2.0], "angle": 135.0}
    no_ellipse = detection_row(1, ellipse=None, d_alpha_mean=None)
    for key in ("ellipse_cx", "ellipse_cy", "ellipse_a", "ellipse_b", "ellipse_angle"):
        del no_ellipse[key]
    store.add_detections(scene.run_id, scene.image_id, [row, no_ellipse])
    first, second = store.detections(scene.image_id)
    assert (first.ellipse_cx, first.ellipse_cy, first.ellipse_a, first.ellipse_b) == (
        3.5,
        4.0,
        9.0,
        2.0,
    )
    assert first.ellipse_angle == 135.0 and first.n_points == 51 and first.is_des is True
    assert second.ellipse_a is None and second.d_alpha_mean is None


def test_detection_rows_are_checked_and_nothing_is_stored_on_error(
    store: Store, scene, detection_row
):
    good = [detection_row(i) for i in range(5)]
    with pytest.raises(InvalidValue, match=r"detections row 3: unknown field\(s\) \['colour'\]"):
        store.add_detections(scene.run_id, scene.image_id, [*good[:3], {**good[3], "colour": 1}])
    missing = dict(good[2])
    del missing["centroid_y"]
    with pytest.raises(
        InvalidValue, match=r"detections row 2: missing field\(s\) \['centroid_y'\]"
    ):
        store.add_detections(scene.run_id, scene.image_id, [*good[:2], missing])
    with pytest.raises(InvalidValue, match="'ellipse' must be"):
        store.add_detections(scene.run_id, scene.image_id, [detection_row(0, ellipse=[1, 2])])
    assert store.detections(scene.image_id) == []


def test_add_detections_of_nothing(store: Store, scene):
    assert store.add_detections(scene.run_id, scene.image_id, []) == []


# ---------------------------------------------------------------- colonies


def test_add_colonies_with_contour_array_and_classes(
    store: Store, scene, detection_row, colony_row
):
    [det_a, det_b] = store.add_detections(
        scene.run_id, scene.image_id, [detection_row(0), detection_row(1)]
    )
    contour = np.array([[1, 2], [3, 4], [5, 7]], dtype=np.int32)
    ids = store.add_colonies(
        scene.run_id,
        scene.image_id,
        [
            colony_row(0, detection_id=det_a, contour=contour),
            colony_row(1, detection_id=det_b, klass=ColonyClass.MERGED, estimated_count=3),
            colony_row(2, klass="mixed", contour=None),
        ],
    )
    colonies = store.colonies(scene.run_id)
    assert [c.id for c in colonies] == ids
    assert colonies[0].contour == [[1, 2], [3, 4], [5, 7]]
    assert colonies[0].detection_id == det_a and colonies[0].estimated_count == 1
    assert [c.klass for c in colonies] == ["authentic", "merged", "mixed"]
    assert colonies[1].estimated_count == 3 and colonies[2].contour is None


def test_add_colonies_refuses_unknown_class(store: Store, scene, colony_row):
    with pytest.raises(InvalidValue, match="colonies row 1: klass 'blob' is not one of"):
        store.add_colonies(
            scene.run_id, scene.image_id, [colony_row(0), colony_row(1, klass="blob")]
        )
    assert store.colonies(scene.run_id) == []


def test_add_colonies_with_missing_detection_stores_nothing(store: Store, scene, colony_row):
    with pytest.raises(IntegrityViolation, match="add_colonies: FOREIGN KEY constraint failed"):
        store.add_colonies(
            scene.run_id, scene.image_id, [colony_row(0), colony_row(1, detection_id=777)]
        )
    assert store.colonies(scene.run_id) == []


# ---------------------------------------------------------------- picks


@pytest.fixture
def colonies(store: Store, scene, colony_row) -> list[int]:
    return store.add_colonies(scene.run_id, scene.image_id, [colony_row(i) for i in range(4)])


def test_plan_picks_in_order_with_default_sequence(store: Store, scene, colonies):
    ids = store.plan_picks(
        scene.run_id,
        [
            {"colony_id": colonies[2], "deck_x_mm": 10.0, "deck_y_mm": 20.0},
            {"colony_id": colonies[0]},
        ],
    )
    more = store.plan_picks(scene.run_id, [{"colony_id": colonies[1], "sample_id": "S-9"}])
    picks = store.picks_for_run(scene.run_id)
    assert [p.id for p in picks] == ids + more
    assert [p.sequence for p in picks] == [0, 1, 2]
    assert [p.colony_id for p in picks] == [colonies[2], colonies[0], colonies[1]]
    assert picks[0].deck_x_mm == 10.0 and picks[2].sample_id == "S-9"
    assert all(p.state is PickState.PLANNED and not p.needs_attention for p in picks)


def test_no_colony_is_planned_twice_in_a_run(store: Store, scene, colonies):
    store.plan_picks(scene.run_id, [{"colony_id": colonies[0]}])
    with pytest.raises(InvalidValue, match=rf"\[{colonies[0]}\] are already planned in run"):
        store.plan_picks(scene.run_id, [{"colony_id": colonies[1]}, {"colony_id": colonies[0]}])
    with pytest.raises(InvalidValue, match="given more than once"):
        store.plan_picks(scene.run_id, [{"colony_id": colonies[2]}, {"colony_id": colonies[2]}])
    assert [p.colony_id for p in store.picks_for_run(scene.run_id)] == [colonies[0]]


def test_unique_run_colony_constraint_in_the_database(store: Store, scene, colonies):
    # The repository checks first; the UNIQUE constraint is the backstop.
    store.plan_picks(scene.run_id, [{"colony_id": colonies[0]}])
    duplicate = insert(Pick).values(
        run_id=scene.run_id,
        colony_id=colonies[0],
        sequence=5,
        state="planned",
        needs_attention=False,
        created_at=utcnow(),
        updated_at=utcnow(),
    )
    with (
        pytest.raises(
            IntegrityError, match=r"UNIQUE constraint failed: picks\.run_id, picks\.colony_id"
        ),
        store.engine.begin() as connection,
    ):
        connection.execute(duplicate)


def test_plan_picks_refuses_colonies_of_another_run(store: Store, scene, colonies):
    other_run = store.create_run("other")
    with pytest.raises(InvalidValue, match=rf"\[{colonies[0]}, 9999\] are not colonies of run"):
        store.plan_picks(other_run, [{"colony_id": colonies[0]}, {"colony_id": 9999}])
    with pytest.raises(NotFound):
        store.plan_picks(12345, [{"colony_id": colonies[0]}])
    assert store.picks_for_run(other_run) == []


def test_picks_in_flight_and_crash_recovery(store: Store, scene, colony_row):
    colonies = store.add_colonies(scene.run_id, scene.image_id, [colony_row(i) for i in range(5)])
    ids = store.plan_picks(scene.run_id, [{"colony_id": c} for c in colonies])
    store.set_pick_state(ids[0], "moving")
    for state in ("moving", "picked"):
        store.set_pick_state(ids[1], state)
    for pick_id in ids[2:4]:
        for state in ("moving", "picked", "delivered"):
            store.set_pick_state(pick_id, state)
    # Pick 3's result was stored, then the process died before it was marked analyzed.
    store.add_analyzer_result(ids[3], "S-3", {"od600": 0.3})
    assert [p.id for p in store.picks_in_flight(scene.run_id)] == ids[:4]

    settled = store.flag_picks_in_flight(scene.run_id)
    assert [(p.id, p.state, p.needs_attention) for p in settled] == [
        (ids[0], "unknown", True),
        (ids[1], "unknown", True),
        (ids[2], "unknown", True),
        (ids[3], "analyzed", False),  # its outcome is known: the result is stored
    ]
    assert settled[0].error == "outcome unknown after restart"
    assert store.picks_in_flight(scene.run_id) == []
    assert store.get_pick(ids[4]).state is PickState.PLANNED  # never touched: not flagged
    moves = [(e.data["from"], e.data["to"]) for e in store.events(scene.run_id, "pick.state")]
    assert moves[-4:] == [
        ("moving", "unknown"),
        ("picked", "unknown"),
        ("delivered", "unknown"),
        ("delivered", "analyzed"),
    ]
    # The operator looked at the plate: pick 0 never touched its colony, pick 1 did.
    assert store.set_pick_state(ids[0], "planned", needs_attention=False).state == "planned"
    assert store.set_pick_state(ids[1], "failed", error="operator: probe lost").state == "failed"


def test_set_pick_state_to_unknown_flags_it(store: Store, scene, colonies):
    [pick_id] = store.plan_picks(scene.run_id, [{"colony_id": colonies[0]}])
    store.set_pick_state(pick_id, "moving")
    before = store.get_pick(pick_id)
    after = store.set_pick_state(pick_id, "unknown")
    assert after.needs_attention is True
    assert after.updated_at >= before.updated_at


# ---------------------------------------------------------------- analyzer results


def test_analyzer_result_of_a_delivered_pick(store: Store, scene, colonies):
    [pick_id, other] = store.plan_picks(scene.run_id, [{"colony_id": c} for c in colonies[:2]])
    for state in ("moving", "picked", "delivered"):
        store.set_pick_state(pick_id, state)
    values = {"od600": np.float64(0.42), "spectrum": np.arange(3)}
    result_id = store.add_analyzer_result(pick_id, "S-1", values, error_code=np.int16(0))
    result = store.analyzer_result(pick_id)
    assert result is not None and result.id == result_id
    assert result.values == {"od600": 0.42, "spectrum": [0, 1, 2]}
    assert (result.sample_id, result.error_code) == ("S-1", 0)
    assert store.get_pick(pick_id).state is PickState.DELIVERED  # the caller marks it analyzed
    with pytest.raises(InvalidValue, match=f"pick {pick_id} already has analyzer result"):
        store.add_analyzer_result(pick_id, "S-1", {})
    assert store.set_pick_state(pick_id, "analyzed").state is PickState.ANALYZED
    with pytest.raises(InvalidValue, match="is 'planned': analyzer results are stored for deliv"):
        store.add_analyzer_result(other, "S-2", {})
    assert store.analyzer_result(other) is None
    assert [r.id for r in store.analyzer_results(scene.run_id)] == [result_id]


def test_values_that_are_not_json_are_refused(store: Store):
    with pytest.raises(InvalidValue, match="run config: cannot store as JSON"):
        store.create_run("r", {"callback": object()})


# ---------------------------------------------------------------- runs and events


def test_list_runs_counts_picks_by_state(store: Store, scene, colonies):
    ids = store.plan_picks(scene.run_id, [{"colony_id": c} for c in colonies])
    store.set_pick_state(ids[0], "failed", error="no colony at target")
    store.set_pick_state(ids[1], "moving")
    empty_run = store.create_run("empty")
    summaries = store.list_runs()
    assert [s.run.id for s in summaries] == [empty_run, scene.run_id]  # newest first
    assert summaries[0].picks_by_state == {} and summaries[0].picks_total == 0
    assert summaries[1].picks_by_state == {"planned": 2, "failed": 1, "moving": 1}
    assert store.run_summary(scene.run_id) == summaries[1]
    assert summaries[1].run.config == {"robot": "sim"}
    assert [s.run.id for s in store.list_runs(limit=1)] == [empty_run]


def test_latest_unfinished_run(store: Store):
    assert store.latest_unfinished_run() is None
    crashed = store.create_run("crashed while running")
    store.set_run_state(crashed, "running")
    done = store.create_run("done")
    store.set_run_state(done, "running")
    store.set_run_state(done, "succeeded")
    latest = store.latest_unfinished_run()
    assert latest is not None and latest.id == crashed and latest.state is RunState.RUNNING
    newer = store.create_run("created, not started")
    assert store.latest_unfinished_run().id == newer


def test_events_in_order_with_kind_filters(store: Store):
    run_id = store.create_run("r")
    other = store.create_run("other")
    store.record_event(run_id, "robot.tx", "G0 X10 Y20", source="robot")
    store.record_event(run_id, "robot.rx", "ok", source="robot")
    marker = store.record_event(run_id, "plate.analyzed", "12 colonies", data={"n": np.int64(12)})
    store.record_event(other, "robot.tx", "$H", source="robot")
    store.record_event(None, "app.start", "labauto started", source="cli")
    store.record_event(run_id, "robot.tx", "M8", source="robot")

    assert [e.message for e in store.events(run_id)] == ["G0 X10 Y20", "ok", "12 colonies", "M8"]
    assert [e.message for e in store.events(run_id, "robot.tx")] == ["G0 X10 Y20", "M8"]
    assert [e.kind for e in store.events(run_id, "robot.")] == ["robot.tx", "robot.rx", "robot.tx"]
    assert [e.message for e in store.events(run_id, after_id=marker)] == ["M8"]
    assert [e.message for e in store.events(None)] == ["labauto started"]
    analyzed = store.events(run_id, "plate.analyzed")[0]
    assert analyzed.data == {"n": 12} and analyzed.source == "orchestrator"
    assert analyzed.ts.tzinfo is not None
    with pytest.raises(InvalidValue, match="event kind must not be empty"):
        store.record_event(run_id, "", "x")


def test_pick_fields_are_type_checked(store: Store, scene, colonies):
    with pytest.raises(InvalidValue, match="picks row 0: field 'deck_x_mm' must be float"):
        store.plan_picks(scene.run_id, [{"colony_id": colonies[0], "deck_x_mm": "12 mm"}])
    [pick_id] = store.plan_picks(scene.run_id, [{"colony_id": colonies[0], "deck_x_mm": 12}])
    assert store.get_pick(pick_id).deck_x_mm == 12.0
    with pytest.raises(InvalidValue, match=f"pick {pick_id}: field 'sample_id' must be str"):
        store.set_pick_state(pick_id, "moving", sample_id=17)
    moved = store.set_pick_state(pick_id, "moving", deck_y_mm=np.float32(2.5), sample_id="S-3")
    assert (moved.deck_y_mm, moved.sample_id) == (2.5, "S-3")


def test_a_value_the_driver_cannot_bind_is_named(store: Store, scene, detection_row):
    with pytest.raises(InvalidValue, match=r"add_detections: .*Error binding parameter"):
        store.add_detections(scene.run_id, scene.image_id, [detection_row(0, shape=object())])
    assert store.detections(scene.image_id) == []


def test_colony_lookups_for_resume(store: Store, scene, colony_row):
    assert store.colony_ids_for_image(scene.run_id, scene.image_id) == []
    rows = [colony_row(2), colony_row(0, klass="merged"), colony_row(1, klass="merged")]
    ids = store.add_colonies(scene.run_id, scene.image_id, rows)
    assert store.colony_ids_for_image(scene.run_id, scene.image_id) == [ids[1], ids[2], ids[0]]
    assert store.colony_counts(scene.run_id) == {"authentic": 1, "merged": 2}
    other_run = store.create_run("other")
    assert store.colony_ids_for_image(other_run, scene.image_id) == []
    assert store.colony_counts(other_run) == {}


def test_latest_unfinished_run_of_a_name(store: Store):
    a = store.create_run("config-a")
    b = store.create_run("config-b")
    assert store.latest_unfinished_run(name="config-a").id == a
    assert store.latest_unfinished_run(name="config-b").id == b
    assert store.latest_unfinished_run(name="config-c") is None
    store.set_run_state(a, "failed", error="camera missing")
    assert store.latest_unfinished_run(name="config-a") is None


def test_following_the_event_log(store: Store):
    run_id = store.create_run("r")
    assert store.last_event_id(run_id, kind_prefix="control.") is None
    first = store.record_event(run_id, "control.pause", "operator asked to pause", "operator")
    store.record_event(run_id, "robot.tx", "G0 X1")
    seen = store.last_event_id(run_id, kind_prefix="control.")
    assert seen == first
    later = store.record_event(run_id, "control.stop", "operator asked to stop", "operator")
    new = store.events_after(run_id, seen, "control.")
    assert [(e.id, e.kind) for e in new] == [(later, "control.stop")]
    assert [e.kind for e in store.events_after(run_id, None, "control")] == [
        "control.pause",
        "control.stop",
    ]
    assert [e.kind for e in store.latest_events(run_id, 2)] == ["robot.tx", "control.stop"]
    assert store.latest_events(run_id, 0) == []


def test_records_to_dict_are_json_ready(store: Store, scene, colonies):
    import json

    [pick_id] = store.plan_picks(scene.run_id, [{"colony_id": colonies[0], "deck_x_mm": 5}])
    store.set_pick_state(pick_id, "moving")
    pick = store.get_pick(pick_id).to_dict()
    assert pick["state"] == "moving" and pick["deck_x_mm"] == 5.0
    assert pick["created_at"].endswith("+00:00")
    summary = store.run_summary(scene.run_id).to_dict()
    assert summary["picks_by_state"] == {"moving": 1}
    assert summary["run"]["state"] == "idle" and summary["run"]["config"] == {"robot": "sim"}
    event = store.events(scene.run_id, "pick.state")[0].to_dict()
    assert event["data"] == {"pick_id": pick_id, "from": "planned", "to": "moving"}
    json.dumps([pick, summary, event])  # no default= needed
