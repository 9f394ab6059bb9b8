"""Points 2, 3 and 4 of issue 12: a run is tied to its config, its plates and one process.

* Resume compares the effective config's hash: another config of the same name is refused with
  the keys that differ, unless the operator names the run (``--resume ID``).
* Plates are identified by their place in the run: two byte-identical images are two plates,
  each with its own picks, and the repeat is reported as a warning.
* A run is leased to one process: a second ``labauto run`` is refused with the owner's pid and
  host; a stale lease is taken over after the timeout with an audit event. A real device (the
  same serial port) is locked for one run at a time.
"""

from __future__ import annotations

import os
import shutil
import socket
import time
from datetime import UTC, datetime, timedelta

import pytest
from reliability_helpers import (
    db_path,
    labauto,
    query,
    workcell_config,
    write_config,
)

from labauto.drivers.grbl_sim import SimulatedGantry, TravelLimits
from labauto.errors import RunError
from labauto.orchestrator.session import check_devices, open_run
from labauto.store import Store
from labauto.store.leases import LeaseHeld, LeaseOwner, StaleCheck

pytestmark = pytest.mark.timeout(120)


def _crash_once(config, plugins, dead_pid):
    """Leave an unfinished run 1 behind, as a killed process would (its owner is dead)."""
    store = Store.open(config.database.url)
    owner = LeaseOwner("dead", dead_pid, socket.gethostname())
    run_id = store.create_run(config.name, {"name": config.name}, config_hash="0" * 64, lease=owner)
    store.set_run_state(run_id, "running")
    return store, run_id


def test_resume_with_another_config_is_refused_naming_the_difference(tmp_path, plugins):
    first = workcell_config(tmp_path, plates=1)
    store = Store.open(first.database.url)
    with open_run(first, store, plugins=plugins) as session:
        run_id = session.run_id  # opened, never executed: left unfinished (idle)
    other = workcell_config(tmp_path, plates=1, robot={"pick_z_mm": -25.0})
    with pytest.raises(RunError) as info, open_run(other, store, plugins=plugins):
        pass
    message = str(info.value)
    assert f"run {run_id} of config 'reliability' is unfinished" in message
    assert "robot.pick_z_mm: -30.0 -> -25.0" in message
    assert f"--resume {run_id}" in message and "--new" in message
    assert [s.run.id for s in store.list_runs()] == [run_id]  # nothing new was started
    # the operator names the run: it resumes with the new config, and the change is audited
    with open_run(other, store, plugins=plugins, resume_id=run_id) as session:
        assert session.resumed and session.run_id == run_id
        outcome = session.execute()
    assert outcome.state == "succeeded"
    changed = store.events(run_id, "run.config_changed")
    assert len(changed) == 1 and "robot.pick_z_mm: -30.0 -> -25.0" in changed[0].message
    # the same config resumes silently: a new run with the same name and config starts fresh
    with open_run(other, store, plugins=plugins) as session:
        assert not session.resumed


def test_byte_identical_plates_are_two_plates_with_their_own_picks(tmp_path, plugins):
    config = workcell_config(tmp_path, plates=1, picking={"max_picks": 2})
    folder = tmp_path / "plates"
    original = next(folder.glob("*.png"))
    shutil.copy(original, folder / "zz_same_frame.png")
    store = Store.open(config.database.url)
    with open_run(config, store, plugins=plugins) as session:
        outcome = session.execute()
    assert outcome.state == "succeeded"
    db = db_path(config)
    images = query(db, "select position, path, sha256 from images order by position")
    assert [(p, name) for p, name, _ in images] == [(0, original.stem), (1, "zz_same_frame")]
    assert images[0][2] == images[1][2]  # the same pixels...
    per_image = query(
        db,
        "select c.image_id, count(*) from picks p join colonies c on c.id = p.colony_id "
        "group by c.image_id order by c.image_id",
    )
    assert [n for _, n in per_image] == [2, 2]  # ...but two plates, each picked
    warning = store.events(outcome.run_id, "plate.repeated_frame")
    assert len(warning) == 1 and "has exactly the pixels of" in warning[0].message


def test_a_second_process_is_refused_with_the_owners_pid_and_host(tmp_path):
    config = workcell_config(
        tmp_path,
        plates=1,
        analyzer={"simulator": {"speed_factor": 1.0, "analysis_seconds": 8.0}},
    )
    config_file = write_config(config, tmp_path / "run.yaml")
    db = db_path(config)
    first = labauto("run", "--config", str(config_file), cwd=tmp_path)
    try:
        deadline = datetime.now(UTC) + timedelta(seconds=60)
        while datetime.now(UTC) < deadline:
            try:
                if query(db, "select 1 from picks where state = 'delivered'"):
                    break
            except Exception:
                pass
            time.sleep(0.02)
        second = labauto("run", "--config", str(config_file), cwd=tmp_path)
        _, err = second.communicate(timeout=60)
        assert second.returncode == 1
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("labauto: error: run 1 is owned by pid")
        assert f"pid {first.pid} on host {socket.gethostname()}" in lines[0]
        _, first_err = first.communicate(timeout=60)
        assert first.returncode == 0, first_err  # the first run was not disturbed
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    assert query(db, "select id, state, lease_token from runs") == [(1, "succeeded", None)]


