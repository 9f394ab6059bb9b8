"""Driver for a picking robot (gantry) running GRBL 1.1: the protocol over a line transport.

The bytes go through :class:`labauto.drivers.line_link.LineLink` (pyserial's
``serial_for_url``), so a USB serial port (``/dev/ttyUSB0``), a network bridge
(``socket://host:port``) and a pseudo-terminal all work the same way. This module is the
protocol: what to send, how to read the answers, and what the controller's state allows.
It is proven against the real GRBL 1.1h firmware (``tests/firmware``) and against the
simulated gantry of :mod:`labauto.drivers.grbl_sim`.

Protocol choices
----------------
* Plain send-and-wait: one line, then read until its ``ok`` / ``error:N``. Lines end in ``\\n``
  only (GRBL treats ``\\r`` as a line end too, so ``\\r\\n`` would earn two replies).
* Moves are absolute millimetres in *machine* coordinates (``G21 G90 G53 G1``), so the travel
  limits checked here are the ones GRBL's own soft limits use, whatever work offset is active.
  Every move uses ``G1`` with an explicit feed: ``travel_feed`` for X/Y, ``z_feed`` for Z.
* Connecting: ``$I`` (firmware version and ``[OPT:]`` build options) and ``$$`` (settings).
  A board that resets when its port opens (an Arduino's DTR line) prints its banner about a
  second later and drops what was sent before; the driver waits up to ``boot_timeout`` for it
  and sends ``$I`` again. With homing or soft limits enabled (``$22=1`` / ``$20=1``) the
  configured travel limits are checked against ``$130``-``$132``, ``$23`` and the sign
  convention of the build (negative machine space unless ``HOMING_FORCE_SET_ORIGIN``), and a
  mismatch fails the connection with :class:`TravelMismatch` naming each axis.
* **E-stop latch.** After :meth:`~GrblRobot.soft_reset` or a start-up banner nobody asked for
  (the controller restarted), the driver refuses every motion command - moves, dwells, the tool
  output, picks - with :class:`GrblNotArmed` until :meth:`~GrblRobot.home` or
  :meth:`~GrblRobot.unlock` re-arms it. A line awaiting its answer when the reset happens fails
  with :class:`GrblReset`, also when GRBL answers ``ok`` for it (it does: the aborted line's
  ``ok`` comes before the banner). A line can never be written after the reset byte: the check
  and the write are one step under the same lock as the reset.
* **Critical alarms.** After ALARM:1 (hard limit) or ALARM:2 (soft limit) GRBL waits about
  500 ms (its alarm report delay), prints ``[MSG:Reset to continue]`` and then listens to
  nothing but a soft reset - not even ``?``. A Ctrl-X sent before that message is lost, so the
  driver waits for the message before resetting (and resets again if the message comes after
  a reset it sent). :meth:`~GrblRobot.status` raises :class:`GrblAlarm` at once meanwhile.
* Push messages (``[MSG:...]``, ``[GC:...]``) are logged and otherwise ignored. Results of
  start-up blocks (``>G21:ok``, ``>G1X5:error:22``) are kept in
  :attr:`~GrblRobot.startup_errors` and logged. A stray ``ok`` or status report left over from
  an earlier failure is read away (and logged) before each command. An ``ALARM:N`` that arrived
  between commands is raised by the next motion command.
* Status: ``MPos`` or ``WPos`` (``$10``); GRBL sends ``WCO`` only every 10-30 reports, so the
  driver keeps the last one and fills it into reports without it (:attr:`GrblStatus.position`
  then works in both modes). A start-up banner forgets it.
* During homing GRBL answers no ``?``; :meth:`~GrblRobot.home` just waits for its ``ok``.

Threads: line commands and :meth:`~GrblRobot.status` are serialised by a lock. The real-time
commands :meth:`~GrblRobot.feed_hold`, :meth:`~GrblRobot.resume` and
:meth:`~GrblRobot.soft_reset` write at once, so another thread can pause or e-stop the robot
while a motion command waits; the waiting call then raises (:class:`GrblAlarm` or
:class:`GrblReset`).

Failures raise the types of :mod:`labauto.drivers.errors`: :class:`DeviceTimeout`,
:class:`DeviceDisconnected`, :class:`UnexpectedReply`, :class:`DeviceRefused` (a target outside
the travel limits, before anything is sent) and the GRBL faults below. After any of them,
:meth:`GrblRobot.reconnect` gives a clean link. (With send-and-wait a reply that comes after its
timeout could otherwise be taken for the answer to the next line.)
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from threading import Lock, RLock
from types import TracebackType

from .errors import DeviceFault, DeviceRefused, DeviceTimeout, UnexpectedReply
from .grbl_protocol import (
    CRITICAL_ALARMS,
    CYCLE_START,
    FEED_HOLD,
    MAX_LINE_LENGTH,
    SOFT_RESET,
    STATUS_QUERY,
    BuildOptions,
    GrblStatus,
    ReplyKind,
    TravelLimits,
    Vector3,
    alarm_meaning,
    classify_reply,
    error_meaning,
    format_axis_words,
    parse_build_options,
    parse_status,
    parse_version_feedback,
    travel_problems,
)
from .line_link import ExchangeCallback, LineLink

__all__ = [
    "GrblAlarm",
    "GrblError",
    "GrblNotArmed",
    "GrblReset",
    "GrblRobot",
    "GrblStatus",
    "TravelLimits",
    "TravelMismatch",
]

logger = logging.getLogger(__name__)

#: After a reply timed out, a new connection waits until the link is quiet this long.
_SETTLE_S = 0.05
#: GRBL sleeps 500 ms after printing ``ALARM:N`` (``report_alarm_message``); margin for a slow host.
_ALARM_DELAY_S = 1.0
_RESET_MESSAGE = "[MSG:Reset to continue]"
#: How long to wait for the answer to a ``$I`` that a booting board may have dropped.
_SECOND_ANSWER_S = 0.5

_REALTIME_NAMES = {STATUS_QUERY: "?", FEED_HOLD: "!", CYCLE_START: "~", SOFT_RESET: "^X"}


class GrblError(DeviceFault):
    """GRBL rejected a line with ``error:N``.

    Attributes
    ----------
    code
        N.
    meaning
        Its text from the GRBL 1.1 error table.
    command
        The line that was rejected.
    """

    def __init__(self, code: int, command: str, *, device: str = "robot") -> None:
        self.meaning = error_meaning(code)
        self.command = command
        super().__init__(
            f"error:{code} in reply to {command!r}: {self.meaning}", device=device, code=code
        )


class GrblAlarm(DeviceFault):
    """GRBL is in the alarm state (``ALARM:N``, or a status report showing ``Alarm``).

    Attributes
    ----------
    code
        N, or ``None`` when the state is known but not its cause (e.g. the homing lock after
        power-up).
    meaning
        Its text from the GRBL 1.1 alarm table.
    requires_reset
        True for ALARM:1 and ALARM:2, after which GRBL listens to nothing but a soft reset.
    """

    def __init__(self, code: int | None, context: str, *, device: str = "robot") -> None:
        self.meaning = (
            alarm_meaning(code)
            if code is not None
            else "alarm state (homing lock or earlier alarm)"
        )
        self.requires_reset = code in CRITICAL_ALARMS
        label = f"ALARM:{code}" if code is not None else "Alarm"
        hint = "soft_reset(), then home()" if self.requires_reset else "home() or unlock()"
        super().__init__(
            f"{label} {context}: {self.meaning} Recover with {hint}.", device=device, code=code
        )


class GrblReset(DeviceFault):
    """The controller was reset while a line awaited its answer: the line did not (fully) run.

    Raised for a start-up banner instead of the answer, and for an ``ok`` that arrives after
    :meth:`GrblRobot.soft_reset` was called (GRBL acknowledges the aborted line).
    """


class GrblNotArmed(DeviceRefused):
    """A motion command was refused because the e-stop latch is set (nothing was sent).

    Set by :meth:`GrblRobot.soft_reset` and by an unexpected start-up banner; cleared by
    :meth:`GrblRobot.home` or :meth:`GrblRobot.unlock`. ``reason`` says what set it.
    """

    def __init__(self, reason: str, command: str, *, device: str = "robot") -> None:
        self.reason = reason
        super().__init__(
            f"{command} refused: not armed since the {reason}; re-arm with home() or unlock()",
            device=device,
        )


class TravelMismatch(DeviceRefused):
    """The configured travel limits do not fit the controller's machine space.

    ``problems`` holds one sentence per axis (see
    :func:`labauto.drivers.grbl_protocol.travel_problems`).
    """

    def __init__(self, problems: list[str], *, device: str = "robot") -> None:
        self.problems = problems
        super().__init__(
            "configured travel does not fit the controller: " + "; ".join(problems),
            device=device,
        )


class GrblRobot:
    """A GRBL 1.1 gantry used as a colony-picking robot.

    Parameters
    ----------
    url
        Anything ``serial.serial_for_url`` opens: ``/dev/ttyUSB0``, ``socket://host:port``, a pty.
    baudrate
        Serial speed (ignored by ``socket://``).
    timeout
        Seconds to wait for any reply that does not wait for motion.
    limits
        Travel limits in machine coordinates (mm); targets outside are refused before sending.
        The default is a stock GRBL build's negative space (:class:`TravelLimits`).
    safe_z
        Z height (mm) for travelling in X/Y. Default 0, the top of the default Z range.
    travel_feed, z_feed
        Feed rates (mm/min) for X/Y travel and for Z moves.
    motion_timeout
        Seconds to wait for motion to finish (``G4 P0``, homing).
    tool_timeout
        Seconds to wait for the reply to a tool command (``M8``/``M9``). GRBL answers it once
        the motion before it is done, so queued motion is waited for first (with
        ``motion_timeout``) and a lost reply then costs ``tool_timeout``, not a whole
        ``motion_timeout``. Default: ``timeout``.
    name
        Device name used in error messages and ``check()``.
    tool_on_command, tool_off_command
        Lines that switch the pick tool (default ``M8`` / ``M9``, the flood-coolant output).
    on_exchange
        ``callback(direction, line)`` called for every line and real-time byte sent
        (``"tx"``) and every non-empty line received (``"rx"``), e.g. to store it in the run's
        audit log. Called synchronously; an exception it raises reaches the caller.
    poll_interval
        Seconds between status polls in :meth:`wait_idle`, and the pyserial read timeout.
    boot_timeout
        Extra seconds :meth:`connect` waits for a start-up banner when ``$I`` gets no answer
        (a board that resets when its port opens boots for about a second).
    check_travel
        Check ``limits`` against the controller's settings when connecting.

    Raises
    ------
    ValueError
        For a non-positive feed or timeout, ``safe_z`` outside ``limits.z``, or a tool command
        that is empty or has a line break.
    """

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 115200,
        timeout: float = 2.0,
        limits: TravelLimits | None = None,
        safe_z: float = 0.0,
        travel_feed: float = 3000.0,
        z_feed: float = 600.0,
        motion_timeout: float = 60.0,
        tool_timeout: float | None = None,
        name: str = "robot",
        tool_on_command: str = "M8",
        tool_off_command: str = "M9",
        on_exchange: ExchangeCallback | None = None,
        poll_interval: float = 0.02,
        boot_timeout: float = 2.5,
        check_travel: bool = True,
    ) -> None:
        self.url = url
        self.name = name
        self.baudrate = baudrate
        self.limits = limits or TravelLimits()
        for label, value in (
            ("timeout", timeout),
            ("travel_feed", travel_feed),
            ("z_feed", z_feed),
            ("motion_timeout", motion_timeout),
            ("tool_timeout", timeout if tool_timeout is None else tool_timeout),
            ("poll_interval", poll_interval),
        ):
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: {label} must be a positive number, got {value!r}")
        if not (isinstance(boot_timeout, int | float) and boot_timeout >= 0):
            raise ValueError(f"{name}: boot_timeout must be >= 0, got {boot_timeout!r}")
        problem = self.limits.violation(z=safe_z)
        if problem:
            raise ValueError(f"{name}: safe_z: {problem}")
        for label, command in (
            ("tool_on_command", tool_on_command),
            ("tool_off_command", tool_off_command),
        ):
            if not command.strip() or "\n" in command or "\r" in command:
                raise ValueError(f"{name}: {label} must be one non-empty line, got {command!r}")
        self.timeout = float(timeout)
        self.safe_z = float(safe_z)
        self.travel_feed = float(travel_feed)
        self.z_feed = float(z_feed)
        self.motion_timeout = float(motion_timeout)
        self.tool_timeout = float(timeout if tool_timeout is None else tool_timeout)
        self._motion_pending = False  # moves queued without waiting for them
        self.tool_on_command = tool_on_command.strip()
        self.tool_off_command = tool_off_command.strip()
        self.poll_interval = float(poll_interval)
        self.boot_timeout = float(boot_timeout)
        self.check_travel = check_travel

        self._link = LineLink(
            url,
            device=name,
            baudrate=baudrate,
            read_timeout=self.poll_interval,
            write_timeout=self.timeout,
            on_exchange=on_exchange,
        )
        self._io_lock = RLock()  # one line command / status query at a time
        self._arm_lock = Lock()  # the latch check and a line's write are one step
        self._firmware: str | None = None
        self._options: BuildOptions | None = None
        self._settings: dict[int, str] = {}
        self._last_alarm: int | None = None
        self._reset_required = False
        self._reset_message_seen = False
        self._reset_messages = 0
        self._banners_seen = 0
        self._resets = 0  # soft resets sent and banners seen: a change voids awaited answers
        self._disarmed: str | None = None
        self._expect_banner = False  # a banner now is the board booting, not an e-stop
        self._wco: Vector3 | None = None
        self._startup_errors: list[str] = []
        self._late_answers_possible = False  # a reply timed out: its answer may still come

    # ------------------------------------------------------------------ connection

    @property
    def on_exchange(self) -> ExchangeCallback | None:
        """The exchange callback (settable, e.g. by the orchestrator for its audit log)."""
        return self._link.on_exchange

    @on_exchange.setter
    def on_exchange(self, callback: ExchangeCallback | None) -> None:
        self._link.on_exchange = callback

    @property
    def firmware(self) -> str | None:
        """Firmware version (``"1.1h"``) reported by the controller; ``None`` before connecting."""
        return self._firmware

    @property
    def build_options(self) -> BuildOptions | None:
        """The ``[OPT:]`` build options of ``$I``; ``None`` before connecting."""
        return self._options

    @property
    def controller_settings(self) -> dict[int, str]:
        """The ``$$`` settings read when connecting (``{}`` if they could not be read)."""
        return dict(self._settings)

    @property
    def startup_errors(self) -> list[str]:
        """Start-up blocks the controller rejected, as reported (``>G1X5:error:22``)."""
        return list(self._startup_errors)

    @property
    def is_connected(self) -> bool:
        """Whether the port is open."""
        return self._link.is_open

    @property
    def last_alarm(self) -> int | None:
        """N of the last ``ALARM:N`` received (kept until the next alarm)."""
        return self._last_alarm

    @property
    def armed(self) -> bool:
        """False after a soft reset or an unexpected restart, until :meth:`home`/:meth:`unlock`."""
        return self._disarmed is None

    @property
    def disarmed_reason(self) -> str | None:
        """What set the e-stop latch (``None`` when armed)."""
        return self._disarmed

    def connect(self) -> None:
        """Open the port and identify the controller (no-op when already connected).

        Sends ``$I`` and waits for its ``ok`` (re-sending it once per start-up banner, since an
        Arduino resets when its port opens), then reads ``$$`` and checks the travel limits.
        If an earlier reply timed out, it then reads until the link has been quiet for 50 ms,
        so late answers to lines sent before do not pass for answers to the next ones.
        If the controller is known to be locked after ALARM:1/2, a soft reset is sent first.
        Motion state and the e-stop latch are left alone.

        Raises
        ------
        DeviceDisconnected
            The port cannot be opened.
        DeviceTimeout
            No answer to ``$I`` (wrong port or baud rate, or not a GRBL controller).
        UnexpectedReply
            The answer is not GRBL's.
        TravelMismatch
            ``limits`` do not fit the controller's machine space.
        """
        with self._io_lock:
            if self._link.is_open:
                return
            self._link.open()
            try:
                self._handshake()
                self._read_settings()
            except BaseException:
                self._link.close()
                raise

    def close(self) -> None:
        """Close the port (idempotent). The controller keeps its state."""
        self._link.close()

    def reconnect(self) -> None:
        """Close and open the link again, e.g. after a timeout, disconnect or garbled reply.

        Renews only the link (it does not call :meth:`close`, which a subclass may extend to
        release more, such as a simulator it owns).
        """
        with self._io_lock:
            self._link.close()
            self.connect()

    def __enter__(self) -> GrblRobot:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def check(self) -> dict[str, object]:
        """Identify the controller for ``labauto devices check``.

        Connects for the duration of the call if not connected yet.

        Returns
        -------
        dict
            ``{"device", "kind": "grbl", "url", "firmware", "build_options", "state",
            "substate", "position": [x, y, z] | None, "last_alarm", "reset_required", "armed",
            "startup_errors"}``.

        Raises
        ------
        DeviceError
            Any subclass, when the controller cannot be reached or answers wrongly.
        """
        opened_here = not self.is_connected
        if opened_here:
            self.connect()
        try:
            try:
                report = self.status()
                state, substate, position = report.state, report.substate, report.position
            except GrblAlarm:
                state, substate, position = "Alarm", None, None
            return {
                "device": self.name,
                "kind": "grbl",
                "url": self.url,
                "firmware": self.firmware,
                "build_options": self._options.codes if self._options else None,
                "state": state,
                "substate": substate,
                "position": list(position) if position is not None else None,
                "last_alarm": self._last_alarm,
                "reset_required": self._reset_required,
                "armed": self.armed,
                "startup_errors": self.startup_errors,
            }
        finally:
            if opened_here:
                self._link.close()

    identify = check

    # ------------------------------------------------------------------ queries

    def status(self) -> GrblStatus:
        """Send ``?`` and return the parsed status report.

        A report without ``WCO`` gets the last one received (``$10=0`` reports ``WPos``).

        Raises
        ------
        GrblAlarm
            The controller is locked after ALARM:1/2 and answers nothing but a soft reset.
        DeviceTimeout, DeviceDisconnected, UnexpectedReply
        """
        with self._io_lock:
            self._drain(raise_alarm=False)
            if self._reset_required:
                raise GrblAlarm(self._last_alarm, "locks the controller", device=self.name)
            self._write(STATUS_QUERY)
            deadline = time.monotonic() + self.timeout
            while True:
                text = self._link.read_line(deadline, "?")
                reply = classify_reply(text)
                if reply.kind is ReplyKind.STATUS:
                    try:
                        report = parse_status(text)
                    except ValueError as exc:
                        raise UnexpectedReply(str(exc), device=self.name) from None
                    return self._with_offset(report)
                if reply.kind is ReplyKind.UNKNOWN:
                    raise UnexpectedReply(
                        f"expected a status report, got {text!r}", device=self.name
                    )
                self._note(reply.kind, text, reply.code, reply.version)
                if self._reset_required:
                    raise GrblAlarm(self._last_alarm, "locks the controller", device=self.name)

    def settings(self) -> dict[int, str]:
        """Return the controller's ``$$`` settings as ``{number: value text}``."""
        values: dict[int, str] = {}
        for line in self._command("$$", raise_pending_alarm=False, needs_arming=False):
            number, _, value = line[1:].partition("=")
            if number.isdigit():
                values[int(number)] = value
        return values

    def execute(self, line: str, *, timeout: float | None = None) -> list[str]:
        """Send one raw line (``$10=0``, ``G10 L2 P1 X-5``, ``$N0=...``) and wait for its ``ok``.

        For set-up and maintenance. A G-code line needs the driver armed; a ``$`` command does
        not. Neither re-arms the driver (use :meth:`home` / :meth:`unlock`).

        Returns
        -------
        list of str
            The push and setting lines printed before the ``ok``.

        Raises
        ------
        GrblError, GrblAlarm, GrblNotArmed, GrblReset, DeviceTimeout, DeviceDisconnected,
        UnexpectedReply
        """
        system = line.strip().startswith("$")
        return self._command(
            line.strip(), timeout=timeout, raise_pending_alarm=not system, needs_arming=not system
        )

    # ------------------------------------------------------------------ machine control

    def home(self) -> GrblStatus:
        """Run the homing cycle (``$H``), re-arm, and return the status afterwards.

        Clears any alarm; after ALARM:1/2 first waits for ``[MSG:Reset to continue]`` and
        sends a soft reset. Waits up to ``motion_timeout`` (GRBL answers no ``?`` meanwhile).
        """
        with self._io_lock:
            self._release_critical_lock()
            self._command(
                "$H", timeout=self.motion_timeout, raise_pending_alarm=False, needs_arming=False
            )
            self._disarmed = None
            return self.status()

    def unlock(self) -> None:
        """Clear the alarm lock without homing (``$X``) and re-arm; resets first after ALARM:1/2.

        The machine position may be wrong after an alarm: prefer :meth:`home`.
        """
        with self._io_lock:
            self._release_critical_lock()
            self._command("$X", raise_pending_alarm=False, needs_arming=False)
            self._disarmed = None

    def move_to(
        self, x: float, y: float, z: float | None = None, *, wait: bool = True
    ) -> GrblStatus | None:
        """Move to (x, y) at safe height, then descend to ``z``.

        Sends ``G21 G90 G53 G1`` lines: Z to ``safe_z``, X/Y at ``travel_feed``, then Z to ``z``
        at ``z_feed`` (skipped when ``z`` is ``None`` or equals ``safe_z``).

        Parameters
        ----------
        x, y, z
            Target in mm, machine coordinates. ``z=None`` stays at ``safe_z``.
        wait
            Wait until the motion has finished (:meth:`wait_idle`) and return its status;
            otherwise return ``None`` once the moves are queued.

        Raises
        ------
        DeviceRefused
            A coordinate is outside the travel limits or not finite; nothing was sent.
        GrblNotArmed
            The e-stop latch is set; nothing was sent.
        GrblAlarm, GrblError, GrblReset, DeviceTimeout, DeviceDisconnected, UnexpectedReply
        """
        target_z = self.safe_z if z is None else z
        self._refuse_outside_limits(x=x, y=y, z=target_z)
        lines = [
            f"G21 G90 G53 G1 {format_axis_words(Z=self.safe_z, F=self.z_feed)}",
            f"G21 G90 G53 G1 {format_axis_words(X=x, Y=y, F=self.travel_feed)}",
        ]
        if target_z != self.safe_z:
            lines.append(f"G21 G90 G53 G1 {format_axis_words(Z=target_z, F=self.z_feed)}")
        with self._io_lock:
            for line in lines:
                self._motion_pending = True
                self._command(line)
            return self.wait_idle() if wait else None

    def wait_idle(self, timeout: float | None = None) -> GrblStatus:
        """Wait until every queued motion is done and the machine is ``Idle``.

        Sends ``G4 P0`` (GRBL answers it only once the planner is empty), then polls ``?``
        until the state is ``Idle`` (or ``Check`` in check mode).

        Parameters
        ----------
        timeout
            Seconds; defaults to ``motion_timeout``.

        Raises
        ------
        GrblAlarm
            An alarm stopped the motion, or the machine is in ``Alarm``.
        DeviceTimeout
            Motion did not finish in time (e.g. a feed hold was never resumed). The
            ``ok`` of that ``G4 P0`` may still come later; the next ``wait_idle`` copes with it,
            as it confirms ``Idle`` by status reports.
        """
        limit = self.motion_timeout if timeout is None else timeout
        deadline = time.monotonic() + limit
        with self._io_lock:
            try:
                self._command("G4 P0", timeout=limit)
            except GrblError as exc:
                if exc.code != 9:  # 9: G-code locked out in the alarm state
                    raise
                raise GrblAlarm(self._last_alarm, "locks the machine", device=self.name) from exc
            while True:
                report = self.status()
                if report.state in ("Idle", "Check"):
                    self._motion_pending = False
                    return report
                if report.is_alarm:
                    raise GrblAlarm(self._last_alarm, "stopped the machine", device=self.name)
                if time.monotonic() > deadline:
                    raise DeviceTimeout(
                        f"machine not idle after {limit} s (state {report.state})",
                        device=self.name,
                    )
                time.sleep(self.poll_interval)

    def dwell(self, seconds: float) -> None:
        """Wait for queued motion, then pause ``seconds`` on the controller (``G4 P``)."""
        if not (isinstance(seconds, int | float) and math.isfinite(seconds) and seconds >= 0):
            raise DeviceRefused(
                f"dwell of {seconds!r} s is not a non-negative number", device=self.name
            )
        self._command(f"G4 P{seconds:.3f}", timeout=self.motion_timeout + seconds)

    def tool_on(self) -> None:
        """Switch the pick tool on (``tool_on_command``), after any queued motion."""
        self._tool(self.tool_on_command)

    def tool_off(self) -> None:
        """Switch the pick tool off (``tool_off_command``), after any queued motion; allowed
        while not armed (after a reset the queue is gone and the tool must still go off)."""
        self._tool(self.tool_off_command, needs_arming=False)

    def _tool(self, line: str, needs_arming: bool = True) -> None:
        with self._io_lock:
            if self._motion_pending and self._disarmed is None:
                self.wait_idle()
            self._command(line, timeout=self.tool_timeout, needs_arming=needs_arming)

    def feed_hold(self) -> None:
        """Pause motion now (real-time ``!``); :meth:`resume` continues. Safe from any thread."""
        self._write(FEED_HOLD)

    def resume(self) -> None:
        """Resume after a feed hold (real-time ``~``). Safe from any thread."""
        self._write(CYCLE_START)

    def soft_reset(self) -> None:
        """Emergency stop: Ctrl-X (0x18) at once, latch, then wait for the start-up banner.

        GRBL stops at once and clears its queue; a reset during motion raises ALARM:3
        (recorded in :attr:`last_alarm`, not raised) and the machine then needs :meth:`home`
        (recommended: position may be lost) or :meth:`unlock`. Whatever the controller says,
        the driver refuses motion until one of them re-arms it. The byte is written
        immediately, also while another thread waits for a reply (that call then raises).
        If the controller turns out to be inside the silent window of a critical alarm, the
        reset is sent again once ``[MSG:Reset to continue]`` has come.

        Raises
        ------
        DeviceTimeout
            No banner within ``timeout`` plus GRBL's 500 ms alarm delay.
        """
        banners_before, messages_before = self._banners_seen, self._reset_messages
        with self._arm_lock:
            self._disarmed = "soft reset (e-stop)"
            self._resets += 1
            self._write(SOFT_RESET)
        with self._io_lock:
            if self._banners_seen == banners_before:
                self._await_banner(messages_before)

    # ------------------------------------------------------------------ pick cycle

    def pick(self, x: float, y: float, z_pick: float, dwell_s: float = 0.5) -> GrblStatus:
        """Take a probe at (x, y): travel at safe height, descend to ``z_pick``, tool on,
        dwell, tool off, rise to ``safe_z``. Returns the final status.

        Everything is checked against the limits before the first line is sent. A reset
        during the pick fails it (:class:`GrblReset`, :class:`GrblAlarm` or
        :class:`GrblNotArmed`); no line of it is sent after the reset.
        """
        return self._touch("pick", x, y, z_pick, dwell_s)

    def deposit(self, x: float, y: float, z_deposit: float, dwell_s: float = 0.5) -> GrblStatus:
        """Deliver the probe at (x, y): the same motion and tool sequence as :meth:`pick`."""
        return self._touch("deposit", x, y, z_deposit, dwell_s)

    def _touch(self, action: str, x: float, y: float, z: float, dwell_s: float) -> GrblStatus:
        self._refuse_outside_limits(x=x, y=y, z=z)
        if not (isinstance(dwell_s, int | float) and math.isfinite(dwell_s) and dwell_s >= 0):
            raise DeviceRefused(
                f"{action}: dwell_s={dwell_s!r} is not a non-negative number", device=self.name
            )
        if self._disarmed is not None:
            raise GrblNotArmed(self._disarmed, action, device=self.name)
        with self._io_lock:
            self.move_to(x, y, z)
            self.tool_on()
            self.dwell(dwell_s)
            self.tool_off()
            report = self.move_to(x, y)
        assert report is not None
        return report

    # ------------------------------------------------------------------ internals

    def _refuse_outside_limits(self, **targets: float | None) -> None:
        problem = self.limits.violation(**targets)
        if problem:
            raise DeviceRefused(f"move refused: {problem}", device=self.name)

    def _with_offset(self, report: GrblStatus) -> GrblStatus:
        if report.work_offset is not None:
            self._wco = report.work_offset
            return report
        if self._wco is not None:
            return dataclasses.replace(report, work_offset=self._wco)
        return report

    def _release_critical_lock(self) -> None:
        self._drain(raise_alarm=False)
        if self._reset_required:
            logger.info(
                "%s: controller locked after ALARM:%s; soft reset", self.name, self._last_alarm
            )
            self._await_reset_message()
            self.soft_reset()

    def _await_reset_message(self) -> None:
        """After ALARM:1/2 wait for ``[MSG:Reset to continue]``: a reset before it is lost."""
        deadline = time.monotonic() + self.timeout + _ALARM_DELAY_S
        while not self._reset_message_seen:
            try:
                text = self._link.read_line(deadline, _RESET_MESSAGE)
            except DeviceTimeout:
                logger.warning(
                    "%s: no %r after ALARM:%s", self.name, _RESET_MESSAGE, self._last_alarm
                )
                return
            reply = classify_reply(text)
            self._note(reply.kind, text, reply.code, reply.version)

    def _handshake(self) -> None:
        """Identify the controller with ``$I``; its answer is ``[VER:...]``, ``[OPT:...]``, ``ok``.

        ``ok`` or ``error:N`` before ``[VER:`` are late answers to lines sent before this
        connection (e.g. after a timeout) and are skipped, except ``error:8``: GRBL refuses
        ``$I`` while it moves, and the connection is then kept with the last known version.
        Silence for ``timeout`` is given ``boot_timeout`` more for a banner (a board that
        resets on open drops what it was sent while booting); the banner then earns a new
        ``$I``. A banner seen here is a boot, not an e-stop, unless one was seen before.
        """
        if self._reset_required:
            self._await_reset_message()
            self.soft_reset()
        self._expect_banner = self._banners_seen == 0
        try:
            self._identify()
        finally:
            self._expect_banner = False

    def _identify(self) -> None:
        self._link.write_line("$I")
        deadline = time.monotonic() + self.timeout
        heard = booted = identified = False
        sent = answered = 0
        sent += 1
        while True:
            try:
                text = self._link.read_line(deadline, "$I")
            except DeviceTimeout:
                if identified:  # a $I sent while the board booted was lost after all
                    return
                if not heard and not booted and self.boot_timeout > 0:
                    booted = True  # wait once for a board that is still booting
                    deadline = time.monotonic() + self.boot_timeout
                    continue
                raise DeviceTimeout(
                    f"no answer to '$I' from {self.url} within {self.timeout} s "
                    "(wrong port or baud rate, or not a GRBL controller?)",
                    device=self.name,
                ) from None
            heard = True
            reply = classify_reply(text)
            if (reply.kind is ReplyKind.OK and identified) or (
                reply.kind is ReplyKind.ERROR and reply.code == 8
            ):
                answered += 1
                if answered >= sent:
                    if self._late_answers_possible:
                        self._settle()
                    return
                # A $I sent before the banner may have been kept: its answer comes next.
                deadline = time.monotonic() + min(self.timeout, _SECOND_ANSWER_S)
                continue
            if reply.kind is ReplyKind.UNKNOWN:
                raise UnexpectedReply(f"answer to '$I' is not GRBL's: {text!r}", device=self.name)
            version = parse_version_feedback(text)
            if version:
                self._firmware, identified = version, True
                continue
            options = parse_build_options(text)
            if options is not None:
                self._options = options
                continue
            self._note(reply.kind, text, reply.code, reply.version)
            if reply.kind is ReplyKind.BANNER:  # the board reset on open: $I may be lost
                self._link.write_line("$I")
                sent += 1
                deadline = time.monotonic() + self.timeout

    def _read_settings(self) -> None:
        """Read ``$$`` and check the travel limits against it (skipped while GRBL moves)."""
        try:
            self._settings = self.settings()
        except GrblError as exc:
            if exc.code != 8:  # 8: '$' commands need Idle/Alarm; keep what was known
                raise
            return
        enforced = self._settings.get(22) == "1" or self._settings.get(20) == "1"
        if not (self.check_travel and enforced):
            return
        problems = travel_problems(self.limits, self._settings, self._options or BuildOptions())
        if problems:
            raise TravelMismatch(problems, device=self.name)

    def _settle(self) -> None:
        """Read away whatever else arrives until the link is quiet for ``_SETTLE_S``.

        Catches late answers queued behind the handshake, such as a second ``$I`` answer when
        an earlier connect attempt timed out on a slow controller.
        """
        self._late_answers_possible = False
        self._link.read_until_quiet(_SETTLE_S, self.timeout)
        self._drain(raise_alarm=False)

    def _command(
        self,
        line: str,
        *,
        timeout: float | None = None,
        raise_pending_alarm: bool = True,
        needs_arming: bool = True,
    ) -> list[str]:
        """Send one line and wait for its ``ok``; return the push/setting lines seen meanwhile."""
        if "\n" in line or "\r" in line or len(line) > MAX_LINE_LENGTH:
            raise ValueError(
                f"{self.name}: not a single GRBL line of <= {MAX_LINE_LENGTH} characters: {line!r}"
            )
        with self._io_lock:
            self._drain(raise_alarm=raise_pending_alarm)
            with self._arm_lock:
                if needs_arming and self._disarmed is not None:
                    raise GrblNotArmed(self._disarmed, repr(line), device=self.name)
                resets_before = self._resets
                self._link.write_line(line)
            deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
            extra: list[str] = []
            while True:
                text = self._read_line(deadline, line)
                reply = classify_reply(text)
                match reply.kind:
                    case ReplyKind.OK:
                        if self._resets != resets_before:
                            raise GrblReset(
                                f"{line!r} was cut short by a soft reset (its 'ok' does not "
                                "mean it ran)",
                                device=self.name,
                            )
                        return extra
                    case ReplyKind.ERROR:
                        raise GrblError(reply.code or 0, line, device=self.name)
                    case ReplyKind.ALARM:
                        self._note_alarm(reply.code)
                        raise GrblAlarm(reply.code, f"while executing {line!r}", device=self.name)
                    case ReplyKind.BANNER:
                        self._note(reply.kind, text, None, reply.version)
                        raise GrblReset(
                            f"controller restarted while waiting for the reply to {line!r}",
                            device=self.name,
                        )
                    case ReplyKind.UNKNOWN:
                        raise UnexpectedReply(
                            f"reply {text!r} to {line!r} is not GRBL's", device=self.name
                        )
                    case ReplyKind.PUSH | ReplyKind.SETTING:
                        self._note(reply.kind, text, None, None)
                        extra.append(text)
                    case _:
                        self._note(reply.kind, text, reply.code, None)

    def _await_banner(self, messages_before: int) -> None:
        deadline = time.monotonic() + self.timeout + _ALARM_DELAY_S
        while True:
            try:
                text = self._read_line(deadline, "soft reset")
            except DeviceTimeout:
                raise DeviceTimeout(
                    f"no start-up banner within {self.timeout + _ALARM_DELAY_S:.1f} s after "
                    "the soft reset",
                    device=self.name,
                ) from None
            reply = classify_reply(text)
            self._note(reply.kind, text, reply.code, reply.version)
            if reply.kind is ReplyKind.BANNER:
                return
            if self._reset_messages > messages_before:
                # The reset came inside the critical alarm's silent window and was lost.
                logger.info("%s: reset was lost in the alarm window; resetting again", self.name)
                messages_before = self._reset_messages
                with self._arm_lock:
                    self._resets += 1
                    self._write(SOFT_RESET)
                deadline = time.monotonic() + self.timeout + _ALARM_DELAY_S

    def _read_line(self, deadline: float, awaiting: str) -> str:
        try:
            return self._link.read_line(deadline, awaiting)
        except DeviceTimeout:
            self._late_answers_possible = True
            raise

    def _drain(self, *, raise_alarm: bool) -> None:
        """Read what has already arrived; note alarms, banners and messages; drop stale replies."""
        self._link.poll()
        alarm: int | None = None
        while (text := self._link.pop_line()) is not None:
            reply = classify_reply(text)
            if reply.kind is ReplyKind.ALARM:
                alarm = reply.code
            self._note(reply.kind, text, reply.code, reply.version)
        if alarm is not None and raise_alarm:
            raise GrblAlarm(alarm, "reported since the last command", device=self.name)

    def _note(self, kind: ReplyKind, text: str, code: int | None, version: str | None) -> None:
        """Update what the driver knows from a line that is not the awaited answer."""
        if kind is ReplyKind.ALARM:
            self._note_alarm(code)
        elif kind is ReplyKind.BANNER:
            self._note_banner(version)
        elif kind is ReplyKind.PUSH and text == _RESET_MESSAGE:
            self._reset_required = True
            self._reset_message_seen = True
            self._reset_messages += 1
        elif kind is ReplyKind.STARTUP and code is not None:
            self._startup_errors.append(text)
            logger.warning(
                "%s: start-up block rejected: %s (%s)", self.name, text, error_meaning(code)
            )
        elif kind in (ReplyKind.OK, ReplyKind.ERROR, ReplyKind.STATUS, ReplyKind.UNKNOWN):
            logger.debug("%s: discarded stale line %r", self.name, text)

    def _note_banner(self, version: str | None) -> None:
        self._firmware = version or self._firmware
        self._reset_required = False
        self._reset_message_seen = False
        self._banners_seen += 1
        self._wco = None
        with self._arm_lock:
            self._resets += 1
            if self._disarmed is None and not self._expect_banner:
                self._disarmed = "unexpected start-up banner (the controller restarted)"
                logger.warning("%s: controller restarted; motion refused until re-armed", self.name)

    def _note_alarm(self, code: int | None) -> None:
        self._last_alarm = code
        if code in CRITICAL_ALARMS:
            self._reset_required = True
            self._reset_message_seen = False

    def _write(self, data: bytes) -> None:
        self._link.write(data, shown=_REALTIME_NAMES.get(data, data.hex()))
