"""Operator control of a running run: pause, resume, stop and e-stop.

In the style of Bluesky's RunEngine and Opentrons' engine, requests are taken at any time but
acted on at safe checkpoints (between picks, when the tool holds nothing):

* ``pause`` — the run waits at the next checkpoint until ``resume``;
* ``stop`` — the run ends at the next checkpoint with cleanup (tool off, head up);
* ``estop`` — immediate: ``on_estop`` runs at once (the robot's soft reset), and the run ends
  without cleanup; a pick in flight is flagged for the operator.

Requests come from the API (``RunControl.pause()`` and so on), from signals (the first Ctrl-C
asks to stop, a second one is an e-stop), or from another terminal through the audit log:
``labauto runs pause ID`` records a ``control.pause`` event that the running process reads.
"""

from __future__ import annotations

import threading
from collections.abc import Callable


class StopRequested(Exception):
    """Raised at a checkpoint when the operator asked to stop."""


class EmergencyStop(Exception):
    """Raised at a checkpoint (or by a device call cut short) after an e-stop."""


COMMANDS = ("pause", "resume", "stop", "estop")


class RunControl:
    """Thread-safe pause / resume / stop / e-stop requests for one run.

    Parameters
    ----------
    on_estop : callable, optional
        Called once, at once, in the thread that asks for the e-stop (e.g. the robot's soft
        reset). Exceptions from it are kept in ``estop_error`` and do not stop the e-stop.
    on_change : callable, optional
        Called with the command name after each accepted request (for the audit log).
    """

    def __init__(
        self,
        on_estop: Callable[[], None] | None = None,
        on_change: Callable[[str], None] | None = None,
    ) -> None:
        self._lock = threading.Lock()
        self._running = threading.Event()
        self._running.set()
        self._stop = False
        self._estop = False
        self.on_estop = on_estop
        self.on_change = on_change
        self.estop_error: BaseException | None = None
        # called at every safe point, in the run's thread, before the checks (the run's lease:
        # a run whose lease was taken over stops at the very next safe point)
        self.guard: Callable[[], None] | None = None

    @property
    def paused(self) -> bool:
        """True while a pause is requested and not yet resumed."""
        return not self._running.is_set()

    @property
    def stop_requested(self) -> bool:
        return self._stop

    @property
    def estopped(self) -> bool:
        return self._estop

    def request(self, command: str) -> None:
        """Apply one of ``COMMANDS`` by name."""
        if command not in COMMANDS:
            raise ValueError(f"unknown run command {command!r} (expected {', '.join(COMMANDS)})")
        getattr(self, command)()

    def pause(self) -> None:
        """Pause at the next checkpoint."""
        self._running.clear()
        self._changed("pause")

    def resume(self) -> None:
        """Continue after a pause."""
        self._running.set()
        self._changed("resume")

    def stop(self) -> None:
        """End the run at the next checkpoint, with cleanup."""
        with self._lock:
            self._stop = True
        self._running.set()  # a paused run must wake up to stop
        self._changed("stop")

    def estop(self) -> None:
        """Emergency stop: call ``on_estop`` now, end the run without cleanup."""
        with self._lock:
            first = not self._estop
            self._estop = True
        self._running.set()
        if first and self.on_estop is not None:
            try:
                self.on_estop()
            except BaseException as exc:  # the e-stop itself must never be lost
                self.estop_error = exc
        if first:
            self._changed("estop")

    def checkpoint(self, on_pause: Callable[[bool], None] | None = None) -> None:
        """A safe point: wait while paused, raise on stop or e-stop.

        Parameters
        ----------
        on_pause : callable, optional
            Called with True when the run starts waiting and False when it goes on.

        Raises
        ------
        EmergencyStop, StopRequested
        """
        self._guard()
        self.raise_if_stopped()
        if self.paused:
            if on_pause is not None:
                on_pause(True)
            self._running.wait()
            if on_pause is not None:
                on_pause(False)
            self._guard()  # a long pause: look again
        self.raise_if_stopped()

    def _guard(self) -> None:
        if self.guard is not None:
            self.guard()

    def raise_if_stopped(self) -> None:
        """Raise ``EmergencyStop`` or ``StopRequested`` if one was asked for."""
        if self._estop:
            raise EmergencyStop("emergency stop")
        if self._stop:
            raise StopRequested("stop requested")

    def _changed(self, command: str) -> None:
        if self.on_change is not None:
            self.on_change(command)
