"""The colony-picking run (paper, section 4.1): plates in, picked and analysed colonies out.

A run takes plates from the camera, analyses each (the ``plate`` application), stores its
detections and colonies, plans the picks, and for each pick moves the robot to the colony, takes a
probe, delivers it to the analyzer, runs the analysis and stores the result. Every step is an
event in the audit log; every device exchange is an event too (``robot.tx`` / ``robot.rx`` ...).

Picks move through ``planned -> moving -> picked -> delivered -> analyzed`` (or ``failed``), and
each state is committed before the device is asked to do the next thing. That makes a crash
recoverable: when a run is resumed, a pick found in ``moving``, ``picked`` or ``delivered`` has an
unknown outcome (the probe may or may not be on the tool or in the analyzer), so it is set to
``unknown`` and flagged for the operator instead of being repeated; ``planned`` picks go on.

A plate's image, detections, colonies, planned picks and their events are committed in one
transaction (:meth:`Store.store_plate`), so a crash leaves a plate either whole or absent. Plates
are identified by their place in the run (the camera's order), never by their pixels: a resumed
run finds plate 2 as plate 2 even if it looks exactly like plate 1 (a repeated frame, which is
reported as a warning). So nothing is picked twice and nothing stored is lost.

With ``head_check`` on, the camera confirms the head's position over each pick before the tool
descends and after the probe (:mod:`labauto.orchestrator.head_check`); a miss fails the pick
(``head.miss``), nothing moves again, and the run fails.

The outcome is honest: ``succeeded`` only when every planned pick was analysed,
``completed_with_errors`` when the run got through its plates but some picks failed or have an
unknown outcome, ``failed`` when it could not go on (resumable with ``--resume ID``). A device
that fails is brought back with the retry policy of ``run.retry`` before the run gives up.
"""

from __future__ import annotations

import contextlib
import hashlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from labauto.config import Config, plate_params
from labauto.devices import Analyzer, Camera, Robot
from labauto.drivers.errors import DeviceError, DeviceRefused
from labauto.errors import RunError
from labauto.orchestrator.calibration import REDO_DECK, Calibration, stored_deck_calibration
from labauto.orchestrator.control import EmergencyStop, RunControl, StopRequested
from labauto.orchestrator.head_check import HeadCheck, HeadMiss, head_check_for
from labauto.orchestrator.planning import PickRules, plan_picks
from labauto.orchestrator.recovery import with_retries
from labauto.plugin_manager import Plugins
from labauto.store import Store
from labauto.store.convert import colony_rows, plate_detection_rows
from labauto.store.states import PickState, RunState


class Reporter(Protocol):
    """Receives every run event as it happens (the CLI shows progress with it)."""

    def on_event(self, kind: str, message: str, data: dict[str, Any]) -> None: ...


@dataclass
class Workcell:
    """The connected devices of a run. ``close()`` disconnects them and stops simulators."""

    robot: Robot
    analyzer: Analyzer
    camera: Camera
    closers: list[Callable[[], None]] = field(default_factory=list)

    def close(self) -> None:
        for close in reversed(self.closers):
            with contextlib.suppress(Exception):  # closing must not mask the run's outcome
                close()


@dataclass(frozen=True)
class RunOutcome:
    """How a run ended."""

    run_id: int
    state: str
    error: str | None
    picks: dict[str, int]
    output_dir: Path


def calibration_from_config(config: Config) -> Calibration:
    """The pixel-to-deck calibration of a config (refused if its residual is too large)."""
    points = config.calibration.points
    return Calibration.from_points(
        np.array([p.pixel for p in points]),
        np.array([p.deck for p in points]),
        config.calibration.max_residual_mm,
    )


def image_digest(image: np.ndarray) -> str:
    """SHA-256 of an image's shape and pixels: the identity of a plate image within a run."""
    digest = hashlib.sha256(str(image.shape).encode())
    digest.update(np.ascontiguousarray(image).tobytes())
    return digest.hexdigest()


