"""``labauto run``, ``labauto runs list|show|stop`` on a real (simulated-device) run."""

from __future__ import annotations

import json

import pytest
import yaml
from run_helpers import workcell_config

from labauto.cli.main import main

pytestmark = pytest.mark.timeout(90)


@pytest.fixture()
def config_file(tmp_path):
    config = workcell_config(tmp_path, plates=1, picking={"max_picks": 2})
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump(config.model_dump(mode="json")))
    return path


def test_run_then_list_and_show(config_file, capsys):
    assert main(["run", "--config", str(config_file), "--json"]) == 0
    outcome = json.loads(capsys.readouterr().out)
    assert outcome["state"] == "succeeded" and outcome["picks"] == {"analyzed": 2}

    assert main(["runs", "list", "--config", str(config_file), "--json"]) == 0
    runs = json.loads(capsys.readouterr().out)
    assert [(r["run"]["id"], r["run"]["state"]) for r in runs] == [(outcome["run_id"], "succeeded")]

    assert (
        main(["runs", "show", str(outcome["run_id"]), "--config", str(config_file), "--json"]) == 0
    )
    report = json.loads(capsys.readouterr().out)
    assert report["colonies"] == {"authentic": 20, "merged": 6, "mixed": 4}
    assert [p["state"] for p in report["picks"]] == ["analyzed", "analyzed"]
    assert all(p["result"] and "od600" in p["result"] for p in report["picks"])
    assert report["attention"] == []

    assert main(["runs", "show", str(outcome["run_id"]), "--config", str(config_file)]) == 0
    text = capsys.readouterr().out
    assert "succeeded" in text and "colonies: authentic 20, merged 6, mixed 4" in text


def test_a_second_run_is_new_and_control_of_a_finished_run_is_refused(config_file, capsys):
    assert main(["run", "--config", str(config_file), "--json"]) == 0
    assert main(["run", "--config", str(config_file), "--json"]) == 0
    capsys.readouterr()
    assert main(["runs", "list", "--config", str(config_file), "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 2
    assert main(["runs", "stop", "1", "--config", str(config_file)]) == 1
    assert "run 1 is succeeded: nothing to stop" in capsys.readouterr().err


def test_show_of_an_unknown_run_is_a_clear_error(config_file, capsys):
    assert main(["db", "upgrade", "--config", str(config_file)]) == 0
    capsys.readouterr()
    assert main(["runs", "show", "99", "--config", str(config_file)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("labauto: error:") and "99" in err
