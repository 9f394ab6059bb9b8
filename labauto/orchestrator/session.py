"""Setting a run up and tearing it down: store, plugins, devices, control channel.

``open_run`` decides whether to start a new run or resume one, builds the workcell from the
driver registry (starting simulated devices when the config says ``simulate: true``), and
listens for operator commands recorded in the audit log by ``labauto runs pause ID`` and the
like. Everything it starts is stopped when the ``with`` block ends.

Which run (without ``--new`` or ``--resume ID``): the newest run of the config's name. If it is
unfinished and was started with the same effective config (same hash), it is resumed; with
another config, or if it failed, nothing starts and the message says what differs and how to go
on (``--resume ID`` or ``--new``): a new run never silently re-picks the colonies of an
unfinished or failed one. The chosen run's lease is taken in the same step (a run driven by a
live process is refused, naming its pid and host), and every real device is locked for the
process (:mod:`labauto.orchestrator.device_locks`).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from labauto.config import Config
from labauto.errors import PluginError, RunError
from labauto.orchestrator.control import COMMANDS, RunControl
from labauto.orchestrator.device_locks import device_locks
from labauto.orchestrator.identity import config_differences, config_hash, effective_config
from labauto.orchestrator.lease import LeaseKeeper
from labauto.orchestrator.run import ColonyPickingRun, Reporter, RunOutcome, Workcell
from labauto.plugin_manager import Plugins, load_plugins
from labauto.store import Store
from labauto.store.leases import LeaseOwner, StaleCheck
from labauto.store.states import RUN_RESUMABLE_STATES, RunState

CONTROL_KIND = "control."
UNFINISHED = (RunState.IDLE, RunState.RUNNING, RunState.PAUSED, RunState.STOPPING)


def check_enabled_plugins(config: Config, plugins: Plugins) -> None:
    """Refuse a ``plugins.enabled`` name that no installed plugin has."""
    enabled = config.plugins.enabled
    if enabled is None:
        return
    known = {info.name for info in plugins.loaded} | {f.name for f in plugins.failed}
    unknown = [name for name in enabled if name not in known]
    if unknown:
        names = ", ".join(repr(name) for name in unknown)
        loaded = ", ".join(sorted(info.name for info in plugins.loaded)) or "none"
        raise PluginError(
            f"plugins.enabled: no installed plugin named {names} (loaded: {loaded}; "
            "`labauto plugins` lists them)"
        )


@dataclass
class RunSession:
    """An opened run, ready to ``execute()``."""

    run_id: int
    resumed: bool
    control: RunControl
    runner: ColonyPickingRun

    def execute(self) -> RunOutcome:
        return self.runner.execute()


def build_workcell(config: Config, plugins: Plugins) -> Workcell:
    """Create the camera, robot and analyzer named in the config (not yet connected)."""
    registry = plugins.registry
    camera = registry.driver("camera", config.camera.driver)(config.camera)
    robot = registry.driver("robot", config.robot.driver)(config.robot)
    try:
        analyzer = registry.driver("analyzer", config.analyzer.driver)(config.analyzer)
    except BaseException:
        robot.close()  # e.g. stop the simulator it started
        raise
    return Workcell(robot, analyzer, camera, closers=[robot.close, analyzer.close])


def _choose_run(
    store: Store,
    config: Config,
    resume_id: int | None,
    force_new: bool,
    owner: LeaseOwner,
) -> tuple[int, bool]:
    """The run to execute, with its lease taken (see the module docstring)."""
    document = effective_config(config)
    digest = config_hash(document)
    stale = StaleCheck(config.run.lease_timeout_s)
    if resume_id is not None:
        run = store.get_run(resume_id)
        if run.state not in RUN_RESUMABLE_STATES:
            raise RunError(
                f"run {resume_id} is {run.state}: only an unfinished or failed run can resume"
            )
        store.take_lease(run.id, owner, stale)
        if run.config_hash is not None and run.config_hash != digest:
            changes = "; ".join(config_differences(run.config, document))
            store.set_run_config(run.id, document, digest)
            store.record_event(
                run.id,
                "run.config_changed",
                f"resumed with another config, as the operator asked: {changes}",
                source="operator",
            )
        return run.id, True
    if not force_new:
        latest = store.latest_run(config.name)
        if latest is not None and latest.state == RunState.FAILED:
            raise RunError(
                f"run {latest.id} of config {config.name!r} failed ({latest.error}); "
                f"resume it with --resume {latest.id}, or start a new run with --new "
                "(which may pick its colonies again)"
            )
        if latest is not None and latest.state in UNFINISHED:
            if latest.config_hash is not None and latest.config_hash != digest:
                changes = "; ".join(config_differences(latest.config, document))
                raise RunError(
                    f"run {latest.id} of config {config.name!r} is unfinished and was started "
                    f"with another config ({changes}); resume it anyway with --resume "
                    f"{latest.id}, or start a new run with --new"
                )
            store.take_lease(latest.id, owner, stale)
            return latest.id, True
    run_id = store.create_run(config.name, document, config_hash=digest, lease=owner)
    return run_id, False


@contextlib.contextmanager
def open_run(
    config: Config,
    store: Store,
    *,
    resume_id: int | None = None,
    force_new: bool = False,
    reporter: Reporter | None = None,
    plugins: Plugins | None = None,
    owner: LeaseOwner | None = None,
) -> Iterator[RunSession]:
    """Open a new or resumed run with its devices, lease and control channel.

    Parameters
    ----------
    owner : LeaseOwner, optional
        Who owns the run (default: this process).

    Raises
    ------
    RunError
        ``resume_id`` names a run that cannot resume; the newest run of the config failed or
        was started with another config; a device is in use by another run.
    LeaseHeld
        Another live process drives the run.
    """
    plugins = plugins or load_plugins(config.plugins.enabled, config.plugins.disabled)
    check_enabled_plugins(config, plugins)
    owner = owner or LeaseOwner.this_process()
    with contextlib.ExitStack() as stack:
        stack.enter_context(device_locks(config, f"a run of config {config.name!r}"))
        workcell = build_workcell(config, plugins)
        stack.callback(workcell.close)
        run_id, resumed = _choose_run(store, config, resume_id, force_new, owner)
        stack.callback(_release, store, run_id, owner)
        for failure in plugins.failed:
            store.record_event(run_id, "plugin.failed", f"{failure.name}: {failure.error}")
        control = RunControl(on_estop=lambda: workcell.robot.soft_reset())
        runner = ColonyPickingRun(run_id, config, store, plugins, workcell, control, reporter)
        control.on_change = lambda command: runner.event(f"run.{command}", f"operator: {command}")
        workcell.robot.on_exchange = runner.exchanges.logger("robot")
        workcell.analyzer.on_exchange = runner.exchanges.logger("analyzer")
        if resumed:
            runner.event("run.resumed", f"resuming run {run_id}")

        def lease_lost(message: str) -> None:
            store.record_event(run_id, "run.lease", f"{message}; stopping", source="orchestrator")
            control.stop()

        keeper = LeaseKeeper(store, run_id, owner, config.run.heartbeat_s, lease_lost)
        control.guard = keeper.verify
        keeper.start()
        stack.callback(keeper.stop)
        poller = _ControlPoller(store, run_id, control)
        poller.start()
        stack.callback(poller.stop)
        yield RunSession(run_id, resumed, control, runner)


def _release(store: Store, run_id: int, owner: LeaseOwner) -> None:
    with contextlib.suppress(Exception):  # the run's outcome matters more than the release
        store.release_lease(run_id, owner)


class _ControlPoller(threading.Thread):
    """Apply operator commands recorded in the audit log (``control.<command>`` events)."""

    def __init__(self, store: Store, run_id: int, control: RunControl, period_s: float = 0.1):
        super().__init__(name=f"labauto-control-{run_id}", daemon=True)
        self.store, self.run_id, self.control, self.period_s = store, run_id, control, period_s
        self._done = threading.Event()
        self._seen = store.last_event_id(run_id, kind_prefix=CONTROL_KIND)

    def run(self) -> None:
        while not self._done.wait(self.period_s):
            for event in self.store.events_after(self.run_id, self._seen, CONTROL_KIND):
                self._seen = event.id
                self.control.request(event.kind.removeprefix(CONTROL_KIND))

    def stop(self) -> None:
        self._done.set()
        self.join(timeout=2.0)


def request_control(store: Store, run_id: int, command: str) -> None:
    """Ask a running run to pause, resume, stop or e-stop (through its audit log)."""
    if command not in COMMANDS:
        raise RunError(f"unknown run command {command!r} (expected {', '.join(COMMANDS)})")
    run = store.get_run(run_id)
    if run.state not in UNFINISHED:
        raise RunError(f"run {run_id} is {run.state}: nothing to {command}")
    store.record_event(
        run_id, CONTROL_KIND + command, f"operator asked to {command}", source="operator"
    )


def describe_run(store: Store, run_id: int, n_events: int = 15) -> dict[str, Any]:
    """Everything ``labauto runs show`` prints, as one JSON-ready document."""
    run = store.get_run(run_id)
    picks = store.picks_for_run(run_id)
    results = {r.pick_id: r.values for r in store.analyzer_results(run_id)}
    pick_rows = [
        {**p.to_dict(), "result": results.get(p.id)} for p in sorted(picks, key=lambda p: p.id)
    ]
    summary = store.run_summary(run_id)
    return {
        "run": run.to_dict(),
        "plates": store.plate_names(run_id),
        "colonies": {str(k): v for k, v in store.colony_counts(run_id).items()},
        "picks_by_state": {str(k): v for k, v in summary.picks_by_state.items()},
        "attention": [p for p in pick_rows if p["needs_attention"]],
        "picks": pick_rows,
        "events": [e.to_dict() for e in store.latest_events(run_id, n_events)],
    }


def check_devices(config: Config, plugins: Plugins | None = None) -> dict[str, dict[str, Any]]:
    """Connect to the robot and analyzer and report who answered (``labauto devices check``).

    The real devices are locked first, so a check never talks to a device a run is driving.

    Raises
    ------
    RunError
        A device is in use by a run.
    """
    plugins = plugins or load_plugins(config.plugins.enabled, config.plugins.disabled)
    with device_locks(config, "labauto devices check"):
        return _check_devices(config, plugins)


def _check_devices(config: Config, plugins: Plugins) -> dict[str, dict[str, Any]]:
    report: dict[str, dict[str, Any]] = {}
    for kind, section in (("robot", config.robot), ("analyzer", config.analyzer)):
        device = None
        try:
            device = plugins.registry.driver(kind, section.driver)(section)
            device.connect()
            report[kind] = {"ok": True, "detail": device.identify(), "simulated": section.simulate}
        except Exception as exc:
            report[kind] = {
                "ok": False,
                "detail": f"{type(exc).__name__}: {exc}",
                "simulated": section.simulate,
            }
        finally:
            if device is not None:
                with contextlib.suppress(Exception):
                    device.close()
    return report