class ExchangeLog:
    """Device exchanges, buffered and written to the audit log in one insert per step.

    Every line a driver sends or receives (``on_exchange(direction, text)``) becomes an event
    ``<device>.<direction>`` with the time it happened. Writing each at once would cost a
    database commit per status poll, so they are kept in memory and flushed before the next
    step is recorded: the log stays in order, and a crash loses at most the exchanges of the
    step in progress (whose outcome is then flagged as unknown anyway).
    """

    def __init__(self, store: Store, run_id: int) -> None:
        self.store = store
        self.run_id = run_id
        self._rows: list[dict[str, Any]] = []
        self._lock = threading.Lock()

    def logger(self, device: str) -> Callable[[str, str], None]:
        """The ``on_exchange`` callback for ``device``."""

        def log(direction: str, text: str) -> None:
            row = {
                "kind": f"{device}.{direction}",
                "message": text,
                "source": device,
                "ts": datetime.now(UTC),
            }
            with self._lock:
                self._rows.append(row)

        return log

    def flush(self) -> None:
        """Write the buffered exchanges."""
        with self._lock:
            rows, self._rows = self._rows, []
        self.store.record_events(self.run_id, rows)


class ColonyPickingRun:
    """One run of the workcell; ``execute()`` drives it to a final state.

    Parameters
    ----------
    run_id : int
        The stored run (new, or an unfinished one being resumed).
    config : Config
        The validated workcell config.
    store : Store
        Where everything is recorded.
    plugins : Plugins
        Source of the plate application and the event hooks.
    workcell : Workcell
        The devices.
    control : RunControl
        Pause / resume / stop / e-stop requests.
    reporter : Reporter, optional
        Told about every event (progress display).
    """

    def __init__(
        self,
        run_id: int,
        config: Config,
        store: Store,
        plugins: Plugins,
        workcell: Workcell,
        control: RunControl,
        reporter: Reporter | None = None,
    ) -> None:
        self.run_id = run_id
        self.config = config
        self.store = store
        self.plugins = plugins
        self.workcell = workcell
        self.control = control
        self.reporter = reporter
        self.output_dir = Path(config.output.dir) / f"run-{run_id:04d}"
        self.exchanges = ExchangeLog(store, run_id)
        self.head_check: HeadCheck | None = None
        self.plate_params = plate_params(config)
        self.rules = PickRules(
            max_picks=config.picking.max_picks,
            min_neighbor_distance_px=config.picking.min_neighbor_distance_px,
            min_rim_distance_px=config.picking.min_rim_distance_px,
            order=config.picking.order,
            classes=tuple(config.picking.classes),
        )

    # -- the audit log -----------------------------------------------------------------------
    def event(
        self,
        kind: str,
        message: str,
        *,
        source: str = "orchestrator",
        data: dict[str, Any] | None = None,
    ) -> None:
        """Record one event in the audit log (after the exchanges leading to it)."""
        self.exchanges.flush()
        self.store.record_event(self.run_id, kind, message, source=source, data=data)
        self._notify(kind, message, data)

    def _notify(self, kind: str, message: str, data: dict[str, Any] | None = None) -> None:
        """Tell the reporter only: for changes the store already audits (run and pick states)."""
        if self.reporter is not None:
            self.reporter.on_event(kind, message, data or {})

    def _hook(self, name: str, **kwargs: Any) -> None:
        """Call an event hook; a failing exporter is logged, never fatal to the run."""
        try:
            getattr(self.plugins.hook, name)(**kwargs)
        except Exception as exc:
            self.event("plugin.error", f"{name} failed: {type(exc).__name__}: {exc}")

    # -- the run -----------------------------------------------------------------------------
    def execute(self) -> RunOutcome:
        """Run (or resume) to a final state: succeeded, completed_with_errors, stopped, failed."""
        self._flag_unknown_picks()
        if self.store.get_run(self.run_id).state == RunState.STOPPING:
            return self._finish(RunState.STOPPED, "stopped before a restart; stop completed")
        self._set_run_state(RunState.RUNNING)
        final, error = RunState.SUCCEEDED, None
        try:
            self._preflight()
            calibration = stored_deck_calibration(self.config, self.store)
            kind = "stored deck calibration (camera model)"
            if calibration is None:
                calibration, kind = calibration_from_config(self.config), "homography"
            self.event(
                "calibration",
                f"pixel-to-deck residual {calibration.residual_mm:.3f} mm "
                f"over {calibration.n_points} points ({kind})",
                data=calibration.to_dict(),
            )
            self.head_check = head_check_for(self.config, self.workcell, calibration)
            self._prepare_devices()
            for position, (plate_name, image) in enumerate(self.workcell.camera):
                self._checkpoint()
                self._process_plate(position, plate_name, image, calibration)
            final, error = self._outcome()
        except StopRequested:
            final, error = RunState.STOPPED, None
            self._cleanup()
        except EmergencyStop:
            final, error = RunState.STOPPED, "emergency stop"
            if self.control.estop_error is not None:  # the soft reset itself failed
                failure = self.control.estop_error
                error = f"emergency stop; robot soft reset failed: {failure}"
                self.event(
                    "run.estop",
                    f"robot soft reset failed: {failure}: check the robot",
                    source="robot",
                )
            self._flag_unknown_picks()
        except Exception as exc:
            final, error = RunState.FAILED, f"{type(exc).__name__}: {exc}"
            self._flag_unknown_picks()
        return self._finish(final, error)

    def _outcome(self) -> tuple[RunState, str | None]:
        """``succeeded`` if every pick was analysed, else ``completed_with_errors`` and why."""
        counts = self.store.run_summary(self.run_id).picks_by_state
        failed = counts.get(PickState.FAILED, 0)
        unknown = counts.get(PickState.UNKNOWN, 0)
        if not failed and not unknown:
            return RunState.SUCCEEDED, None
        total = sum(counts.values())
        parts = [f"{failed} of {total} picks failed"] if failed else []
        if unknown:
            parts.append(f"{unknown} of {total} have an unknown outcome (flagged for the operator)")
        return RunState.COMPLETED_WITH_ERRORS, "; ".join(parts)

    def _preflight(self) -> None:
        """Checks before anything moves: positions inside the travel, output folder writable."""
        problems = self.config.robot.position_problems()
        if problems:
            raise RunError("robot: " + "; ".join(problems))
        if self.config.output.annotate:
            try:
                self.output_dir.mkdir(parents=True, exist_ok=True)
                probe = self.output_dir / ".labauto-write-test"
                probe.write_bytes(b"")
                probe.unlink()
            except OSError as exc:
                raise RunError(
                    f"{self.output_dir}: output folder cannot be written ({exc.strerror})"
                ) from None

    def _set_run_state(self, state: RunState, error: str | None = None) -> None:
        self.store.set_run_state(self.run_id, state, error=error)
        self._notify("run.state", state.value + (f": {error}" if error else ""))

    def _finish(self, final: RunState, error: str | None) -> RunOutcome:
        self.exchanges.flush()
        if final is RunState.STOPPED and self.store.get_run(self.run_id).state != "stopping":
            self._set_run_state(RunState.STOPPING)
        self._set_run_state(final, error)
        picks = {str(k): v for k, v in self.store.run_summary(self.run_id).picks_by_state.items()}
        self._hook(
            "labauto_run_finished",
            run_id=self.run_id,
            state=final.value,
            summary={"picks": picks, "error": error},
        )
        return RunOutcome(self.run_id, final.value, error, picks, self.output_dir)

    def _checkpoint(self) -> None:
        def on_pause(waiting: bool) -> None:
            self._set_run_state(RunState.PAUSED if waiting else RunState.RUNNING)

        self.control.checkpoint(on_pause)

    def _prepare_devices(self) -> None:
        robot, analyzer = self.workcell.robot, self.workcell.analyzer
        for name, device in (("robot", robot), ("analyzer", analyzer)):
            self._retrying(name, "connect", device.connect)
            info = device.identify()
            self.event(
                f"{name}.ready", f"{name} connected: {_summary(info)}", source=name, data=info
            )
        if self.config.robot.home_on_start:
            robot.home()
            self.event("robot.homed", "robot homed", source="robot")

    def _cleanup(self) -> None:
        """After a stop: tool off and head up where it is, so the deck is safe to reach into."""
        robot = self.workcell.robot
        try:
            robot.tool_off()
            x, y, _z = robot.status().position
            robot.move_to(x, y)
            self.event("run.cleanup", f"tool off, head raised at ({x:.1f}, {y:.1f}) mm")
        except Exception as exc:
            self.event("run.cleanup", f"cleanup incomplete: {exc}")

    def _flag_unknown_picks(self) -> None:
        """Settle picks interrupted in flight: flagged for the operator, never repeated."""
        for pick in self.store.flag_picks_in_flight(
            self.run_id, reason="outcome unknown: the run was interrupted during this pick"
        ):
            flagged = ", flagged for the operator" if pick.needs_attention else ""
            self._notify(
                f"pick.{pick.state}",
                f"pick {pick.id} (colony {pick.colony_id}) was interrupted: now {pick.state}"
                + flagged,
            )

    # -- one plate ---------------------------------------------------------------------------
    def _process_plate(
        self, position: int, plate_name: str, image: np.ndarray, calibration: Calibration
    ) -> None:
        _check_image_size(plate_name, image, calibration)  # before the analysis, not after
        application = self.plugins.registry.get("applications", "plate")
        result = application(image, self.plate_params)
        stored = self.store.image_at(self.run_id, position)
        if stored is not None:
            if stored.path != plate_name:
                raise RunError(
                    f"plate {position} of run {self.run_id} was {stored.path!r} but the camera "
                    f"now gives {plate_name!r}: the plates changed since the run started"
                )
            self.event(
                "plate.resumed",
                f"{plate_name}: plate {position} already stored, not re-stored",
                data={"plate": plate_name, "position": position},
            )
            id_of = {c.colony_index: c.id for c in self.store.colonies(self.run_id, stored.id)}
        else:
            id_of = self._store_plate(position, plate_name, image, result, calibration)
        self._write_outputs(plate_name, image, result, id_of)
        on_this_plate = set(id_of.values())
        for pick in self.store.picks_for_run(self.run_id):
            if pick.colony_id in on_this_plate and pick.state == PickState.PLANNED:
                self._checkpoint()
                self._do_pick(pick)
        self._write_outputs(plate_name, image, result, id_of)

    def _store_plate(
        self,
        position: int,
        plate_name: str,
        image: np.ndarray,
        result: Any,
        calibration: Calibration,
    ) -> dict[int, int]:
        """Store a plate (image, detections, colonies, planned picks) in one transaction.

        Returns the stored colony id of each colony of the plate result.
        """
        digest = image_digest(image)
        for twin in self.store.images_with_digest(self.run_id, digest):
            self.event(
                "plate.repeated_frame",
                f"warning: {plate_name} (plate {position}) has exactly the pixels of "
                f"{twin.path} (plate {twin.position}): a duplicate file or a stale camera "
                "frame? It is treated as a plate of its own",
                data={"plate": plate_name, "position": position, "same_as": twin.position},
            )
        counts = result.counts
        method = f"plate:{self.plate_params.method}"
        local_ids = [c.id for c in result.colonies]
        index_of = {local: i for i, local in enumerate(local_ids)}
        document = result.to_dict()
        colonies = colony_rows(document)
        for i, row in enumerate(colonies):
            row["detection"] = i
        planned = plan_picks(result.colonies, calibration, self.rules, result.dish)
        picks = [
            {
                "colony": index_of[p.colony_id],
                "deck_x_mm": p.deck_mm[0],
                "deck_y_mm": p.deck_mm[1],
            }
            for p in planned
        ]
        events = [
            {
                "kind": "plate.analyzed",
                "message": f"{plate_name}: {counts['authentic']} authentic, "
                f"{counts['merged']} merged, {counts['mixed']} mixed ({result.timing_ms:.1f} ms)",
                "data": {"plate": plate_name, "position": position, **counts},
            },
            {
                "kind": "picks.planned",
                "message": f"{plate_name}: {len(planned)} picks planned",
                "data": {"plate": plate_name, "position": position, "picks": len(planned)},
            },
        ]
        self.exchanges.flush()
        stored = self.store.store_plate(
            self.run_id,
            position=position,
            name=plate_name,
            source=self.config.camera.path,
            path=plate_name,
            width=result.width,
            height=result.height,
            sha256=digest,
            detections=plate_detection_rows(document, method),
            colonies=colonies,
            picks=picks,
            events=events,
        )
        for event in events:
            self._notify(event["kind"], event["message"], event["data"])
        self._hook(
            "labauto_detections_stored",
            run_id=self.run_id,
            image_id=stored.image_id,
            plate=plate_name,
            count=len(stored.detection_ids),
        )
        return dict(zip(local_ids, stored.colony_ids, strict=True))

    # -- one pick ----------------------------------------------------------------------------
    def _do_pick(self, pick: Any) -> None:
        """Pick one colony, deliver it, analyse it; each state is stored before the next step."""
        robot, analyzer, cfg = self.workcell.robot, self.workcell.analyzer, self.config.robot
        sample_id = f"R{self.run_id:04d}P{pick.id:05d}"
        started = time.perf_counter()
        missed: HeadMiss | None = None
        try:
            self._pick_state(pick, PickState.MOVING, sample_id=sample_id)
            self._confirm_head(pick, travel=True)  # over the colony, before descending
            robot.pick(pick.deck_x_mm, pick.deck_y_mm, cfg.pick_z_mm, cfg.dwell_s)
            self._confirm_head(pick, travel=False)  # back at safe height after the probe
            self._pick_state(pick, PickState.PICKED)
            robot.deposit(cfg.deposit.x, cfg.deposit.y, cfg.deposit.z, cfg.dwell_s)
            self._pick_state(pick, PickState.DELIVERED)
            values = analyzer.analyze(sample_id, self.config.analyzer.analysis_timeout_s)
            self.exchanges.flush()
            self.store.add_analyzer_result(pick.id, sample_id, values)
            self._pick_state(pick, PickState.ANALYZED)
        except HeadMiss as exc:
            missed = exc
            self.exchanges.flush()
            self.store.set_pick_state(pick.id, PickState.FAILED, error=str(exc))
            self.event(
                "head.miss",
                str(exc),
                source="camera",
                data={"pick_id": pick.id, **exc.result.to_dict()},
            )
        except DeviceError as exc:
            if self.control.estopped:
                raise EmergencyStop("emergency stop") from exc
            self._pick_failed(pick, exc)
        elapsed_ms = (time.perf_counter() - started) * 1000
        self.event(
            "pick.done",
            f"pick {pick.id} finished in {elapsed_ms:.0f} ms",
            data={"pick_id": pick.id, "ms": round(elapsed_ms, 1)},
        )
        final = self.store.get_pick(pick.id)
        self._hook("labauto_pick_finished", run_id=self.run_id, pick=final.to_dict())
        if missed is not None:
            raise missed  # the run stops: no further motion on a machine that lost its place

    def _confirm_head(self, pick: Any, *, travel: bool) -> None:
        """With a head check: the camera confirms the head is over the pick (else HeadMiss)."""
        if self.head_check is None:
            return
        if travel:
            self.workcell.robot.move_to(pick.deck_x_mm, pick.deck_y_mm)
        result = self.head_check.check(pick.deck_x_mm, pick.deck_y_mm)
        if not result.ok:
            raise HeadMiss(pick.id, result)
        self.event(
            "head.checked",
            result.message(),
            source="camera",
            data={"pick_id": pick.id, **result.to_dict()},
        )

    def _pick_state(self, pick: Any, state: PickState, **fields: Any) -> None:
        self.exchanges.flush()
        self.store.set_pick_state(pick.id, state, **fields)
        self._notify("pick.state", f"pick {pick.id}: {state.value}")

    def _pick_failed(self, pick: Any, exc: DeviceError) -> None:
        """Mark the pick failed and bring the failed device back (if that fails, so does the run).

        The robot is reconnected and homed (its position may be lost); the analyzer is
        reconnected and reset; each with the retry policy of ``run.retry``. The pick itself is
        not retried: its probe may be spoiled. A refused move (a target outside the travel)
        needs no recovery: nothing was sent.
        """
        self.exchanges.flush()
        self.store.set_pick_state(pick.id, PickState.FAILED, error=str(exc))
        self.event(
            "pick.failed",
            f"pick {pick.id} failed: {exc}",
            data={"pick_id": pick.id, "error": str(exc)},
        )
        if isinstance(exc, DeviceRefused):
            return
        if exc.device == self.workcell.analyzer.name:
            analyzer = self.workcell.analyzer

            def recover() -> None:
                analyzer.reconnect()
                analyzer.reset()

        else:
            robot = self.workcell.robot

            def recover() -> None:
                robot.reconnect()
                robot.home()

        self._retrying(exc.device, "recover", recover)
        self.event(
            f"{exc.device}.recovered",
            f"{exc.device} reconnected and reset after: {exc}",
            source=exc.device,
        )

    def _retrying(self, device: str, what: str, action: Callable[[], Any]) -> Any:
        """Run a device step with the retry policy; each failed try is an audit event."""

        def failed(attempt: int, attempts: int, delay_s: float, error: BaseException) -> None:
            then = f"; next try in {delay_s:.1f} s" if attempt < attempts else "; giving up"
            self.event(
                f"{device}.retry",
                f"{device} {what} try {attempt} of {attempts} failed: {error}{then}",
                source=device,
                data={"attempt": attempt, "attempts": attempts, "error": str(error)},
            )

        try:
            return with_retries(
                action,
                self.config.run.retry,
                on_failure=failed,
                retry_on=(DeviceError, OSError),
                cancelled=lambda: self.control.stop_requested or self.control.estopped,
            )
        except (DeviceError, OSError):
            self.control.raise_if_stopped()  # the operator's stop ended the retries
            raise

    # -- operator output ---------------------------------------------------------------------
    def _write_outputs(
        self, plate_name: str, image: np.ndarray, result: Any, id_of: dict[int, int]
    ) -> None:
        from labauto.report import write_plate_outputs

        if not self.config.output.annotate:
            return
        touched = {
            pick.colony_id
            for pick in self.store.picks_for_run(self.run_id)
            if pick.state != PickState.PLANNED
        }
        picked = {local for local, stored in id_of.items() if stored in touched}
        write_plate_outputs(self.output_dir, plate_name, image, result, picked)


def _check_image_size(plate_name: str, image: np.ndarray, calibration: Any) -> None:
    """Refuse a plate image whose size is not the one a camera-model calibration is for (its
    pixels would map to the wrong deck positions); a homography has no image size."""
    size = getattr(calibration, "image_size", None)
    height, width = image.shape[:2]
    if size is not None and (width, height) != tuple(size):
        raise RunError(
            f"{plate_name}: {width}x{height} pixels, but the stored deck calibration is for "
            f"{size[0]}x{size[1]} images: " + REDO_DECK + " (with the camera in this mode)"
        )


def _summary(info: dict[str, Any]) -> str:
    """A one-line description of a device from its ``identify()`` dict."""
    keys = ("kind", "model", "firmware", "firmware_version", "url", "endpoint", "state")
    return ", ".join(f"{key} {info[key]}" for key in keys if info.get(key) not in (None, ""))
