"""Point 1 of issue 12: a crash at any commit boundary loses no plate and repeats no pick.

In-process: an uninterrupted reference run counts its committed writes; then, for EVERY commit
boundary, a fresh run is 'killed' right after that commit (:class:`CrashingStore`) and resumed
by a new session, and what was stored and planned must equal the reference run: same plates,
same detections and colonies once each, the same colonies chosen for picking, no pick started
twice. A pick that was in flight at the crash is flagged ``unknown`` for the operator (never
repeated); every other pick is analysed.

Real processes: ``labauto run`` is killed with SIGKILL again and again at varied moments and
restarted until it ends on its own; the same invariants must hold.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import time

import pytest
from reliability_helpers import (
    CrashingStore,
    SimulatedCrash,
    db_path,
    integrity_problems,
    labauto,
    plate_picture,
    query,
    workcell_config,
    write_config,
)

from labauto.orchestrator.session import open_run
from labauto.store import Store
from labauto.store.leases import LeaseOwner

pytestmark = pytest.mark.timeout(240)


def _run(config, store, plugins, owner=None):
    with open_run(config, store, plugins=plugins, owner=owner) as session:
        return session.execute()


def test_a_crash_after_any_commit_is_resumed_to_the_same_picks(tmp_path, plugins, dead_pid):
    reference_config = workcell_config(tmp_path / "reference", plates=1)
    reference_store = CrashingStore.open_crashing(reference_config.database.url)
    outcome = _run(reference_config, reference_store, plugins)
    assert outcome.state == "succeeded"
    boundaries = reference_store.commits
    reference = plate_picture(db_path(reference_config))
    assert reference["0"]["picks"], "the reference run must plan picks"
    assert boundaries >= 15

    report = []
    for boundary in range(1, boundaries + 1):
        folder = tmp_path / f"crash-{boundary:02d}"
        config = workcell_config(folder, plates=1)
        db = db_path(config)
        crashing = CrashingStore.open_crashing(config.database.url, crash_after=boundary)
        dead_owner = LeaseOwner(f"dead-{boundary}", dead_pid, os.uname().nodename)
        with pytest.raises(SimulatedCrash):
            _run(config, crashing, plugins, owner=dead_owner)
        crashing.close()
        state = query(db, "select state from runs where id = 1")[0][0]
        in_flight = query(db, "select id from picks where state in ('moving', 'picked')")
        delivered = query(
            db,
            "select id from picks where state = 'delivered' and id not in "
            "(select pick_id from analyzer_results)",
        )
        resumed = None
        if state not in ("succeeded", "completed_with_errors"):
            with Store.open(config.database.url) as store:
                resumed = _run(config, store, plugins)
            assert resumed.run_id == 1, f"boundary {boundary}: a new run was started"
        picture = plate_picture(db)
        assert picture == reference, f"boundary {boundary}: stored {picture} != {reference}"
        assert integrity_problems(db) == [], f"boundary {boundary}"
        flagged = {pick for (pick,) in in_flight + delivered}
        unknown = {
            pick for (pick,) in query(db, "select id from picks where state = 'unknown'") if pick
        }
        assert unknown == flagged, f"boundary {boundary}: unknown {unknown} != {flagged}"
        final = query(db, "select state from runs where id = 1")[0][0]
        assert final == ("completed_with_errors" if flagged else "succeeded"), boundary
        report.append((boundary, state, resumed is not None, len(flagged)))
    print(f"\ncrash windows: {len(report)} commit boundaries killed; resumed {report}")
    assert len(report) == boundaries


def _last_event(db) -> int:
    try:
        return query(db, "select coalesce(max(id), 0) from events")[0][0]
    except sqlite3.OperationalError:  # no schema yet
        return 0


def _kill_after_start(child, db, after_event: int, delay_s: float) -> bool:
    """SIGKILL ``child`` ``delay_s`` after it set its run running (unless it ended first).

    Returns True if it was killed.
    """
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and child.poll() is None:
        try:
            started = query(
                db,
                f"select 1 from events where id > {after_event} and kind = 'run.state' "
                "and json_extract(data, '$.to') = 'running'",
            )
        except sqlite3.OperationalError:
            started = []
        if started:
            break
        time.sleep(0.01)
    try:
        child.wait(timeout=delay_s)
        return False
    except subprocess.TimeoutExpired:
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=30)
        return True


def test_real_sigkills_at_varied_moments_lose_nothing_and_repeat_nothing(tmp_path):
    config = workcell_config(
        tmp_path,
        plates=2,
        picking={"max_picks": 3},
        robot={"simulator": {"speed_factor": 100.0}},
        analyzer={"simulator": {"speed_factor": 2.0, "analysis_seconds": 1.0}},
    )
    config_file = write_config(config, tmp_path / "run.yaml")
    db = db_path(config)
    # seconds after each (re)started process set the run running: devices, plates, picks.
    # Six picks of 0.5 s analysis each: a kill ends at most one pick in flight (flagged
    # unknown) and each process finishes at most about one more, so the first four kills come
    # before the run's end even on an idle machine (with four picks of 0.25 s it ended after 3)
    delays = [0.05, 0.35, 0.65, 0.95, 1.25]
    kills, runs, last = 0, 0, None
    while True:
        runs += 1
        after = _last_event(db) if db.exists() else 0
        child = labauto("run", "--config", str(config_file), cwd=tmp_path)
        delay = delays[kills] if kills < len(delays) else 120.0
        if _kill_after_start(child, db, after, delay):
            kills += 1
            child.stdout.close()
            child.stderr.close()
            try:
                states = query(db, "select state from runs")
            except sqlite3.OperationalError:  # killed before the schema was there
                states = []
            if states and states[0][0] in ("succeeded", "completed_with_errors"):
                break  # killed after its last commit: nothing left to resume
            continue
        out, err = child.communicate()
        last = (child.returncode, out, err)
        break
    assert kills >= 4, f"only {kills} kills happened before the run ended"
    assert query(db, "select count(*) from runs") == [(1,)], "a resume started a new run"
    state = query(db, "select state from runs")[0][0]
    unknown = query(db, "select count(*) from picks where state = 'unknown'")[0][0]
    assert state == ("completed_with_errors" if unknown else "succeeded"), last
    if last is not None:  # the last process ended on its own: its exit status is honest
        assert last[0] == (3 if unknown else 0), last
    assert integrity_problems(db) == []
    picture = plate_picture(db)
    assert [p["plate"] for p in picture.values()] == ["plate_101_amber", "plate_202_red_blood"]
    assert all(p["detections"] == p["colonies"] == 30 for p in picture.values())
    assert all(len(p["picks"]) == 3 for p in picture.values())
    analyzed = query(db, "select count(*) from picks where state = 'analyzed'")[0][0]
    assert analyzed + unknown == 6
    takeovers = query(db, "select message from events where kind = 'run.lease'")
    assert len(takeovers) >= 1 and all("its process is gone" in m for (m,) in takeovers)
    resumes = query(db, "select count(*) from events where kind = 'run.resumed'")[0][0]
    print(
        f"\nSIGKILL chain: {kills} kills, {runs} processes, {resumes} resumes, "
        f"{analyzed} analysed, {unknown} flagged unknown, 0 repeated"
    )
