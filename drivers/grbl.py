"""Driver for a picking robot (gantry) running GRBL 1.1.

The driver talks to the controller through pyserial's ``serial_for_url``, so a USB serial port
(``/dev/ttyUSB0``), a network bridge (``socket://host:port``) and a pseudo-terminal (the
simulator of :mod:`labauto.drivers.grbl_sim`) all work the same way.

Protocol choices
----------------
* Plain send-and-wait: one line, then read until its ``ok`` / ``error:N``. Lines end in ``\\n``
  only (GRBL treats ``\\r`` as a line end too, so ``\\r\\n`` would earn two replies).
* Moves are absolute millimetres in *machine* coordinates (``G21 G90 G53 G1``), so the travel
  limits checked here are the ones GRBL's own soft limits use, whatever work offset is active.
  Every move uses ``G1`` with an explicit feed: ``travel_feed`` for X/Y, ``z_feed`` for Z.
* Push messages (``[MSG:...]``, ``[GC:...]``, ``>...:ok``) are logged and otherwise ignored.
  A stray ``ok`` or status report left over from an earlier failure is read away (and logged)
  before each command. An ``ALARM:N`` that arrived between commands is raised by the next
  motion command; :meth:`GrblRobot.status`, :meth:`~GrblRobot.home`, :meth:`~GrblRobot.unlock`
  and :meth:`~GrblRobot.soft_reset` record it instead, since they are how one recovers.
* After ALARM:1 (hard limit) or ALARM:2 (soft limit) GRBL ignores everything but a soft reset.
  The driver remembers this: :meth:`~GrblRobot.home`, :meth:`~GrblRobot.unlock` and
  :meth:`~GrblRobot.connect` send the reset first, and :meth:`~GrblRobot.status` raises
  :class:`GrblAlarm` at once instead of waiting for an answer that will not come.
* Firmware version: read from ``$I`` (``[VER:1.1h.20190830:]``) on connect, and from the
  start-up banner whenever one is seen (an Arduino resets when the port opens; the banner then
  arrives first and ``$I`` is sent again).

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

import contextlib
import logging
import math
import socket
import time
from collections.abc import Callable
from threading import Lock, RLock
from types import TracebackType

import serial
from serial.urlhandler import protocol_socket as socket_url

from .errors import (
    DeviceDisconnected,
    DeviceFault,
    DeviceRefused,
    DeviceTimeout,
    UnexpectedReply,
)
from .grbl_protocol import (
    CRITICAL_ALARMS,
    CYCLE_START,
    FEED_HOLD,
    MAX_LINE_LENGTH,
    SOFT_RESET,
    STATUS_QUERY,
    GrblStatus,
    ReplyKind,
    TravelLimits,
    alarm_meaning,
    classify_reply,
    error_meaning,
    format_axis_words,
    parse_status,
    parse_version_feedback,
)

__all__ = [
    "GrblAlarm",
    "GrblError",
    "GrblReset",
    "GrblRobot",
    "GrblStatus",
    "TravelLimits",
]

logger = logging.getLogger(__name__)

ExchangeCallback = Callable[[str, str], None]

#: After a reply timed out, a new connection waits until the link is quiet this long.
_SETTLE_S = 0.05

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
    """The controller restarted (start-up banner) while a reply was awaited; the line is lost."""


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
        self.on_exchange = on_exchange

        self._serial: serial.SerialBase | None = None
        self._rx = bytearray()
        self._io_lock = RLock()  # one line command / status query at a time
        self._write_lock = Lock()  # whole writes, also from other threads
        self._firmware: str | None = None
        self._last_alarm: int | None = None
        self._reset_required = False
        self._banners_seen = 0
        self._late_answers_possible = False  # a reply timed out: its answer may still come

    # ------------------------------------------------------------------ connection

    @property
    def firmware(self) -> str | None:
        """Firmware version (``"1.1h"``) reported by the controller; ``None`` before connecting."""
        return self._firmware

    @property
    def is_connected(self) -> bool:
        """Whether the port is open."""
        return self._serial is not None

    @property
    def last_alarm(self) -> int | None:
        """N of the last ``ALARM:N`` received (kept until the next alarm)."""
        return self._last_alarm

    def connect(self) -> None:
        """Open the port and identify the controller (no-op when already connected).

        Sends ``$I`` and waits for its ``ok`` (re-sending it once per start-up banner, since an
        Arduino resets when its port opens). If an earlier reply timed out, it then reads until
        the link has been quiet for 50 ms, so late answers to lines sent before do not pass
        for answers to the next ones.
        If the controller is known to be locked after ALARM:1/2, a soft reset is sent first.
        Motion state is left alone otherwise.

        Raises
        ------
        DeviceDisconnected
            The port cannot be opened.
        DeviceTimeout
            No answer to ``$I`` (wrong port or baud rate, or not a GRBL controller).
        UnexpectedReply
            The answer is not GRBL's.
        """
        with self._io_lock:
            if self._serial is not None:
                return
            try:
                self._serial = serial.serial_for_url(
                    self.url,
                    baudrate=self.baudrate,
                    timeout=self.poll_interval,
                    write_timeout=self.timeout,
                )
            except (serial.SerialException, OSError, ValueError) as exc:
                raise DeviceDisconnected(
                    f"cannot open {self.url}: {exc}", device=self.name
                ) from exc
            self._rx.clear()
            try:
                self._handshake()
            except BaseException:
                self.close()
                raise

    def close(self) -> None:
        """Close the port (idempotent). The controller keeps its state."""
        link, self._serial = self._serial, None
        self._rx.clear()
        if link is not None:
            try:
                _close_quickly(link)
            except (serial.SerialException, OSError) as exc:  # already broken: nothing to save
                logger.debug("%s: error while closing %s: %s", self.name, self.url, exc)

    def reconnect(self) -> None:
        """Close and open the link again, e.g. after a timeout, disconnect or garbled reply."""
        with self._io_lock:
            self.close()
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
            ``{"device", "kind": "grbl", "url", "firmware", "state", "substate",
            "position": [x, y, z] | None, "last_alarm", "reset_required"}``.

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
                "state": state,
                "substate": substate,
                "position": list(position) if position is not None else None,
                "last_alarm": self._last_alarm,
                "reset_required": self._reset_required,
            }
        finally:
            if opened_here:
                self.close()

    identify = check

    # ------------------------------------------------------------------ queries

    def status(self) -> GrblStatus:
        """Send ``?`` and return the parsed status report.

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
                text = self._read_line(deadline, "?")
                reply = classify_reply(text)
                if reply.kind is ReplyKind.STATUS:
                    try:
                        return parse_status(text)
                    except ValueError as exc:
                        raise UnexpectedReply(str(exc), device=self.name) from None
                if reply.kind is ReplyKind.UNKNOWN:
                    raise UnexpectedReply(
                        f"expected a status report, got {text!r}", device=self.name
                    )
                self._note(reply.kind, text, reply.code, reply.version)

    def settings(self) -> dict[int, str]:
        """Return the controller's ``$$`` settings as ``{number: value text}``."""
        values: dict[int, str] = {}
        for line in self._command("$$", raise_pending_alarm=False):
            number, _, value = line[1:].partition("=")
            if number.isdigit():
                values[int(number)] = value
        return values

    # ------------------------------------------------------------------ machine control

    def home(self) -> GrblStatus:
        """Run the homing cycle (``$H``) and return the status afterwards.

        Clears any alarm; sends a soft reset first if the controller is locked after
        ALARM:1/2. Waits up to ``motion_timeout``.
        """
        with self._io_lock:
            self._release_critical_lock()
            self._command("$H", timeout=self.motion_timeout, raise_pending_alarm=False)
            return self.status()

    def unlock(self) -> None:
        """Clear the alarm lock without homing (``$X``); soft-resets first after ALARM:1/2.

        The machine position may be wrong after an alarm: prefer :meth:`home`.
        """
        with self._io_lock:
            self._release_critical_lock()
            self._command("$X", raise_pending_alarm=False)

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
        GrblAlarm, GrblError, DeviceTimeout, DeviceDisconnected, UnexpectedReply
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
        """Switch the pick tool off (``tool_off_command``), after any queued motion."""
        self._tool(self.tool_off_command)

    def _tool(self, line: str) -> None:
        with self._io_lock:
            if self._motion_pending:
                self.wait_idle()
            self._command(line, timeout=self.tool_timeout)

    def feed_hold(self) -> None:
        """Pause motion now (real-time ``!``); :meth:`resume` continues. Safe from any thread."""
        self._write(FEED_HOLD)

    def resume(self) -> None:
        """Resume after a feed hold (real-time ``~``). Safe from any thread."""
        self._write(CYCLE_START)

    def soft_reset(self) -> None:
        """Emergency stop: Ctrl-X (0x18), then wait for the start-up banner.

        GRBL stops at once and clears its queue; a reset during motion raises ALARM:3
        (recorded in :attr:`last_alarm`, not raised) and the machine then needs :meth:`home`
        (recommended: position may be lost) or :meth:`unlock`. The byte is written
        immediately, also while another thread waits for a reply (that call then raises).

        Raises
        ------
        DeviceTimeout
            No banner within ``timeout``.
        """
        banners_before = self._banners_seen
        self._write(SOFT_RESET)
        with self._io_lock:
            if self._banners_seen == banners_before:
                self._await_banner()

    # ------------------------------------------------------------------ pick cycle

    def pick(self, x: float, y: float, z_pick: float, dwell_s: float = 0.5) -> GrblStatus:
        """Take a probe at (x, y): travel at safe height, descend to ``z_pick``, tool on,
        dwell, tool off, rise to ``safe_z``. Returns the final status.

        Everything is checked against the limits before the first line is sent.
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

    def _release_critical_lock(self) -> None:
        self._drain(raise_alarm=False)
        if self._reset_required:
            logger.info(
                "%s: controller locked after ALARM:%s; soft reset", self.name, self._last_alarm
            )
            self.soft_reset()

    def _handshake(self) -> None:
        """Identify the controller with ``$I``; its answer is ``[VER:...]``, ``[OPT:...]``, ``ok``.

        ``ok`` or ``error:N`` before ``[VER:`` are late answers to lines sent before this
        connection (e.g. after a timeout) and are skipped, except ``error:8``: GRBL refuses
        ``$I`` while it moves, and the connection is then kept with the last known version.
        """
        if self._reset_required:
            self.soft_reset()
        self._write_line("$I")
        deadline = time.monotonic() + self.timeout
        identified = False
        while True:
            try:
                text = self._read_line(deadline, "$I")
            except DeviceTimeout:
                raise DeviceTimeout(
                    f"no answer to '$I' from {self.url} within {self.timeout} s "
                    "(wrong port or baud rate, or not a GRBL controller?)",
                    device=self.name,
                ) from None
            reply = classify_reply(text)
            if (reply.kind is ReplyKind.OK and identified) or (
                reply.kind is ReplyKind.ERROR and reply.code == 8
            ):
                if self._late_answers_possible:
                    self._settle()
                return
            if reply.kind is ReplyKind.UNKNOWN:
                raise UnexpectedReply(f"answer to '$I' is not GRBL's: {text!r}", device=self.name)
            version = parse_version_feedback(text)
            if version:
                self._firmware, identified = version, True
                continue
            self._note(reply.kind, text, reply.code, reply.version)
            if reply.kind is ReplyKind.BANNER:  # the board reset on open: $I was lost
                self._write_line("$I")
                deadline = time.monotonic() + self.timeout

    def _settle(self) -> None:
        """Read away whatever else arrives until the link is quiet for ``_SETTLE_S``.

        Catches late answers queued behind the handshake, such as a second ``$I`` answer when
        an earlier connect attempt timed out on a slow controller.
        """
        self._late_answers_possible = False
        quiet_until = time.monotonic() + _SETTLE_S
        hard_stop = time.monotonic() + self.timeout
        link = self._require_link()
        while (now := time.monotonic()) < quiet_until and now < hard_stop:
            try:
                chunk = link.read(link.in_waiting or 1)
            except (serial.SerialException, OSError) as exc:
                self._lost(exc)
            if chunk:
                self._rx += chunk
                self._late_answers_possible = False
        quiet_until = time.monotonic() + _SETTLE_S
        self._drain(raise_alarm=False)

    def _command(
        self, line: str, *, timeout: float | None = None, raise_pending_alarm: bool = True
    ) -> list[str]:
        """Send one line and wait for its ``ok``; return the push/setting lines seen meanwhile."""
        if "\n" in line or "\r" in line or len(line) > MAX_LINE_LENGTH:
            raise ValueError(
                f"{self.name}: not a single GRBL line of <= {MAX_LINE_LENGTH} characters: {line!r}"
            )
        with self._io_lock:
            self._drain(raise_alarm=raise_pending_alarm)
            self._write_line(line)
            deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
            extra: list[str] = []
            while True:
                text = self._read_line(deadline, line)
                reply = classify_reply(text)
                match reply.kind:
                    case ReplyKind.OK:
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
                        self._note(reply.kind, text, None, None)

    def _await_banner(self) -> None:
        deadline = time.monotonic() + self.timeout
        while True:
            try:
                text = self._read_line(deadline, "soft reset")
            except DeviceTimeout:
                raise DeviceTimeout(
                    f"no start-up banner within {self.timeout} s after the soft reset",
                    device=self.name,
                ) from None
            reply = classify_reply(text)
            self._note(reply.kind, text, reply.code, reply.version)
            if reply.kind is ReplyKind.BANNER:
                return

    def _drain(self, *, raise_alarm: bool) -> None:
        """Read what has already arrived; note alarms, banners and messages; drop stale replies."""
        self._require_link()
        while True:
            try:
                waiting = self._serial.in_waiting  # type: ignore[union-attr]
                if not waiting:
                    break
                self._rx += self._serial.read(waiting)  # type: ignore[union-attr]
            except (serial.SerialException, OSError) as exc:
                self._lost(exc)
        alarm: int | None = None
        while (text := self._pop_line()) is not None:
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
            self._firmware = version or self._firmware
            self._reset_required = False
            self._banners_seen += 1
        elif kind is ReplyKind.PUSH and "Reset to continue" in text:
            self._reset_required = True
        elif kind in (ReplyKind.OK, ReplyKind.ERROR, ReplyKind.STATUS, ReplyKind.UNKNOWN):
            logger.debug("%s: discarded stale line %r", self.name, text)

    def _note_alarm(self, code: int | None) -> None:
        self._last_alarm = code
        if code in CRITICAL_ALARMS:
            self._reset_required = True

    def _require_link(self) -> serial.SerialBase:
        if self._serial is None:
            raise DeviceDisconnected(
                f"not connected to {self.url}; call connect()", device=self.name
            )
        return self._serial

    def _lost(self, exc: BaseException) -> None:
        self.close()
        raise DeviceDisconnected(f"link to {self.url} lost: {exc}", device=self.name) from exc

    def _pop_line(self) -> str | None:
        end = self._rx.find(b"\n")
        if end < 0:
            return None
        raw = bytes(self._rx[:end])
        del self._rx[: end + 1]
        text = raw.decode("ascii", errors="replace").strip()
        if text:
            self._log("rx", text)
        return text

    def _read_line(self, deadline: float, awaiting: str) -> str:
        """Return the next non-empty line, reading until ``deadline`` (monotonic seconds)."""
        link = self._require_link()
        while True:
            text = self._pop_line()
            if text:
                return text
            if text is None:
                if time.monotonic() >= deadline:
                    self._late_answers_possible = True
                    raise DeviceTimeout(f"no reply to {awaiting!r} in time", device=self.name)
                try:
                    self._rx += link.read(link.in_waiting or 1)
                except (serial.SerialException, OSError) as exc:
                    self._lost(exc)

    def _write_line(self, line: str) -> None:
        self._write(line.encode("ascii") + b"\n", shown=line)

    def _write(self, data: bytes, *, shown: str | None = None) -> None:
        link = self._require_link()
        self._log("tx", shown if shown is not None else _REALTIME_NAMES.get(data, data.hex()))
        with self._write_lock:
            try:
                link.write(data)
            except serial.SerialTimeoutException as exc:
                raise DeviceTimeout(f"write to {self.url} timed out", device=self.name) from exc
            except (serial.SerialException, OSError) as exc:
                self._lost(exc)

    def _log(self, direction: str, line: str) -> None:
        logger.debug("%s %s %s", self.name, ">>" if direction == "tx" else "<<", line)
        if self.on_exchange is not None:
            self.on_exchange(direction, line)


def _close_quickly(link: serial.SerialBase) -> None:
    """Close a pyserial port; for ``socket://`` skip the 0.3 s sleep pyserial 3.5 adds to
    ``close()`` "in case of quick reconnects" (the driver does not need it)."""
    sock = getattr(link, "_socket", None)
    if isinstance(link, socket_url.Serial) and isinstance(sock, socket.socket):
        with contextlib.suppress(OSError):
            sock.shutdown(socket.SHUT_RDWR)
        sock.close()
        link._socket = None
        link.is_open = False
        return
    link.close()
