"""Setting a run up and tearing it down: store, plugins, devices, control channel.

``open_run`` decides whether to start a new run or resume an unfinished one (the latest
unfinished run of the same config name, unless ``force_new``), builds the workcell from the
driver registry (starting simulated devices when the config says ``simulate: true``), and
listens for operator commands recorded in the audit log by ``labauto runs pause ID`` and the
like. Everything it starts is stopped when the ``with`` block ends.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from labauto.config import Config
from labauto.errors import RunError
from labauto.orchestrator.control import COMMANDS, RunControl
from labauto.orchestrator.run import ColonyPickingRun, Reporter, RunOutcome, Workcell
from labauto.plugin_manager import Plugins, load_plugins
from labauto.store import Store
from labauto.store.states import RunState

CONTROL_KIND = "control."
UNFINISHED = (RunState.IDLE, RunState.RUNNING, RunState.PAUSED, RunState.STOPPING)


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


def _choose_run(store: Store, config: Config, resume_id: int | None, force_new: bool):
    if resume_id is not None:
        run = store.get_run(resume_id)
        if run.state not in UNFINISHED:
            raise RunError(f"run {resume_id} is {run.state}: only an unfinished run can resume")
        return run.id, True
    if not force_new:
        unfinished = store.latest_unfinished_run(name=config.name)
        if unfinished is not None:
            return unfinished.id, True
    return store.create_run(config.name, config.model_dump(mode="json")), False


@contextlib.contextmanager
def open_run(
    config: Config,
    store: Store,
    *,
    resume_id: int | None = None,
    force_new: bool = False,
    reporter: Reporter | None = None,
    plugins: Plugins | None = None,
) -> Iterator[RunSession]:
    """Open a new or resumed run with its devices and control channel.

    Raises
    ------
    RunError
        If ``resume_id`` names a finished run.
    """
    plugins = plugins or load_plugins(config.plugins.enabled, config.plugins.disabled)
    workcell = build_workcell(config, plugins)
    try:
        run_id, resumed = _choose_run(store, config, resume_id, force_new)
    except BaseException:
        workcell.close()
        raise
    for failure in plugins.failed:
        store.record_event(run_id, "plugin.failed", f"{failure.name}: {failure.error}")
    control = RunControl(on_estop=lambda: workcell.robot.soft_reset())
    runner = ColonyPickingRun(run_id, config, store, plugins, workcell, control, reporter)
    control.on_change = lambda command: runner.event(f"run.{command}", f"operator: {command}")
    workcell.robot.on_exchange = runner.exchanges.logger("robot")
    workcell.analyzer.on_exchange = runner.exchanges.logger("analyzer")
    if resumed:
        runner.event("run.resumed", f"resuming run {run_id}")
    poller = _ControlPoller(store, run_id, control)
    poller.start()
    try:
        yield RunSession(run_id, resumed, control, runner)
    finally:
        poller.stop()
        workcell.close()


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
    """Connect to the robot and analyzer and report who answered (``labauto devices check``)."""
    plugins = plugins or load_plugins(config.plugins.enabled, config.plugins.disabled)
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
