"""Colony-picking runs with the real drivers against simulated devices over a pty and TCP.

Each test runs a real run: the plate analysis on a bundled sample plate, a SQLite file migrated
by Alembic, the GRBL driver talking to the simulated gantry through a pseudo-terminal and the
Modbus driver talking to the simulated analyzer over TCP.
"""

from __future__ import annotations

import csv
import threading
import time

import pytest
from run_helpers import Recorder

from labauto.drivers.analyzer_sim import result_for
from labauto.errors import RunError
from labauto.orchestrator.session import open_run, request_control
from labauto.store import Store

pytestmark = pytest.mark.timeout(90)


def run(config, recorder=None, **kwargs):
    store = Store.open(config.database.url)
    with open_run(config, store, reporter=recorder, **kwargs) as session:
        outcome = session.execute()
        analyzer_map = session.runner.workcell.analyzer.map
    return store, outcome, analyzer_map


def picks_by_state(store, run_id):
    states: dict[str, int] = {}
    for pick in store.picks_for_run(run_id):
        states[str(pick.state)] = states.get(str(pick.state), 0) + 1
    return states


def test_full_run_picks_analyses_and_stores_everything(make_config):
    config = make_config(plates=2)
    store, outcome, analyzer_map = run(config)

    assert outcome.state == "succeeded" and outcome.error is None
    assert picks_by_state(store, outcome.run_id) == {"analyzed": 6}
    # every analyzer result is the simulated instrument's answer for that sample id
    results = store.analyzer_results(outcome.run_id)
    assert len(results) == 6
    for result in results:
        assert result.values == pytest.approx(result_for(analyzer_map, result.sample_id))
    # detections and colonies of both plates, colonies linked to their detections
    colonies = store.colonies(outcome.run_id)
    assert len(colonies) == 60 and all(c.detection_id is not None for c in colonies)
    assert sorted(store.plate_names(outcome.run_id)) == sorted(
        p.stem for p in (config_dir(config)).glob("*.png")
    )
    # the audit log has the steps and the device exchanges
    kinds = {e.kind for e in store.events(outcome.run_id)}
    assert {
        "calibration",
        "plate.analyzed",
        "picks.planned",
        "pick.done",
        "robot.tx",
        "robot.rx",
        "analyzer.tx",
        "analyzer.rx",
        "run.state",
    } <= kinds
    sent = [e.message for e in store.events(outcome.run_id, "robot.tx")]
    assert "$H" in sent and sum(line == "M8" for line in sent) == 12  # tool on: 6 picks + 6 drops
    # operator output: an annotated image and a CSV per plate, picked colonies marked
    picked_rows = 0
    for png in config_dir(config).glob("*.png"):
        assert (outcome.output_dir / f"{png.stem}.annotated.png").stat().st_size > 10_000
        with (outcome.output_dir / f"{png.stem}.colonies.csv").open() as handle:
            picked_rows += sum(row["picked"] == "1" for row in csv.DictReader(handle))
    assert picked_rows == 6


def config_dir(config):
    from pathlib import Path

    return Path(config.camera.path)


def test_pick_order_and_limits_follow_the_config(make_config):
    store, outcome, _ = run(make_config(picking={"max_picks": 2, "order": "smallest"}))
    picks = sorted(store.picks_for_run(outcome.run_id), key=lambda p: p.sequence)
    areas = {c.id: c.area_px for c in store.colonies(outcome.run_id)}
    assert len(picks) == 2
    assert areas[picks[0].colony_id] <= areas[picks[1].colony_id]
    authentic = [c for c in store.colonies(outcome.run_id) if c.klass == "authentic"]
    assert {p.colony_id for p in picks} <= {c.id for c in authentic}


def test_pause_waits_at_a_checkpoint_and_resume_goes_on(make_config):
    recorder = Recorder()
    config = make_config()
    store = Store.open(config.database.url)
    seen: dict[str, object] = {}
    with open_run(config, store, reporter=recorder) as session:
        control = session.control

        def resume_later():
            time.sleep(0.4)
            seen["state_while_paused"] = store.get_run(session.run_id).state
            seen["in_flight_while_paused"] = store.picks_in_flight(session.run_id)
            control.resume()

        def pause():
            control.pause()
            threading.Thread(target=resume_later).start()

        recorder.when(lambda kind, _: kind == "pick.done", pause)
        outcome = session.execute()
    assert outcome.state == "succeeded"
    assert seen["state_while_paused"] == "paused"
    assert seen["in_flight_while_paused"] == []  # paused between picks, nothing in the tool
    assert picks_by_state(store, outcome.run_id) == {"analyzed": 3}
    assert ("run.state", "paused") in recorder.events


def test_stop_ends_between_picks_with_cleanup(make_config):
    recorder = Recorder()
    config = make_config()
    store = Store.open(config.database.url)
    with open_run(config, store, reporter=recorder) as session:
        recorder.when(lambda kind, _: kind == "pick.done", session.control.stop)
        outcome = session.execute()
    assert outcome.state == "stopped" and outcome.error is None
    assert picks_by_state(store, outcome.run_id) == {"analyzed": 1, "planned": 2}
    cleanup = [e.message for e in store.events(outcome.run_id, "run.cleanup")]
    assert cleanup and cleanup[0].startswith("tool off, head raised")


