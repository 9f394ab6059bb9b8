"""A writer process killed with SIGKILL loses at most the write in progress."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import pytest

from labauto.store import Store

WRITER = textwrap.dedent(
    """
    import sys
    from labauto.store import Store

    store = Store.open(sys.argv[1])
    run_id = store.create_run("doomed")
    store.set_run_state(run_id, "running")
    plate = store.add_plate("p").id
    image = store.add_image(plate, "p.png", 10, 10, "f" * 64, run_id=run_id).id
    rows = [
        {"object_index": i, "method": "canny", "centroid_x": 1.0, "centroid_y": 2.0,
         "n_points": 9, "closed": True, "is_des": False}
        for i in range(2000)
    ]
    print("run", run_id, flush=True)
    batch = 0
    while True:
        event_id = store.record_event(run_id, "test.tick", f"tick {batch}")
        print("event", event_id, flush=True)
        store.add_detections(run_id, image, rows)
        batch += 1
        print("batches", batch, flush=True)
    """
)


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_sigkill_loses_nothing_committed(db_url, tmp_path):
    Store.open(db_url).close()  # migrate up front so the child only writes
    child = subprocess.Popen(
        [sys.executable, "-c", WRITER, db_url],
        stdout=subprocess.PIPE,
        text=True,
    )
    reported_events: list[int] = []
    batches = 0
    try:
        assert child.stdout is not None
        run_id = int(child.stdout.readline().split()[1])
        while batches < 5:
            kind, value = child.stdout.readline().split()
            if kind == "event":
                reported_events.append(int(value))
            else:
                batches = int(value)
        # Kill in the middle of whatever comes next (an event or a 2000-row bulk insert).
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait(timeout=10)
        if child.stdout is not None:
            child.stdout.close()
    assert child.returncode == -signal.SIGKILL

    path = db_url.removeprefix("sqlite:///")
    with sqlite3.connect(path) as con:
        assert con.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        assert con.execute("PRAGMA foreign_key_check").fetchall() == []
        detections = con.execute("SELECT count(*) FROM detections").fetchone()[0]
    assert detections % 2000 == 0  # a bulk insert is stored whole or not at all
    assert detections >= 2000 * batches

    with Store.open(db_url) as store:
        stored = {e.id for e in store.events(run_id, "test.tick")}
        assert set(reported_events) <= stored
        run = store.latest_unfinished_run()
        assert run is not None and run.id == run_id and run.state == "running"
        assert store.set_run_state(run_id, "running").state == "running"  # resume
