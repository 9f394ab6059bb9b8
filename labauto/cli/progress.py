"""Progress of a run on the terminal: a bar over the planned picks and a line per key event."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

#: Events worth a line of their own; the rest (device exchanges, pick states) only move the bar.
SHOWN = {
    "run.state",
    "run.resumed",
    "run.pause",
    "run.resume",
    "run.stop",
    "run.estop",
    "calibration",
    "robot.ready",
    "analyzer.ready",
    "plate.analyzed",
    "plate.resumed",
    "picks.planned",
    "pick.failed",
    "pick.unknown",
    "plugin.error",
    "plugin.failed",
    "robot.recovered",
    "analyzer.recovered",
    "run.cleanup",
    "run.lease",
    "run.config_changed",
    "plate.repeated_frame",
    "robot.retry",
    "analyzer.retry",
}


class RunProgress:
    """A ``Reporter`` for ``ColonyPickingRun`` that draws on stderr (quiet: draws nothing)."""

    def __init__(self, quiet: bool = False) -> None:
        self.console = Console(stderr=True, quiet=quiet)
        self.progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=self.console,
            transient=False,
        )
        self.task = self.progress.add_task("picks", total=0)

    def start(self, run_id: int, resumed: bool, planned: int = 0, done: int = 0) -> None:
        """Start drawing; a resumed run starts from its ``planned`` picks, ``done`` of them."""
        self.progress.update(
            self.task, description=f"run {run_id} picks", total=planned, completed=done
        )
        self.console.print(f"{'resuming' if resumed else 'starting'} run {run_id}")
        self.progress.start()

    def stop(self) -> None:
        self.progress.stop()

    def on_event(self, kind: str, message: str, data: dict[str, Any]) -> None:
        if kind == "picks.planned":
            total = self.progress.tasks[0].total or 0
            self.progress.update(self.task, total=total + int(data.get("picks", 0)))
        elif kind == "pick.done":
            self.progress.advance(self.task)
        if kind in SHOWN:
            warn = ("failed", "unknown", "estop", "error", "retry", "repeated_frame", "lease")
            style = "red" if kind.endswith(warn) else "dim"
            self.progress.console.print(f"[{style}]{kind}[/{style}] {message}")
