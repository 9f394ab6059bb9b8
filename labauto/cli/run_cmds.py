"""``labauto run``, ``labauto runs ...`` and ``labauto devices check``: the workcell at work."""

from __future__ import annotations

import json
import signal
import threading
from typing import Any

import click

from labauto.cli.options import config_option
from labauto.config import Config

#: A run id as the database can hold it (a larger number is a usage error, not an overflow).
RUN_ID = click.IntRange(1, 2**63 - 1)


def _store(config: Config):
    from labauto.store import Store

    return Store.open(config.database.url, migrate=True)


def _existing_store(config: Config):
    """The store for commands that only read or control runs: a missing database is an error.

    (Opening a mistyped SQLite path would otherwise create an empty database there.)
    """
    from sqlalchemy.engine import make_url

    from labauto.errors import LabautoError
    from labauto.store.db import safe_url

    try:
        url = make_url(config.database.url)
    except Exception:
        return _store(config)  # the store names a malformed URL
    database = url.database
    if url.get_backend_name() == "sqlite" and database not in (None, "", ":memory:"):
        from pathlib import Path

        if not Path(database).exists():
            raise LabautoError(
                f"no database at {safe_url(config.database.url)!r} (file {database} does not "
                "exist): check database.url or LABAUTO_DATABASE_URL"
            )
    return _store(config)


@click.command("run")
@config_option
@click.option("--new", "force_new", is_flag=True, help="Start a new run even if one is unfinished.")
@click.option(
    "--resume", "resume_id", type=RUN_ID, default=None, help="Resume this unfinished or failed run."
)
@click.option("--json", "as_json", is_flag=True, help="Print the outcome as JSON at the end.")
def run_cmd(config: Config, force_new: bool, resume_id: int | None, as_json: bool) -> None:
    """Pick colonies: analyse plates, pick, deliver to the analyzer, store everything.

    An unfinished run of the same name and config (for example after a crash) is resumed
    unless --new is given; one started with another config, or a failed one, is resumed only
    with --resume ID. Exit status: 0 succeeded or stopped, 1 failed, 3 completed with errors
    (some picks failed or have an unknown outcome). Ctrl-C, SIGTERM and SIGHUP stop at the next
    safe point; a second Ctrl-C is an emergency stop. From another terminal: labauto runs
    pause|resume|stop|estop ID.
    """
    from labauto.cli.progress import RunProgress
    from labauto.orchestrator.session import open_run

    store = _store(config)
    progress = RunProgress(quiet=as_json)
    with open_run(
        config, store, resume_id=resume_id, force_new=force_new, reporter=progress
    ) as session:
        picks = store.run_summary(session.run_id).picks_by_state
        progress.start(
            session.run_id,
            session.resumed,
            planned=sum(picks.values()),
            done=sum(n for state, n in picks.items() if state != "planned"),
        )
        previous = _install_signal_handlers(session.control)
        try:
            outcome = session.execute()
        finally:
            progress.stop()
            for signum, handler in previous.items():
                signal.signal(signum, handler)
    if as_json:
        click.echo(
            json.dumps(
                {
                    "run_id": outcome.run_id,
                    "state": outcome.state,
                    "error": outcome.error,
                    "picks": outcome.picks,
                    "output_dir": str(outcome.output_dir),
                },
                indent=2,
            )
        )
    else:
        click.echo(
            f"run {outcome.run_id} {outcome.state}"
            + (f" ({outcome.error})" if outcome.error else "")
            + f"; picks: {_counts(outcome.picks)}; output in {outcome.output_dir}"
        )
    if outcome.state in EXIT_CODES:
        raise SystemExit(EXIT_CODES[outcome.state])


#: Exit status of ``labauto run`` by outcome (0 otherwise: succeeded, stopped).
EXIT_CODES = {"failed": 1, "completed_with_errors": 3}


def _counts_text(values: dict[str, Any]) -> str:
    return ", ".join(f"{key} {value}" for key, value in values.items())


def _counts(picks: dict[str, int]) -> str:
    return ", ".join(f"{n} {state}" for state, n in sorted(picks.items())) or "none"


