"""Store side of issue 12: a plate stored in one transaction, plates by place, 0001 -> 0002."""

from __future__ import annotations

import sqlite3

import pytest

from labauto.store import InvalidValue, Store, current_revision, downgrade, head_revision, upgrade


def _plate(store: Store, run_id: int, position: int, *, bad_pick: bool = False, digest="ab"):
    detections = [
        {"object_index": i, "method": "plate", "centroid_x": 1.0 * i, "centroid_y": 2.0,
         "n_points": 9, "closed": True, "is_des": True}
        for i in range(3)
    ]  # fmt: skip
    colonies = [
        {"colony_index": i, "klass": "authentic", "centroid_x": 1.0 * i, "centroid_y": 2.0,
         "detection": i}
        for i in range(3)
    ]  # fmt: skip
    picks = [{"colony": 2, "deck_x_mm": 10.0, "deck_y_mm": 20.0}, {"colony": 0}]
    if bad_pick:
        picks.append({"colony": 7})  # no such colony: the whole plate must be refused
    return store.store_plate(
        run_id,
        position=position,
        name=f"plate-{position}",
        source="camera:0",
        path=f"plate-{position}",
        width=64,
        height=48,
        sha256=digest * 32,
        detections=detections,
        colonies=colonies,
        picks=picks,
        events=[{"kind": "plate.analyzed", "message": "3 colonies"}],
    )


def _counts(store: Store) -> tuple[int, ...]:
    with store.engine.connect() as connection:
        return tuple(
            connection.exec_driver_sql(f"select count(*) from {table}").scalar()
            for table in ("images", "detections", "colonies", "picks", "events")
        )


def test_a_plate_is_stored_whole_with_links_and_in_pick_order(store: Store):
    run_id = store.create_run("r")
    stored = _plate(store, run_id, 0)
    colonies = store.colonies(run_id, stored.image_id)
    assert [c.detection_id for c in colonies] == stored.detection_ids
    picks = store.picks_for_run(run_id)
    assert [p.colony_id for p in picks] == [stored.colony_ids[2], stored.colony_ids[0]]
    assert [p.sequence for p in picks] == [0, 1]
    assert store.image_at(run_id, 0).id == stored.image_id
    assert [e.kind for e in store.events(run_id)] == ["plate.analyzed"]


def test_a_bad_row_stores_nothing_of_the_plate(store: Store):
    run_id = store.create_run("r")
    before = _counts(store)
    with pytest.raises(InvalidValue, match="picks row 2: 'colony' must index the colonies"):
        _plate(store, run_id, 0, bad_pick=True)
    assert _counts(store) == before


def test_plates_are_identified_by_place_not_pixels(store: Store):
    run_id = store.create_run("r")
    first = _plate(store, run_id, 0, digest="cd")
    second = _plate(store, run_id, 1, digest="cd")  # the same pixels: still a plate of its own
    assert first.image_id != second.image_id
    assert [i.position for i in store.images_with_digest(run_id, "cd" * 32)] == [0, 1]
    with pytest.raises(InvalidValue, match="plate 1 is stored already"):
        _plate(store, run_id, 1)


def test_a_0001_database_with_runs_is_upgraded_and_keeps_its_data(db_url):
    upgrade(db_url, "0001")
    path = db_url.removeprefix("sqlite:///")
    with sqlite3.connect(path) as con:
        con.execute(
            "insert into runs (name, state, created_at) values ('old', 'running', '2026-11-30')"
        )
        con.execute("insert into plates (name, created_at) values ('p', '2026-11-30')")
        con.execute(
            "insert into images (plate_id, run_id, path, width, height, sha256, captured_at) "
            f"values (1, 1, 'p.png', 4, 4, '{'e' * 64}', '2026-11-30')"
        )
    upgrade(db_url)
    assert current_revision(db_url) == head_revision()
    with Store.open(db_url) as store:
        run = store.get_run(1)
        assert (run.name, run.state, run.config_hash, run.lease_token) == (
            "old", "running", None, None
        )  # fmt: skip
        assert store.get_image(1).position is None
        assert store.set_run_state(1, "completed_with_errors").state == "completed_with_errors"
    downgrade(db_url, "0001")  # completed_with_errors becomes failed on the way down
    with sqlite3.connect(path) as con:
        assert con.execute("select state from runs").fetchall() == [("failed",)]
