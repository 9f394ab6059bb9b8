"""A simulated GRBL 1.1 gantry behind a real pseudo-terminal or TCP socket.

The simulator speaks the same line protocol as a GRBL 1.1 controller, so the real driver
(:class:`labauto.drivers.grbl.GrblRobot`) talks to it through pyserial exactly as it would talk
to hardware. It runs in one background thread; its pseudo-terminal is a
:class:`labauto.drivers.pty_link.PtyLink`. Where the firmware's behaviour is known it is copied
from GRBL 1.1h, and ``tests/firmware`` compares the two byte for byte (status reports, alarms,
resets, holds, homing); what is left different is said below.

What it simulates (and the choices made where a real machine would differ)
---------------------------------------------------------------------------
* **Start-up**: like GRBL with homing enabled (``$22=1``) it starts in ``Alarm`` and prints
  ``\\r\\nGrbl 1.1h ['$' for help]`` and ``[MSG:'$H'|'$X' to unlock]``; ``homing_lock=False``
  starts ``Idle`` instead. With ``reset_on_open`` the pty behaves like an Arduino on USB: every
  open of the port restarts the controller (position lost, settings kept) and the banner comes
  ``boot_delay`` seconds later; bytes sent while it boots are lost. ``startup_blocks`` are run
  after each start-up outside ``Alarm`` and answered ``>line:ok`` / ``>line:error:N``.
* **Machine space**: as GRBL's soft limits see it. Without ``HOMING_FORCE_SET_ORIGIN`` (the
  stock build, the default for limits such as ``x=(-300, 0)``) each axis spans
  ``[-$13N, 0]``, homing ends ``homing_pulloff`` below the switch (``MPos -1``) and
  ``[OPT:V,15,128]`` has no ``Z``. Limits that start at 0 (``x=(0, 300)``) model a build with
  the option and X/Y homing to their minimum (``$23=3``): homing ends at 0 and
  ``[OPT:VZ,15,128]``. ``$$`` reports ``$23`` and ``$130``-``$132`` to match.
* **Motion**: ``G0``/``G1`` with ``X Y Z F``, ``G20/G21``, ``G90/G91``, ``G53``, ``G54`` with
  ``G10 L2 P1`` offsets, ``G17``, ``G94``, ``G80``, ``G4 P<seconds>``, ``M3/M4/M5 S``,
  ``M7/M8/M9``. Moves are queued (``ok`` at once) and executed one after another at constant
  speed, no acceleration: a move takes ``distance / feed`` (``G0`` uses ``rapid_feed``). Every
  simulated duration - moves, dwells, homing - is divided by ``speed_factor``. ``?`` during a
  move reports ``Run`` with the interpolated ``MPos`` and the programmed feed (GRBL reports the
  momentary one). ``G4``, ``G10``, ``M3-M9`` and ``$H`` wait for the planner to empty before
  their ``ok``. Arcs, jogging (``$J=``), probing and overrides are not simulated
  (``error:20`` / ``error:3``).
* **Status reports** follow GRBL's field order and refresh counters: ``WCO`` in the first report
  after a start-up and then every 10th (30th while busy), ``Ov`` (with ``A:`` when an output is
  on) every 10th (20th while busy) and right after an output changed; ``$10=0`` reports
  ``WPos`` instead of ``MPos``. The real firmware built for the host (grbl-sim) also sends
  ``Pn:`` because it has no input pins; this simulator does not.
* **Real-time bytes** ``?``, ``!``, ``~`` and Ctrl-X act immediately, also while a line waits.
  ``!`` stops the position at once but reports ``Hold:1`` (decelerating) for ``hold_decel``
  simulated seconds, then ``Hold:0``. During homing ``?`` is not answered at once; the report
  comes when homing ends (GRBL checks only for a reset then).
* **Reset** (Ctrl-X): clears the planner and the line buffer, turns outputs off; during motion or
  homing it raises ``ALARM:3`` / ``ALARM:6`` first. A line still awaiting its answer (a dwell,
  ``G4 P0``, the line a soft limit stopped) is answered ``ok`` before the banner, as GRBL does.
* **Alarms**: after printing ``ALARM:N`` GRBL sleeps 500 ms (``alarm_delay``), hearing nothing:
  ``?`` and Ctrl-X sent then are lost. A target outside ``limits`` raises ``ALARM:2``. ALARM:1 and
  ALARM:2 are *critical*: after the delay the controller prints ``[MSG:Reset to continue]`` and
  ignores everything - lines and ``?`` alike - until Ctrl-X.
* **Line endings**: like GRBL, ``\\r`` and ``\\n`` each end a line, so ``\\r\\n`` gives two
  replies. Replies end in ``\\r\\n``.

Faults
------
Armed from the constructor (``faults=[{"fault": "delay", "seconds": 0.3}]`` or :class:`Fault`
objects) or at run time with :meth:`SimulatedGantry.inject`; each is used up by the lines it
affects. They are what the real firmware cannot be made to do:

``no_reply`` (``count``)
    swallow the next ``count`` lines: not executed, never answered.
``garbled`` (``count``)
    execute the next ``count`` lines but answer line noise instead of ``ok``/``error``.
``delay`` (``seconds``, ``count``)
    answer the next ``count`` lines ``seconds`` late (wall-clock, not scaled).
``alarm_mid_move`` (``code``, ``fraction``)
    the next move (of non-zero length) stops at ``fraction`` of its length with
    ``ALARM:code`` (1 = hard limit).
``restart``
    on the next line (not executed) the controller restarts by itself (a brown-out or a
    watchdog): position and homing are lost and the banner is printed at once.
``lost_steps`` (``axis``, ``mm``, ``count``)
    the next ``count`` moves along ``axis`` lose ``mm`` of their travel on it (at most all of
    it): the carriage stops short, as when a stepper skips steps (too fast, a crash, a slipped
    belt), while the controller counts every step as done. Status reports keep showing the
    commanded position (:attr:`SimulatedGantry.reported_position`); where the head really is
    (:attr:`SimulatedGantry.position`, what a camera sees) is off by the steps lost, until a
    homing cycle finds the switches again and the offset is gone.
``disconnect``
    on the next line (not executed) drop the link: the TCP client is closed, the pty is hung up
    and replaced by a new one behind the stable path returned by :meth:`start_pty` - like a USB
    adapter re-enumerating under the same ``/dev/serial/by-id`` link.

Only one host should be connected at a time: output goes to every open link.
Run ``python -m labauto.drivers.grbl_sim`` to serve a simulator on a pty for manual use.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import os
import re
import select
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

from .grbl_protocol import CRITICAL_ALARMS, TravelLimits
from .grbl_sim_gcode import G_GROUPS, GcodeError, parse_words, strip_comments
from .grbl_sim_links import PtyEnd, TcpLink

__all__ = ["FAULT_KINDS", "Fault", "SimulatedGantry"]

FAULT_KINDS = (
    "no_reply",
    "garbled",
    "delay",
    "alarm_mid_move",
    "disconnect",
    "restart",
    "lost_steps",
)

#: What a garbled reply looks like on the wire: bit errors, a stray control byte, no "ok".
GARBLED_REPLY = b"\xf2o\x1b\xebk#\xa7"

_REALTIME = {ord("?"), ord("!"), ord("~"), 0x18}
_BUSY_POLL_S = 0.002
_IDLE_POLL_S = 0.25
_BUILD_DATE = "20190830"
_BUSY_STATES = ("Run", "Home", "Hold", "Jog", "Door")
#: GRBL's status refresh counts (config.h): WCO idle/busy, overrides idle/busy.
_WCO_REFRESH = (10, 30)
_OVR_REFRESH = (10, 20)


@dataclass
class Fault:
    """One armed fault (see the module docstring for the kinds).

    Parameters
    ----------
    kind
        One of :data:`FAULT_KINDS`.
    count
        Lines affected by ``no_reply``, ``garbled`` and ``delay``.
    seconds
        Reply delay of ``delay`` (wall-clock seconds).
    code
        Alarm code raised by ``alarm_mid_move``.
    fraction
        Where along the move ``alarm_mid_move`` strikes (0 < fraction < 1).
    axis
        Axis (``"x"``, ``"y"`` or ``"z"``) of ``lost_steps``.
    mm
        Travel lost per move by ``lost_steps`` (mm, > 0).
    """

    kind: str
    count: int = 1
    seconds: float = 0.5
    code: int = 1
    fraction: float = 0.5
    axis: str = "x"
    mm: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"unknown fault {self.kind!r}; expected one of {FAULT_KINDS}")
        if self.count < 1:
            raise ValueError(f"fault {self.kind}: count must be >= 1, got {self.count}")
        if not self.seconds >= 0:
            raise ValueError(f"fault {self.kind}: seconds must be >= 0, got {self.seconds}")
        if not 0 < self.fraction < 1:
            raise ValueError(f"fault {self.kind}: fraction must be in (0, 1), got {self.fraction}")
        if self.axis not in ("x", "y", "z"):
            raise ValueError(f"fault {self.kind}: axis must be x, y or z, got {self.axis!r}")
        if not (math.isfinite(self.mm) and self.mm > 0):
            raise ValueError(f"fault {self.kind}: mm must be > 0, got {self.mm}")

    @classmethod
    def from_config(cls, config: Fault | Mapping[str, object]) -> Fault:
        """Build a fault from a mapping such as ``{"fault": "delay", "seconds": 0.3}``.

        A :class:`Fault` is copied: the simulator counts its own copy down.
        """
        if isinstance(config, Fault):
            return dataclasses.replace(config)
        options = dict(config)
        kind = options.pop("fault", options.pop("kind", None))
        if kind is None:
            raise ValueError(f"fault config {config!r} has no 'fault' key")
        try:
            return cls(str(kind), **options)  # type: ignore[arg-type]
        except TypeError as exc:
            raise ValueError(f"fault config {config!r}: {exc}") from None


@dataclass
class _Move:
    """A queued straight-line move (or the homing cycle) in machine coordinates."""

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    feed: float  # mm/min
    duration: float  # simulated seconds, already divided by speed_factor
    homing: bool = False
    alarm_at: float | None = None  # fraction of the move where an injected alarm strikes
    alarm_code: int = 1
    elapsed: float = 0.0
    slip: tuple[float, float, float] = (0.0, 0.0, 0.0)  # travel lost by a lost_steps fault

    def progress(self) -> float:
        """Share of the move done (0..1)."""
        return 1.0 if self.duration <= 0 else min(max(self.elapsed / self.duration, 0.0), 1.0)

    def point(self, elapsed: float) -> tuple[float, float, float]:
        if self.duration <= 0:
            return self.end
        t = min(max(elapsed / self.duration, 0.0), 1.0)
        return tuple(a + (b - a) * t for a, b in zip(self.start, self.end, strict=True))  # type: ignore[return-value]


@dataclass
class _Pending:
    """The answer to a line that cannot be given yet (the controller stops reading meanwhile)."""

    replies: list[str] = field(default_factory=lambda: ["ok"])
    wait_planner: bool = False  # wait until every queued move is done
    dwell: float = 0.0  # then wait this long (simulated, scaled)
    extra_delay: float = 0.0  # then this long (wall clock; the "delay" fault)
    not_before: float = 0.0
    then: Callable[[], list[str] | None] | None = None  # action when ready; may add replies
    garbled: bool = False
    held: bool = False  # stopped by an alarm: answered "ok" only by the next reset


def _axis_layout(limits: TravelLimits, force_origin: bool | None) -> tuple[bool, int]:
    """Check ``limits`` fit a GRBL machine space; return (HOMING_FORCE_SET_ORIGIN, ``$23``)."""
    mask = 0
    for i, axis in enumerate("xyz"):
        low, high = getattr(limits, axis)
        if high == 0.0 and low < 0:
            continue
        if low == 0.0 and high > 0 and force_origin is not False:
            mask |= 1 << i
            continue
        raise ValueError(
            f"limits.{axis}=({low:g}, {high:g}) fits no GRBL machine space: expected (-travel, 0)"
            + (
                " or (0, travel) (a HOMING_FORCE_SET_ORIGIN build)"
                if force_origin is not False
                else ""
            )
        )
    if force_origin is None:
        force_origin = mask != 0
    return force_origin, mask


class SimulatedGantry:
    """A GRBL 1.1 gantry simulated in a thread, served over a pty and/or TCP.

    Parameters
    ----------
    limits
        Soft limits in machine coordinates (mm); a target outside raises ``ALARM:2``. Each axis
        is ``(-travel, 0)`` or, for a ``HOMING_FORCE_SET_ORIGIN`` build, ``(0, travel)``.
    speed_factor
        Divides every simulated duration (tests use 50-200).
    firmware
        Version in the banner and ``$I`` (``"1.1h"``).
    faults
        Faults armed from the start (:class:`Fault` objects or mappings, see module docstring).
    homing_lock
        Start in ``Alarm`` (GRBL with homing enabled, the default) instead of ``Idle``.
    rapid_feed, homing_feed
        Feed rates in mm/min of ``G0`` and of the homing cycle.
    homing_force_origin
        Model a build with ``HOMING_FORCE_SET_ORIGIN``; ``None``: whenever an axis of ``limits``
        starts at 0.
    homing_pulloff
        ``$27``: how far below the switch homing ends in a stock build (mm).
    reset_on_open, boot_delay
        Restart on every open of the pty (a DTR reset) and print the banner ``boot_delay``
        wall-clock seconds later.
    alarm_delay
        Wall-clock seconds GRBL stays deaf after printing ``ALARM:N`` (500 ms in GRBL 1.1).
    hold_decel
        Simulated seconds a feed hold reports ``Hold:1`` before ``Hold:0``.
    latency_s
        Deliver pty output in batches this far apart (a USB adapter's latency timer).
    startup_blocks
        ``$N0``/``$N1`` lines run after each start-up outside ``Alarm``.

    Examples
    --------
    >>> with SimulatedGantry(speed_factor=100) as sim:  # doctest: +SKIP
    ...     robot = GrblRobot(sim.start_pty())
    """

    def __init__(
        self,
        limits: TravelLimits | None = None,
        speed_factor: float = 1.0,
        firmware: str = "1.1h",
        faults: Iterable[Fault | Mapping[str, object]] | None = None,
        *,
        homing_lock: bool = True,
        rapid_feed: float = 6000.0,
        homing_feed: float = 3000.0,
        homing_force_origin: bool | None = None,
        homing_pulloff: float = 1.0,
        reset_on_open: bool = False,
        boot_delay: float = 1.0,
        alarm_delay: float = 0.5,
        hold_decel: float = 0.05,
        latency_s: float = 0.0,
        startup_blocks: Iterable[str] = (),
    ) -> None:
        if not speed_factor > 0:
            raise ValueError(f"speed_factor must be > 0, got {speed_factor!r}")
        if not (rapid_feed > 0 and homing_feed > 0):
            raise ValueError(f"feeds must be > 0, got {rapid_feed!r}, {homing_feed!r}")
        for label, value in (
            ("homing_pulloff", homing_pulloff),
            ("boot_delay", boot_delay),
            ("alarm_delay", alarm_delay),
            ("hold_decel", hold_decel),
            ("latency_s", latency_s),
        ):
            if not value >= 0:
                raise ValueError(f"{label} must be >= 0, got {value!r}")
        self.limits = limits or TravelLimits()
        self.force_origin, self.homing_dir_mask = _axis_layout(self.limits, homing_force_origin)
        self.speed_factor = float(speed_factor)
        self.firmware = firmware
        self.rapid_feed = float(rapid_feed)
        self.homing_feed = float(homing_feed)
        self.homing_pulloff = float(homing_pulloff)
        self.reset_on_open = reset_on_open
        self.boot_delay = float(boot_delay)
        self.alarm_delay = float(alarm_delay)
        self.hold_decel = float(hold_decel)
        self.latency_s = float(latency_s)
        self.startup_blocks = [str(b) for b in startup_blocks]
        self._homing_lock = homing_lock
        self._faults: list[Fault] = [Fault.from_config(f) for f in faults or ()]

        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        self._pty: PtyEnd | None = None
        self._tcp: TcpLink | None = None

        self._received: list[str] = []
        self._realtime_received: list[str] = []
        self._rx = bytearray()
        self._lines: deque[str] = deque()
        self._status_mask = 1  # $10
        self._wco = (0.0, 0.0, 0.0)  # G54 offset (G10 L2 P1), kept like EEPROM data
        self._position = (0.0, 0.0, 0.0)
        self._power_up()

    # ---------------------------------------------------------------- public API

    def start_pty(self) -> str:
        """Serve on a new pseudo-terminal and return the path to give the driver.

        The path is a symlink in a private temporary directory that always points at the
        current pty (see the ``disconnect`` fault); the real device is :attr:`pty_device`.
        """
        with self._lock:
            if self._pty is None:
                on_open = self._port_opened if self.reset_on_open else None
                self._pty = PtyEnd("ttyGRBL", on_open, self.latency_s)
                if not self.reset_on_open:
                    self._boot_messages = []  # printed before anyone listened
            path = self._pty.link_path
        self._start_thread()
        return path

    def start_tcp(self, port: int = 0) -> str:
        """Listen on 127.0.0.1 (``port=0`` picks a free port) and return ``socket://127.0.0.1:PORT``."""
        with self._lock:
            if self._tcp is None:
                self._tcp = TcpLink(port)
                self._boot_messages = []  # printed before anyone listened
            url = f"socket://127.0.0.1:{self._tcp.port}"
        self._start_thread()
        return url

    def stop(self) -> None:
        """Stop the thread and close every link (idempotent)."""
        self._stopping.set()
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        with self._lock:
            pty, self._pty = self._pty, None
            if self._tcp is not None:
                self._tcp.close()
                self._tcp = None
        if pty is not None:
            pty.close()  # outside the lock: the relay thread may be in _port_opened
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._wake_r = self._wake_w = -1

    def __enter__(self) -> SimulatedGantry:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def inject(self, fault: str, **options: object) -> None:
        """Arm a fault, e.g. ``inject("delay", seconds=0.3)`` (see the module docstring).

        Raises
        ------
        ValueError
            For an unknown fault kind or option.
        """
        armed = Fault.from_config({"fault": fault, **options})
        with self._lock:
            self._faults.append(armed)

    def clear_faults(self) -> None:
        """Disarm every fault not yet used."""
        with self._lock:
            self._faults.clear()

    @property
    def faults(self) -> list[Fault]:
        """Faults still armed."""
        with self._lock:
            return list(self._faults)

    @property
    def pty_device(self) -> str | None:
        """The current ``/dev/pts/N`` behind :meth:`start_pty`'s path (``None`` without pty)."""
        with self._lock:
            return self._pty.device if self._pty else None

    @property
    def received(self) -> list[str]:
        """Every line received so far (real-time bytes excluded), as sent."""
        with self._lock:
            return list(self._received)

    @property
    def realtime_received(self) -> list[str]:
        """Every real-time command received: ``"?"``, ``"!"``, ``"~"`` or ``"^X"``."""
        with self._lock:
            return list(self._realtime_received)

    @property
    def position(self) -> tuple[float, float, float]:
        """Where the head really is, machine coordinates in mm (interpolated during a move).

        The same as :attr:`reported_position` unless a ``lost_steps`` fault struck.
        """
        with self._lock:
            self._advance(time.monotonic())
            slip = self._slip
            if self._planner:
                block = self._planner[0]
                done = block.progress()
                slip = tuple(s + done * b for s, b in zip(slip, block.slip, strict=True))
            return tuple(p + s for p, s in zip(self._current_position(), slip, strict=True))  # type: ignore[return-value]

    @property
    def reported_position(self) -> tuple[float, float, float]:
        """The machine position the controller believes and reports (``MPos``), in mm."""
        with self._lock:
            self._advance(time.monotonic())
            return self._current_position()

    @property
    def state(self) -> str:
        """Machine state as a status report shows it (``"Idle"``, ``"Hold:0"``, ...)."""
        with self._lock:
            self._advance(time.monotonic())
            return self._state_text()

    @property
    def tool_on(self) -> bool:
        """Whether the flood-coolant output (``M8``, the pick tool by default) is on."""
        with self._lock:
            return self._flood

    @property
    def homed(self) -> bool:
        """Whether a homing cycle has completed since start-up."""
        with self._lock:
            return self._homed

    @property
    def home_position(self) -> tuple[float, float, float]:
        """Where homing ends: 0 with ``HOMING_FORCE_SET_ORIGIN``, else ``-homing_pulloff``."""
        if self.force_origin:
            return (0.0, 0.0, 0.0)
        return (-self.homing_pulloff,) * 3  # type: ignore[return-value]

    # ---------------------------------------------------------------- machine state

    def _power_up(self) -> None:
        self._slip: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._state = "Alarm" if self._homing_lock else "Idle"
        self._homed = False
        self._reset_modal()
        self._planner: deque[_Move] = deque()
        self._pending: _Pending | None = None
        self._lockout: str | None = None  # "critical" (only Ctrl-X) or "sleep"
        self._last_tick = time.monotonic()
        self._stall_until = 0.0  # deaf after an alarm report until then
        self._after_stall: Callable[[], None] | None = None
        self._boot_until = 0.0
        self._hold_settles = 0.0
        self._status_deferred = False
        self._wco_counter = self._ovr_counter = 0
        self._boot_messages = self._banner() + self._run_startup_blocks()

    def _port_opened(self) -> None:
        """A host opened the pty: restart like an Arduino whose DTR line pulses."""
        with self._lock:
            self._rx.clear()
            self._lines.clear()
            self._position = (0.0, 0.0, 0.0)
            self._power_up()
            self._boot_until = time.monotonic() + self.boot_delay
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def _reset_modal(self) -> None:
        self._motion_mode = 0
        self._inches = False
        self._relative = False
        self._feed = 0.0
        self._spindle_speed = 0.0
        self._spindle = "off"  # "cw", "ccw"
        self._flood = False
        self._mist = False

    def _banner(self) -> list[str]:
        lines = ["", f"Grbl {self.firmware} ['$' for help]"]
        if self._state == "Alarm":
            lines.append("[MSG:'$H'|'$X' to unlock]")
        return lines

    def _run_startup_blocks(self) -> list[str]:
        if self._state == "Alarm":
            return []
        results = []
        for block in self.startup_blocks:
            pending = self._execute(block)
            answer = pending.replies[0] if pending.replies else "ok"
            results.append(f">{block}:{answer}")
        return results

    def _current_position(self) -> tuple[float, float, float]:
        if self._planner:
            block = self._planner[0]
            return block.point(block.elapsed)
        return self._position

    def _planned_end(self) -> tuple[float, float, float]:
        return self._planner[-1].end if self._planner else self._position

    def _state_text(self) -> str:
        if self._state == "Hold":
            return "Hold:1" if time.monotonic() < self._hold_settles else "Hold:0"
        return self._state

    def _status_report(self) -> str:
        x, y, z = self._current_position()
        busy = self._state in _BUSY_STATES
        moving = self._state in ("Run", "Home") and bool(self._planner)
        feed = self._planner[0].feed if moving else 0.0
        if self._status_mask & 1:
            report = f"<{self._state_text()}|MPos:{x:.3f},{y:.3f},{z:.3f}"
        else:
            wx, wy, wz = (p - o for p, o in zip((x, y, z), self._wco, strict=True))
            report = f"<{self._state_text()}|WPos:{wx:.3f},{wy:.3f},{wz:.3f}"
        if self._status_mask & 2:
            report += f"|Bf:{15 - len(self._planner)},128"
        report += f"|FS:{feed:.0f},"
        report += f"{self._spindle_speed if self._spindle != 'off' else 0:.0f}"
        if self._wco_counter > 0:
            self._wco_counter -= 1
        else:
            self._wco_counter = _WCO_REFRESH[busy] - 1
            if self._ovr_counter == 0:
                self._ovr_counter = 1
            report += "|WCO:" + ",".join(f"{v:.3f}" for v in self._wco)
        if self._ovr_counter > 0:
            self._ovr_counter -= 1
        else:
            self._ovr_counter = _OVR_REFRESH[busy] - 1
            report += "|Ov:100,100,100"
            accessories = (
                {"cw": "S", "ccw": "C"}.get(self._spindle, "")
                + ("F" if self._flood else "")
                + ("M" if self._mist else "")
            )
            if accessories:
                report += f"|A:{accessories}"
        return report + ">"

    def _advance(self, now: float) -> None:
        """Run the planner up to ``now``, emitting the alarm of an injected fault if it strikes."""
        dt = now - self._last_tick
        self._last_tick = now
        if self._state not in ("Run", "Home"):
            return
        while dt > 0 and self._planner:
            block = self._planner[0]
            if block.alarm_at is not None:
                strike = block.alarm_at * block.duration
                if block.elapsed + dt >= strike:
                    block.elapsed = strike
                    self._alarm(block.alarm_code, now)
                    return
            remaining = block.duration - block.elapsed
            if dt >= remaining:
                dt -= remaining
                self._position = block.end
                self._add_slip(block.slip)
                self._planner.popleft()
            else:
                block.elapsed += dt
                dt = 0.0
        if not self._planner:
            self._state = "Idle"

    def _add_slip(self, slip: tuple[float, float, float], share: float = 1.0) -> None:
        self._slip = tuple(s + share * b for s, b in zip(self._slip, slip, strict=True))  # type: ignore[assignment]

    def _drop_planner(self) -> None:
        """Clear the planner where it is, keeping the share of lost travel already lost."""
        if self._planner:
            block = self._planner[0]
            self._add_slip(block.slip, block.progress())
        self._planner.clear()

    def _alarm(self, code: int, now: float) -> None:
        """Stop everything where it is, print ``ALARM:code`` and stay deaf ``alarm_delay``.

        A line awaiting its answer keeps waiting (the next reset answers it ``ok``). After a
        critical alarm the controller then prints ``[MSG:Reset to continue]`` and locks.
        """
        self._position = self._current_position()
        self._drop_planner()
        if self._pending is not None:
            self._pending.held = True
        self._lines.clear()
        self._spindle, self._flood, self._mist = "off", False, False
        self._state = "Alarm"
        self._status_deferred = False
        self._emit([f"ALARM:{code}"])
        self._stall_until = now + self.alarm_delay
        if code in CRITICAL_ALARMS:
            self._lockout = "critical"

            def report_critical() -> None:
                self._emit(["[MSG:Reset to continue]"])

            self._after_stall = report_critical

    def _soft_reset(self, now: float) -> None:
        """Ctrl-X: alarm if moving (then deaf ``alarm_delay``), answer a held line, banner."""
        if self._state in ("Run", "Home") or (self._state == "Hold" and self._planner):
            self._alarm(6 if self._state == "Home" else 3, now)
            self._after_stall = self._finish_reset
            return
        self._finish_reset()

    def _finish_reset(self) -> None:
        messages = ["ok"] if self._pending is not None and not self._pending.garbled else []
        self._position = self._current_position()
        self._drop_planner()
        self._pending = None
        self._lines.clear()
        self._rx.clear()
        self._lockout = None
        self._status_deferred = False
        self._wco_counter = self._ovr_counter = 0
        if self._state == "Sleep":
            self._state = "Alarm"
        elif self._state != "Alarm":
            self._state = "Idle"
        self._reset_modal()
        self._emit(messages + self._banner() + self._run_startup_blocks())

    # ---------------------------------------------------------------- faults

    def _lost_steps(
        self, start: tuple[float, ...], target: tuple[float, ...]
    ) -> tuple[float, float, float]:
        """The travel a move loses to an armed ``lost_steps`` fault on an axis it moves."""
        for fault in self._faults:
            if fault.kind != "lost_steps":
                continue
            axis = "xyz".index(fault.axis)
            travel = target[axis] - start[axis]
            if travel == 0:
                continue
            self._take_fault_object(fault)
            slip = [0.0, 0.0, 0.0]
            slip[axis] = -math.copysign(min(fault.mm, abs(travel)), travel)
            return tuple(slip)  # type: ignore[return-value]
        return (0.0, 0.0, 0.0)

    def _take_fault_object(self, fault: Fault) -> None:
        fault.count -= 1
        if fault.count == 0:
            self._faults.remove(fault)

    def _take_fault(self, kind: str) -> Fault | None:
        for fault in self._faults:
            if fault.kind == kind:
                if kind in ("alarm_mid_move", "disconnect", "restart"):
                    self._faults.remove(fault)
                else:
                    self._take_fault_object(fault)
                return fault
        return None

    # ---------------------------------------------------------------- line execution

    def _accept_line(self, raw: str) -> _Pending | None:
        """Execute one received line; return its (maybe deferred) answer, or None for none."""
        if self._take_fault("no_reply"):
            return None
        delay = self._take_fault("delay")
        garbled = self._take_fault("garbled") is not None
        pending = self._execute(raw)
        pending.garbled = garbled
        if delay is not None:
            pending.extra_delay = delay.seconds
        return pending

    def _execute(self, raw: str) -> _Pending:
        line = strip_comments(raw).replace(" ", "").upper()
        if len(raw) > 79:
            return _Pending(["error:11"])
        if not line:
            return _Pending()
        if line.startswith("$"):
            return self._system_command(line)
        if self._state in ("Alarm", "Jog"):
            return _Pending(["error:9"])
        try:
            return self._gcode(line)
        except GcodeError as exc:
            return _Pending([f"error:{exc.code}"])

    def _system_command(self, line: str) -> _Pending:
        command = line[1:]
        if command == "":
            return _Pending(
                ["[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]", "ok"]
            )
        if command == "G":
            return _Pending([self._parser_state(), "ok"])
        if command == "X":
            if self._state == "Alarm":
                self._state = "Idle"
                return _Pending(["[MSG:Caution: Unlocked]", "ok"])
            return _Pending()
        if command == "C":
            if self._state == "Check":
                self._state = "Idle"
                return _Pending(["[MSG:Disabled]", "ok", *self._reset_lines()])
            if self._state != "Idle":
                return _Pending(["error:8"])
            self._state = "Check"
            return _Pending(["[MSG:Enabled]", "ok"])
        if self._state not in ("Idle", "Alarm"):
            return _Pending(["error:8"])
        if command == "$":
            return _Pending([*self._settings(), "ok"])
        if command == "I":
            codes = "VZ" if self.force_origin else "V"
            return _Pending(
                [f"[VER:{self.firmware}.{_BUILD_DATE}:]", f"[OPT:{codes},15,128]", "ok"]
            )
        if command == "H":
            return self._start_homing()
        if command == "SLP":
            self._state = "Sleep"
            self._lockout = "sleep"
            self._spindle, self._flood, self._mist = "off", False, False
            return _Pending(["ok", "[MSG:Sleeping]"])
        setting = re.fullmatch(r"(\d+)=([-+]?\d*\.?\d*)", command)
        if setting:
            if setting.group(1) == "10":
                self._status_mask = int(float(setting.group(2) or 0))
            return _Pending()
        return _Pending(["error:3"])

    def _reset_lines(self) -> list[str]:
        """Leaving check mode resets GRBL: the banner follows the ``ok``."""
        self._planner.clear()
        self._reset_modal()
        return self._banner()

    def _settings(self) -> list[str]:
        (x0, x1), (y0, y1), (z0, z1) = self.limits.x, self.limits.y, self.limits.z
        return [
            f"$10={self._status_mask}", "$20=1", "$21=0", "$22=1",
            f"$23={self.homing_dir_mask}", f"$27={self.homing_pulloff:.3f}",
            f"$110={self.rapid_feed:.3f}", f"$111={self.rapid_feed:.3f}",
            f"$112={self.rapid_feed:.3f}",
            f"$130={x1 - x0:.3f}", f"$131={y1 - y0:.3f}", f"$132={z1 - z0:.3f}",
        ]  # fmt: skip

    def _parser_state(self) -> str:
        spindle = {"off": "M5", "cw": "M3", "ccw": "M4"}[self._spindle]
        coolant = " ".join(c for c, on in (("M7", self._mist), ("M8", self._flood)) if on)
        return (
            f"[GC:G{self._motion_mode} G54 G17 {'G20' if self._inches else 'G21'} "
            f"{'G91' if self._relative else 'G90'} G94 {spindle} {coolant or 'M9'} T0 "
            f"F{self._feed:g} S{self._spindle_speed:g}]"
        )

    def _start_homing(self) -> _Pending:
        start = self._current_position()
        home = self.home_position
        distance = math.dist(start, home)
        duration = distance / self.homing_feed * 60.0 / self.speed_factor
        self._planner.append(_Move(start, home, self.homing_feed, duration, homing=True))
        self._state = "Home"
        self._last_tick = time.monotonic()

        def finish() -> list[str]:
            # GRBL answers the ? that came during homing still in Home, then runs the
            # start-up blocks, then says ok.
            self._state = "Home"
            replies = []
            if self._status_deferred:
                self._status_deferred = False
                replies.append(self._status_report())
            self._homed = True
            self._slip = (0.0, 0.0, 0.0)  # the switches give the real position back
            self._state = "Idle"
            return [*replies, *self._run_startup_blocks(), "ok"]

        return _Pending(replies=[], wait_planner=True, then=finish)

    def _gcode(self, line: str) -> _Pending:
        words = parse_words(line)
        g_codes = [value for letter, value in words if letter == "G"]
        m_codes = [value for letter, value in words if letter == "M"]
        values: dict[str, float] = {}
        for letter, value in words:
            if letter in "GMN":
                continue
            if letter not in "XYZFPSTL":
                raise GcodeError(20)
            if letter in values:
                raise GcodeError(25)
            values[letter] = value

        motion_mode, machine_coords, dwell = self._motion_mode, False, None
        inches, relative, set_offset = self._inches, self._relative, False
        groups_seen: set[str] = set()
        for code in g_codes:
            group = G_GROUPS.get(code)
            if group is None:
                raise GcodeError(20)
            if group in groups_seen and group != "nonmodal":
                raise GcodeError(21)
            groups_seen.add(group)
            if code in (0, 1, 80):
                motion_mode = int(code)
            elif code == 4:
                dwell = values.get("P")
                if dwell is None:
                    raise GcodeError(28)
                if dwell < 0:
                    raise GcodeError(4)
            elif code == 10:
                if values.get("L") != 2 or values.get("P") not in (0, 1):
                    raise GcodeError(20)  # only G10 L2 P0/P1 (the G54 offset) is simulated
                set_offset = True
            elif code in (20, 21):
                inches = code == 20
            elif code in (90, 91):
                relative = code == 91
            elif code == 53:
                machine_coords = True
        for code in m_codes:
            if code not in (3, 4, 5, 7, 8, 9):
                raise GcodeError(20)
        if "L" in values and not set_offset:
            raise GcodeError(36)

        axes = {a: values[a] for a in "XYZ" if a in values}
        scale = 25.4 if inches else 1.0
        if set_offset:
            if not axes:
                raise GcodeError(26)
            self._wco = tuple(  # type: ignore[assignment]
                axes[a] * scale if a in axes else self._wco[i] for i, a in enumerate("XYZ")
            )
            self._wco_counter = 0  # GRBL reports a changed offset in the next report
            return _Pending(wait_planner=True)
        if machine_coords and motion_mode not in (0, 1):
            raise GcodeError(30)
        if axes and (motion_mode == 80 or dwell is not None):
            raise GcodeError(31)
        feed = values["F"] * scale if "F" in values else self._feed
        if "F" in values and values["F"] <= 0:
            raise GcodeError(4)
        if axes and motion_mode == 1 and feed <= 0:
            raise GcodeError(22)

        target = None
        if axes:
            origin = self._planned_end()
            target = tuple(
                (
                    origin[i] + axes[a] * scale
                    if relative and not machine_coords
                    else axes[a] * scale + (0.0 if machine_coords else self._wco[i])
                )
                if a in axes
                else origin[i]
                for i, a in enumerate("XYZ")
            )

        # Every check passed: commit the modal state (GRBL never half-executes a block).
        self._motion_mode, self._inches, self._relative, self._feed = (
            motion_mode, inches, relative, feed
        )  # fmt: skip
        if "S" in values:
            self._spindle_speed = values["S"]
        if target is not None and not self.limits.contains(*target):
            # Soft limit: nothing of the block runs, a critical alarm; "ok" comes at the reset.
            self._alarm(2, time.monotonic())
            return _Pending(held=True)
        outputs = self._output_changes(m_codes)
        if self._state == "Check":
            return _Pending()
        if outputs is None and dwell is None:
            if target is not None:
                self._queue_move(target, motion_mode, feed)
            return _Pending()

        def synchronised() -> None:
            if outputs is not None:
                outputs()
            if target is not None:
                self._queue_move(target, motion_mode, feed)

        return _Pending(
            wait_planner=True, dwell=(dwell or 0.0) / self.speed_factor, then=synchronised
        )

    def _output_changes(self, m_codes: list[float]) -> Callable[[], None] | None:
        if not m_codes:
            return None

        def apply() -> None:
            self._ovr_counter = 0  # GRBL reports an output change in the next status report
            for code in m_codes:
                if code in (3, 4):
                    self._spindle = "cw" if code == 3 else "ccw"
                elif code == 5:
                    self._spindle = "off"
                elif code == 7:
                    self._mist = True
                elif code == 8:
                    self._flood = True
                elif code == 9:
                    self._flood = self._mist = False

        return apply

    def _queue_move(self, target: tuple[float, ...], motion_mode: int, feed: float) -> None:
        start = self._planned_end()
        rate = self.rapid_feed if motion_mode == 0 else feed
        duration = math.dist(start, target) / rate * 60.0 / self.speed_factor
        move = _Move(start, target, rate, duration)  # type: ignore[arg-type]
        fault = self._take_fault("alarm_mid_move") if duration > 0 else None
        if fault is not None:
            move.alarm_at, move.alarm_code = fault.fraction, fault.code
        move.slip = self._lost_steps(start, target)
        if not self._planner and self._state == "Idle":
            self._last_tick = time.monotonic()
            self._state = "Run"
        self._planner.append(move)

    # ---------------------------------------------------------------- I/O loop

    def _start_thread(self) -> None:
        if self._thread is None:
            self._stopping.clear()
            self._thread = threading.Thread(target=self._run, name="labauto-grbl-sim", daemon=True)
            self._thread.start()
        else:
            with contextlib.suppress(OSError):
                os.write(self._wake_w, b"x")

    def _links(self) -> list[PtyEnd | TcpLink]:
        return [link for link in (self._pty, self._tcp) if link is not None]

    def _emit(self, lines: Iterable[str], raw: bytes | None = None) -> None:
        data = raw if raw is not None else b"".join(f"{x}\r\n".encode() for x in lines)
        if data:
            for link in self._links():
                link.write(data)

    def _power_on_messages(self) -> None:
        """Print the start-up banner once the board has booted (``reset_on_open``)."""
        if self._boot_messages:
            self._emit(self._boot_messages)
            self._boot_messages = []

    def _run(self) -> None:
        while not self._stopping.is_set():
            with self._lock:
                busy = self._service(time.monotonic())
                owners = {fd: link for link in self._links() for fd in link.fds()}
            readable, _, _ = select.select(
                [self._wake_r, *owners], [], [], _BUSY_POLL_S if busy else _IDLE_POLL_S
            )
            with self._lock:
                for fd in readable:
                    if fd == self._wake_r:
                        with contextlib.suppress(OSError):
                            os.read(self._wake_r, 64)
                        continue
                    link = owners[fd]
                    if link not in self._links():
                        continue
                    data = link.read(fd)
                    if data is None:
                        self._rx.clear()
                        self._lines.clear()
                    elif data:
                        self._receive(data)

    def _receive(self, data: bytes) -> None:
        now = time.monotonic()
        if now < self._boot_until:
            return  # the board is still booting: the bootloader eats what it is sent
        for byte in data:
            if byte in _REALTIME:
                self._realtime(byte, now)
            elif byte >= 0x80:
                continue  # extended real-time commands (overrides): ignored
            elif byte in (0x0A, 0x0D):
                line = self._rx.decode("ascii", errors="replace")
                self._rx.clear()
                self._received.append(line)
                if self._take_fault("disconnect"):
                    self._disconnect()
                    return
                if self._take_fault("restart"):
                    self._rx.clear()
                    self._lines.clear()
                    self._position = (0.0, 0.0, 0.0)
                    self._power_up()
                    self._power_on_messages()
                    return
                if self._lockout is None:
                    self._lines.append(line)
            else:
                self._rx.append(byte)

    def _disconnect(self) -> None:
        self._rx.clear()
        self._lines.clear()
        if self._pty is not None:
            self._pty.drop()
        if self._tcp is not None:
            self._tcp.drop()

    def _realtime(self, byte: int, now: float) -> None:
        self._advance(now)
        self._realtime_received.append("^X" if byte == 0x18 else chr(byte))
        if now < self._stall_until:
            return  # deaf while the alarm report delay runs: the byte is lost
        if byte == 0x18:
            self._soft_reset(now)
        elif self._lockout == "critical":
            return
        elif byte == ord("?"):
            if self._state == "Home":
                self._status_deferred = True
            else:
                self._emit([self._status_report()])
        elif byte == ord("!"):
            if self._state == "Run":
                self._position = self._current_position()
                self._state = "Hold"
                self._hold_settles = now + self.hold_decel / self.speed_factor
            elif self._state == "Idle":
                self._state = "Hold"
                self._hold_settles = now
        elif byte == ord("~") and self._state == "Hold":
            self._state = "Run" if self._planner else "Idle"
            self._last_tick = now

    def _service(self, now: float) -> bool:
        """Advance time, finish waiting answers, execute queued lines; return True if busy."""
        if self._boot_until:
            if now < self._boot_until:
                return True
            self._boot_until = 0.0
            self._power_on_messages()
        if self._stall_until:
            if now < self._stall_until:
                return True
            self._stall_until = 0.0
            then, self._after_stall = self._after_stall, None
            if then is not None:
                then()
        self._advance(now)
        while True:
            if self._pending is not None:
                if not self._pending_ready(now):
                    return True
                pending, self._pending = self._pending, None
                extra = pending.then() if pending.then else None
                replies = pending.replies + (extra or [])
                if pending.garbled:
                    self._emit([], raw=GARBLED_REPLY + b"\r\n")
                else:
                    self._emit(replies)
            if not self._lines or self._lockout is not None or self._stall_until:
                return bool(self._planner) or bool(self._stall_until)
            self._pending = self._accept_line(self._lines.popleft())
            self._advance(now)

    def _pending_ready(self, now: float) -> bool:
        pending = self._pending
        assert pending is not None
        if pending.held:
            return False
        if pending.wait_planner:
            if self._planner or self._state in ("Hold", "Alarm"):
                return False
            pending.wait_planner = False
            pending.not_before = now + pending.dwell
            pending.dwell = 0.0
        if now < pending.not_before:
            return False
        if pending.extra_delay > 0:
            pending.not_before = now + pending.extra_delay
            pending.extra_delay = 0.0
            return False
        return True


def _interrupt(signum: int, frame: object) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # once is enough: let the clean-up run
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> None:
    """Serve a simulated gantry on a pty (and optionally TCP) until Ctrl-C."""
    parser = argparse.ArgumentParser(description="Simulated GRBL 1.1 gantry for labauto.")
    parser.add_argument("--speed-factor", type=float, default=1.0)
    parser.add_argument("--tcp", type=int, default=None, metavar="PORT", help="also serve TCP")
    parser.add_argument("--no-homing-lock", action="store_true", help="start Idle, not Alarm")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, _interrupt)  # clean up the pty link on `kill` as on Ctrl-C
    with SimulatedGantry(
        speed_factor=args.speed_factor, homing_lock=not args.no_homing_lock
    ) as sim:
        print(f"pty: {sim.start_pty()} -> {sim.pty_device}", flush=True)
        if args.tcp is not None:
            print(f"tcp: {sim.start_tcp(args.tcp)}", flush=True)
        with contextlib.suppress(KeyboardInterrupt):
            while True:
                time.sleep(3600)


if __name__ == "__main__":
    main()
