"""Points 5 and 6 of issue 12: honest outcomes, positions checked first, outages retried.

* A run whose picks fail ends ``completed_with_errors`` with exit status 3, never
  ``succeeded``; a pick height outside the travel is refused before anything moves.
* An analyzer unreachable for 3 s is brought back by the retry policy (tries with a growing
  delay) and the run goes on; when the retries run out the run fails, a plain ``labauto run``
  refuses to start over, and ``--resume ID`` finishes it without picking a colony twice.
"""

from __future__ import annotations

import json
import threading

import pytest
from reliability_helpers import Trigger, db_path, query, workcell_config, write_config

from labauto.cli.main import main
from labauto.errors import RunError
from labauto.orchestrator.session import open_run
from labauto.store import Store

pytestmark = pytest.mark.timeout(120)


def test_a_run_whose_every_pick_fails_is_not_a_success(tmp_path, capsys):
    config = workcell_config(
        tmp_path,
        plates=1,
        picking={"max_picks": 2},
        analyzer={"simulator": {"faults": {"error_state": 7}}},
    )
    config_file = write_config(config, tmp_path / "run.yaml")
    assert main(["run", "--config", str(config_file), "--json"]) == 3
    outcome = json.loads(capsys.readouterr().out)
    assert outcome["state"] == "completed_with_errors"
    assert outcome["picks"] == {"failed": 2}
    assert outcome["error"] == "2 of 2 picks failed"


def test_a_pick_height_outside_the_travel_is_refused_before_anything_moves(tmp_path, capsys):
    config = workcell_config(tmp_path, plates=1)
    data = config.model_dump(mode="json")
    data["robot"]["pick_z_mm"] = -80.0  # limits_z_mm is [-50, 0]
    config_file = tmp_path / "run.yaml"
    config_file.write_text(json.dumps(data))
    assert main(["run", "--config", str(config_file)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == (
        f"labauto: error: {config_file}: robot: pick_z_mm: -80 mm is outside the travel "
        "limits [-50, 0] mm"
    )
    assert not db_path(config).exists()  # refused before a database, a device or a move


def _outage(session, seconds: float) -> None:
    """Make the simulated analyzer drop every connection for ``seconds``."""
    server = session.runner.workcell.analyzer.simulator
    server.inject_fault("drop_connection")
    threading.Timer(seconds, server.clear_fault).start()


def test_a_three_second_analyzer_outage_is_ridden_out_by_the_retry_policy(tmp_path, plugins):
    config = workcell_config(
        tmp_path,
        plates=2,
        analyzer={"timeout_s": 0.3},
        run={"retry": {"attempts": 8, "initial_delay_s": 0.25, "factor": 2, "max_delay_s": 1.5}},
    )
    store = Store.open(config.database.url)
    holder = {}
    trigger = Trigger("pick.done", lambda: _outage(holder["session"], 3.0))
    with open_run(config, store, plugins=plugins, reporter=trigger) as session:
        holder["session"] = session
        outcome = session.execute()
    assert trigger.fired
    assert outcome.state == "completed_with_errors", outcome.error  # not failed
    assert outcome.picks == {"analyzed": 1, "failed": 1}
    retries = store.events(outcome.run_id, "analyzer.retry")
    assert len(retries) >= 2 and "next try in" in retries[0].message
    assert store.events(outcome.run_id, "analyzer.recovered")


def test_a_failed_run_is_resumed_only_when_asked_and_repicks_nothing(tmp_path, plugins):
    config = workcell_config(
        tmp_path,
        plates=2,
        picking={"max_picks": 2},
        analyzer={"timeout_s": 0.3},
        run={"retry": {"attempts": 2, "initial_delay_s": 0.05}},
    )
    store = Store.open(config.database.url)
    holder = {}
    trigger = Trigger("pick.done", lambda: _outage(holder["session"], 2.0))
    with open_run(config, store, plugins=plugins, reporter=trigger) as session:
        holder["session"] = session
        failed = session.execute()
    assert failed.state == "failed" and failed.error
    handled = {p.colony_id: p.state for p in store.picks_for_run(failed.run_id)}
    assert sum(state != "planned" for state in handled.values()) == 2  # one analysed, one failed
    with pytest.raises(RunError) as info, open_run(config, store, plugins=plugins):
        pass
    assert f"run {failed.run_id} of config 'reliability' failed" in str(info.value)
    assert f"--resume {failed.run_id}" in str(info.value)
    assert len(store.list_runs()) == 1  # nothing was started over
    with open_run(config, store, plugins=plugins, resume_id=failed.run_id) as session:
        resumed = session.execute()
    assert resumed.run_id == failed.run_id
    assert resumed.state == "completed_with_errors"
    assert resumed.picks == {"analyzed": 3, "failed": 1}
    db = db_path(config)
    started = query(
        db,
        "select json_extract(data, '$.pick_id'), count(*) from events where kind = 'pick.state' "
        "and json_extract(data, '$.to') = 'moving' group by 1",
    )
    assert len(started) == 4 and all(n == 1 for _, n in started)  # no colony picked twice