def test_estop_mid_move_resets_the_robot_and_flags_the_pick(make_config):
    recorder = Recorder()
    config = make_config(robot={"simulator": {"speed_factor": 5.0}})
    store = Store.open(config.database.url)
    with open_run(config, store, reporter=recorder) as session:
        gantry = session.runner.workcell.robot.simulator

        def estop_soon():
            threading.Timer(0.15, session.control.estop).start()

        recorder.when(lambda kind, message: message.endswith(": moving"), estop_soon)
        outcome = session.execute()
    assert outcome.state == "stopped" and outcome.error == "emergency stop"
    assert "^X" in gantry.realtime_received  # the soft reset (Ctrl-X) reached the controller
    flagged = [p for p in store.picks_for_run(outcome.run_id) if p.needs_attention]
    assert len(flagged) == 1 and flagged[0].state == "unknown"
    assert picks_by_state(store, outcome.run_id) == {"unknown": 1, "planned": 2}


def test_robot_that_stops_answering_fails_one_pick_and_recovers(make_config):
    recorder = Recorder()
    config = make_config(robot={"timeout_s": 0.4})
    store = Store.open(config.database.url)
    with open_run(config, store, reporter=recorder) as session:
        gantry = session.runner.workcell.robot.simulator
        recorder.when(lambda kind, _: kind == "pick.done", lambda: gantry.inject("no_reply"))
        outcome = session.execute()
    assert outcome.state == "completed_with_errors"  # a failed pick is not a success
    assert outcome.error == "1 of 3 picks failed"
    failed = [p for p in store.picks_for_run(outcome.run_id) if p.state == "failed"]
    assert len(failed) == 1 and "no reply" in failed[0].error.lower()
    assert picks_by_state(store, outcome.run_id) == {"analyzed": 2, "failed": 1}
    assert store.events(outcome.run_id, "robot.recovered")


def test_analyzer_error_fails_the_pick_and_the_run_goes_on(make_config):
    recorder = Recorder()
    config = make_config()
    store = Store.open(config.database.url)
    with open_run(config, store, reporter=recorder) as session:
        server = session.runner.workcell.analyzer.simulator
        recorder.when(
            lambda kind, _: kind == "pick.done", lambda: server.inject_fault("error_state", code=7)
        )
        recorder.when(lambda kind, _: kind == "pick.failed", server.clear_fault)
        outcome = session.execute()
    assert outcome.state == "completed_with_errors"
    failed = [p for p in store.picks_for_run(outcome.run_id) if p.state == "failed"]
    assert len(failed) == 1 and "7" in failed[0].error
    assert picks_by_state(store, outcome.run_id) == {"analyzed": 2, "failed": 1}


def test_control_commands_arrive_through_the_audit_log(make_config):
    recorder = Recorder()
    config = make_config()
    store = Store.open(config.database.url)
    with open_run(config, store, reporter=recorder) as session:
        recorder.when(
            lambda kind, _: kind == "pick.done",
            lambda: request_control(store, session.run_id, "stop"),
        )
        outcome = session.execute()
    assert outcome.state == "stopped"
    assert store.events(outcome.run_id, "control.stop")[0].source == "operator"
    assert picks_by_state(store, outcome.run_id)["planned"] >= 1


def test_a_finished_run_cannot_be_resumed_or_controlled(make_config):
    store, outcome, _ = run(make_config(picking={"max_picks": 1}))
    with pytest.raises(RunError, match=f"run {outcome.run_id} is succeeded"):
        run(make_config(), resume_id=outcome.run_id)
    with pytest.raises(RunError, match="nothing to pause"):
        request_control(store, outcome.run_id, "pause")


def test_event_hooks_reach_an_installed_exporter(make_config):
    import labauto_sample_plugin as sample  # installed by the test setup (make install)

    before = len(sample.EVENTS)
    _, outcome, _ = run(make_config(picking={"max_picks": 2}))
    names = [name for name, kwargs in sample.EVENTS[before:] if kwargs["run_id"] == outcome.run_id]
    assert names == ["detections_stored", "pick_finished", "pick_finished", "run_finished"]
    finished = sample.EVENTS[-1][1]
    assert finished["state"] == "succeeded" and finished["summary"]["picks"] == {"analyzed": 2}


def test_unknown_driver_is_a_clear_error_and_leaves_no_run(make_config):
    from labauto.errors import PluginError

    config = make_config(analyzer={"driver": "nonexistent"})
    store = Store.open(config.database.url)
    with (
        pytest.raises(PluginError, match="no analyzer driver named 'nonexistent'"),
        open_run(config, store),
    ):
        pass
    assert store.list_runs() == []


def test_a_failed_soft_reset_during_an_estop_is_reported(make_config):
    recorder = Recorder()
    config = make_config()
    store = Store.open(config.database.url)
    with open_run(config, store, reporter=recorder) as session:

        def unplugged():
            raise ConnectionError("robot port gone")

        session.control.on_estop = unplugged
        recorder.when(lambda kind, _: kind == "pick.done", session.control.estop)
        outcome = session.execute()
    assert outcome.state == "stopped"
    assert outcome.error == "emergency stop; robot soft reset failed: robot port gone"
    events = store.events(outcome.run_id, "run.estop")
    assert any("soft reset failed" in e.message for e in events)


def test_an_analyzer_with_a_scan_cycle_from_the_config_gets_every_result(make_config):
    config = make_config(analyzer={"simulator": {"scan_cycle_s": 0.05, "speed_factor": 200.0}})
    store = Store.open(config.database.url)
    with open_run(config, store) as session:
        assert session.runner.workcell.analyzer.simulator.scan_cycle_s == 0.05
        outcome = session.execute()
    assert outcome.state == "succeeded"
    results = [p for p in store.picks_for_run(outcome.run_id) if p.state == "analyzed"]
    assert len(results) == 3