def _install_signal_handlers(control: Any) -> dict[int, Any]:
    """Ctrl-C stops (twice: e-stop), SIGTERM and SIGHUP stop; returns the handlers replaced."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    stopping = [signal.SIGTERM] + ([signal.SIGHUP] if hasattr(signal, "SIGHUP") else [])
    previous = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, *stopping)}
    interrupts = {"count": 0}

    def on_interrupt(signum: int, frame: Any) -> None:
        interrupts["count"] += 1
        if interrupts["count"] == 1:
            click.echo("\nstopping at the next safe point (Ctrl-C again: emergency stop)", err=True)
            control.stop()
        else:
            click.echo("\nEMERGENCY STOP", err=True)
            control.estop()

    signal.signal(signal.SIGINT, on_interrupt)
    for signum in stopping:  # a closed terminal (SIGHUP) must not leave the run "running"
        signal.signal(signum, lambda signum, frame: control.stop())
    return previous


@click.group("runs")
def runs() -> None:
    """List, inspect and control stored runs."""


@runs.command("list")
@config_option
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def runs_list(config: Config, as_json: bool) -> None:
    """Summarise the stored runs, newest first."""
    summaries = _existing_store(config).list_runs()
    if as_json:
        click.echo(json.dumps([s.to_dict() for s in summaries], indent=2, default=str))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="labauto runs")
    for column in ("id", "name", "state", "started", "finished", "picks"):
        table.add_column(column)
    for s in summaries:
        run = s.run
        table.add_row(
            str(run.id),
            run.name,
            run.state,
            _when(run.started_at),
            _when(run.finished_at),
            _counts(dict(s.picks_by_state)),
        )
    Console().print(table)


@runs.command("show")
@click.argument("run_id", type=RUN_ID)
@config_option
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@click.option(
    "--events",
    "n_events",
    type=click.IntRange(0, 100_000),
    default=15,
    show_default=True,
    help="How many of the latest events to show.",
)
def runs_show(run_id: int, config: Config, as_json: bool, n_events: int) -> None:
    """Show one run: state, plates, picks (flagged ones first) and its latest events."""
    from labauto.orchestrator.session import describe_run

    report = describe_run(_existing_store(config), run_id, n_events)
    if as_json:
        click.echo(json.dumps(report, indent=2, default=str))
        return
    run = report["run"]
    click.echo(
        f"run {run['id']} '{run['name']}': {run['state']}"
        + (f" ({run['error']})" if run.get("error") else "")
    )
    click.echo(f"  started {run.get('started_at')}, finished {run.get('finished_at')}")
    if run.get("lease_pid") is not None:
        click.echo(
            f"  owned by pid {run['lease_pid']} on host {run['lease_host']}, "
            f"last heartbeat {run.get('lease_heartbeat_at')}"
        )
    click.echo(f"  plates: {', '.join(report['plates']) or 'none'}")
    click.echo(f"  colonies: {_counts_text(report['colonies']) or 'none'}")
    click.echo(f"  picks: {_counts(report['picks_by_state'])}")
    for pick in report["attention"]:
        click.echo(f"  ATTENTION pick {pick['id']} (colony {pick['colony_id']}): {pick['error']}")
    for pick in report["picks"]:
        values = {
            k: f"{v:.4g}" if isinstance(v, float) else v
            for k, v in (pick.get("result") or {}).items()
        }
        click.echo(
            f"  pick {pick['id']}: {pick['state']} at ({pick['deck_x_mm']:.1f}, "
            f"{pick['deck_y_mm']:.1f}) mm, sample {pick.get('sample_id')}"
            + (f", result {_counts_text(values)}" if values else "")
        )
    click.echo("  latest events:")
    for event in report["events"]:
        click.echo(f"    {event['ts']} {event['kind']}: {event['message']}")


def _control_command(command: str):
    @runs.command(command)
    @click.argument("run_id", type=RUN_ID)
    @config_option
    def send(run_id: int, config: Config) -> None:
        from labauto.orchestrator.session import request_control

        request_control(_existing_store(config), run_id, command)
        click.echo(f"asked run {run_id} to {command}")

    send.__doc__ = f"Ask a running run to {command} (recorded in its audit log)."
    return send


for _command in ("pause", "resume", "stop", "estop"):
    _control_command(_command)


def _when(value: Any) -> str:
    return "-" if value is None else value.strftime("%Y-%m-%d %H:%M:%S")


@click.group("devices")
def devices() -> None:
    """Check the configured devices."""


@devices.command("check")
@config_option
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def devices_check(config: Config, as_json: bool) -> None:
    """Connect to the robot and the analyzer (real or simulated) and report what answered."""
    from labauto.orchestrator.session import check_devices

    report = check_devices(config)
    if as_json:
        click.echo(json.dumps(report, indent=2))
    else:
        for name, entry in report.items():
            status = "ok" if entry["ok"] else "NO ANSWER"
            click.echo(f"{name}: {status}: {entry['detail']}")
    failed = [name for name, entry in report.items() if not entry["ok"]]
    if failed:
        from labauto.errors import LabautoError

        raise LabautoError(f"{' and '.join(failed)} did not answer")