def test_a_stale_lease_is_taken_over_after_the_timeout_with_an_audit_event(tmp_path):
    config = workcell_config(tmp_path, plates=1)
    store = Store.open(config.database.url)
    elsewhere = LeaseOwner("other-host", 4242, "another-host.example")
    run_id = store.create_run(config.name, lease=elsewhere)
    me = LeaseOwner.this_process()
    stale = StaleCheck(timeout_s=0.5)
    with pytest.raises(LeaseHeld) as info:  # alive as far as we can tell: its heartbeat is fresh
        store.take_lease(run_id, me, stale)
    assert "owned by pid 4242 on host another-host.example" in str(info.value)
    with store.engine.begin() as connection:  # time passes without a heartbeat
        old = (datetime.now(UTC) - timedelta(seconds=5)).replace(tzinfo=None)
        connection.exec_driver_sql(
            "update runs set lease_heartbeat_at = ? where id = ?", (old, run_id)
        )
    assert store.take_lease(run_id, me, stale) == "pid 4242 on host another-host.example"
    event = store.events(run_id, "run.lease")[-1]
    assert "taken over from pid 4242 on host another-host.example" in event.message
    assert "last heartbeat was" in event.message
    assert store.get_run(run_id).lease_pid == os.getpid()
    with pytest.raises(Exception, match="taken over"):  # the old owner's heartbeat now fails
        store.heartbeat(run_id, elsewhere)


def test_a_dead_owner_on_this_host_is_taken_over_at_once(tmp_path, plugins, dead_pid):
    config = workcell_config(tmp_path, plates=1)
    store, run_id = _crash_once(config, plugins, dead_pid)
    store.set_run_config(run_id, None, None)  # a run of before the hash: resumable by name
    with open_run(config, store, plugins=plugins) as session:
        assert session.run_id == run_id and session.resumed
        assert session.execute().state == "succeeded"
    event = store.events(run_id, "run.lease")[0]
    assert f"pid {dead_pid} on {socket.gethostname()} does not exist" in event.message


def test_one_serial_port_is_driven_by_one_run_at_a_time(tmp_path, plugins):
    # the config's travel (0-300, 0-200 mm): a build with HOMING_FORCE_SET_ORIGIN
    limits = TravelLimits(x=(0.0, 300.0), y=(0.0, 200.0), z=(-50.0, 0.0))
    gantry = SimulatedGantry(speed_factor=400.0, limits=limits)
    port = gantry.start_pty()
    try:
        lock_dir = str(tmp_path / "locks")
        real_robot = {"simulate": False, "port": port}
        first = workcell_config(
            tmp_path / "a", plates=1, robot=real_robot, run={"lock_dir": lock_dir}
        )
        second = workcell_config(
            tmp_path / "b", plates=1, robot=real_robot, run={"lock_dir": lock_dir}
        )
        store_a, store_b = Store.open(first.database.url), Store.open(second.database.url)
        with open_run(first, store_a, plugins=plugins) as session:
            with pytest.raises(RunError) as info, open_run(second, store_b, plugins=plugins):
                pass
            assert f"robot {os.path.realpath(port)} is in use by a run of config" in str(info.value)
            assert f"pid {os.getpid()}" in str(info.value)
            assert session.execute().state == "succeeded"
            with pytest.raises(RunError, match="is in use by a run of config"):
                check_devices(second, plugins)  # not even a check talks to a busy port
        assert store_b.list_runs() == []  # the refused run left nothing behind
        # released when the first run ended: the second can now use the port
        with open_run(second, store_b, plugins=plugins) as session:
            assert session.execute().state == "succeeded"
    finally:
        gantry.stop()


@pytest.mark.parametrize("heartbeat_s", [0.1, 30.0])
def test_a_run_whose_lease_is_taken_over_stops_at_the_next_safe_point(
    tmp_path, plugins, heartbeat_s
):
    # with a 30 s heartbeat the keeper's thread never beats during the run: the safe point's
    # own look at the lease stops it, before the next pick moves the robot
    config = workcell_config(
        tmp_path,
        plates=2,
        run={"heartbeat_s": heartbeat_s, "lease_timeout_s": 3 * heartbeat_s + 0.2},
        analyzer={"simulator": {"speed_factor": 2.0, "analysis_seconds": 1.0}},
    )
    store = Store.open(config.database.url)
    intruder = LeaseOwner("intruder", 4243, "another-host.example")

    def take_over() -> None:  # another process decides the lease is stale and takes it
        store.take_lease(1, intruder, StaleCheck(timeout_s=0.5, is_dead=lambda pid, host: True))

    from reliability_helpers import Trigger

    with open_run(config, store, plugins=plugins, reporter=Trigger("pick.done", take_over)) as s:
        outcome = s.execute()
    assert outcome.state == "stopped"  # it did not go on driving the workcell
    moved = [p for p in store.picks_for_run(1) if p.state != "planned"]
    assert len(moved) == 1  # the pick during which the lease was taken, and no other
    lost = [e.message for e in store.events(1, "run.lease")]
    assert any("was taken over by pid 4243 on host another-host.example" in m for m in lost)
    assert store.get_run(1).lease_pid == 4243  # the intruder keeps it; ours was not released


def test_runs_show_names_the_owner_of_a_leased_run(tmp_path, capsys):
    from labauto.cli.main import main

    config = workcell_config(tmp_path, plates=1)
    store = Store.open(config.database.url)
    store.create_run(config.name, lease=LeaseOwner("t", 4244, "bench-7"))
    config_file = write_config(config, tmp_path / "c.yaml")
    assert main(["runs", "show", "1", "--config", str(config_file)]) == 0
    assert "owned by pid 4244 on host bench-7" in capsys.readouterr().out
