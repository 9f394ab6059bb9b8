"""The real GRBL 1.1h firmware (grbl-sim, built for the host) behind a pseudo-terminal of ours.

grbl-sim compiles GRBL's own sources for Linux; it reads the serial byte stream on stdin and
writes its replies on stdout. :class:`FirmwareBridge` runs it on the server end of a
:class:`labauto.drivers.pty_link.PtyLink`, so the driver opens an ordinary tty path, as it would
open ``/dev/ttyUSB0``. Like a USB-serial adapter in front of an Arduino it can restart the
firmware whenever the port is opened (the DTR reset: the banner then comes about a second
later, as grbl-sim waits one simulated second before reading its input) and deliver the
firmware's output in batches (``latency_s``, an FTDI latency timer).

:func:`build_grbl_sim` compiles the firmware from ``../shared/firmware`` in a scratch folder
(gcc and make only), and :func:`make_eeprom` runs it once to store the settings the tests use,
so every start begins from the same EEPROM. Nothing of the firmware is copied into labauto.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import signal
import subprocess
import tempfile
import termios
import threading
import time
from pathlib import Path
from types import TracebackType

from labauto.drivers.pty_link import PtyLink

#: The firmware's source tree next to the repository (a read-only copy in CI).
FIRMWARE_DIR = Path(__file__).resolve().parents[2].parent / "shared" / "firmware" / "grbl"

#: Settings stored in the EEPROM every firmware start begins with: homing and soft limits on
#: (so the machine space is enforced, and the homing lock holds at power-up), a 200 x 200 x 50 mm
#: machine, and rates and accelerations high enough for quick tests.
TEST_SETTINGS = {  # in this order: soft limits ($20) need homing ($22) first
    10: "1",
    22: "1",
    20: "1",
    27: "1.000",
    110: "6000.000",
    111: "6000.000",
    112: "6000.000",
    120: "800.000",
    121: "800.000",
    122: "800.000",
    130: "200.000",
    131: "200.000",
    132: "50.000",
}
_COMMAND = ["stdbuf", "-i0", "-o0"]
#: Compiler flags of the build (see :func:`build_grbl_sim` for why unoptimised).
BUILD_FLAGS = "-g -O0 -fcommon"
_SIM_OPTIONS = ["-n", "-b", "/dev/null", "-s", "/dev/null"]


def source_digest(source: Path) -> str:
    """A short hash of the firmware sources (every .c/.h/Makefile) and the build flags."""
    digest = hashlib.sha256(BUILD_FLAGS.encode())
    for path in sorted(source.rglob("*")):
        if path.is_file() and (path.suffix in (".c", ".h") or path.name == "Makefile"):
            digest.update(str(path.relative_to(source)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def build_grbl_sim(source: Path, scratch: Path) -> Path:
    """Copy ``source`` into ``scratch`` and compile grbl-sim there; return the executable.

    An executable already built in ``scratch`` is reused.

    Raises
    ------
    RuntimeError
        With the compiler's output when the build fails.
    """
    tree = scratch / "grbl"
    exe = tree / "grbl" / "grbl-sim" / "grbl_sim.exe"
    if exe.is_file():
        return exe
    if tree.exists():
        shutil.rmtree(tree)
    shutil.copytree(source, tree)
    for path in tree.rglob("*"):  # the source may be a read-only copy
        path.chmod(path.stat().st_mode | 0o200)
    jobs = str(min(2, os.cpu_count() or 1))
    # -O0: grbl-sim runs GRBL's serial interrupt in a second host thread, and with -O2 the
    # compiler may store a byte into the transmit ring after publishing its index, so the
    # "interrupt" sends a stale byte (seen: "FS:0,02Pn:" for "FS:0,0|Pn:", about 1 report in
    # 1,000 under load). Unoptimised it builds in ~4 s instead of ~18 s and showed none.
    result = subprocess.run(
        ["make", "-j", jobs, "main", f"FLAGS={BUILD_FLAGS}"],
        cwd=tree / "grbl" / "grbl-sim",
        capture_output=True,
        text=True,
        check=False,
    )
    if result.returncode != 0 or not exe.is_file():
        raise RuntimeError(f"building grbl-sim failed:\n{result.stdout}\n{result.stderr}")
    return exe


def make_eeprom(exe: Path, folder: Path, settings: dict[int, str] = TEST_SETTINGS) -> Path:
    """Run the firmware once in ``folder`` to store ``settings``; return its ``EEPROM.DAT``.

    The firmware writes its EEPROM file for sure only on a clean exit (end of its input), so
    it is sent the settings one by one, each awaited, and then its stdin is closed.
    """
    folder.mkdir(parents=True, exist_ok=True)
    process = subprocess.Popen(
        [*_COMMAND, str(exe), *_SIM_OPTIONS],
        cwd=folder,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
    )
    assert process.stdin is not None and process.stdout is not None
    answers: list[str] = []
    try:
        _read_until(process, answers, "Grbl 1.1")
        for number, value in settings.items():
            process.stdin.write(f"${number}={value}\n".encode())
            process.stdin.flush()
            _read_until(process, answers, "ok")
        process.stdin.close()
        process.wait(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    eeprom = folder / "EEPROM.DAT"
    if not eeprom.is_file():
        raise RuntimeError(f"storing the test settings failed: {answers!r}")
    return eeprom


def _read_until(process: subprocess.Popen[bytes], answers: list[str], wanted: str) -> None:
    """Read the firmware's output lines until one starts with ``wanted`` (30 s at most)."""
    assert process.stdout is not None
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        line = process.stdout.readline().decode(errors="replace").strip()
        if not line and process.poll() is not None:
            break
        if line:
            answers.append(line)
        if line.startswith("error:") and wanted == "ok":
            raise RuntimeError(f"the firmware refused a test setting: {answers!r}")
        if line.startswith(wanted):
            return
    raise RuntimeError(f"no {wanted!r} from the firmware: {answers!r}")


class FirmwareBridge:
    """Serve the firmware on a pty path; restart it on open if asked.

    Parameters
    ----------
    exe
        The grbl-sim executable.
    eeprom
        EEPROM file every start copies (the firmware's settings).
    restart_on_open
        Restart the firmware each time a client opens the port (an Arduino's DTR reset);
        otherwise it is started once and keeps running across opens.
    latency_s
        Deliver the firmware's output in batches this far apart.
    """

    def __init__(
        self, exe: Path, eeprom: Path, *, restart_on_open: bool = False, latency_s: float = 0.0
    ) -> None:
        self.exe = exe
        self.eeprom = eeprom
        self.restart_on_open = restart_on_open
        self.latency_s = latency_s
        self.starts = 0
        self._folder = Path(tempfile.mkdtemp(prefix="labauto-grbl-fw-"))
        self._link = PtyLink(
            "ttyGRBL",
            on_client_open=self.restart if restart_on_open else None,
            latency_s=latency_s,
        )
        self._tty = -1
        self._process: subprocess.Popen[bytes] | None = None
        self._lock = threading.Lock()

    @property
    def path(self) -> str:
        """The tty path to give the driver."""
        return self._link.client_path

    def start(self) -> str:
        """Open the pty pair and (unless it starts on open) start the firmware; return the path."""
        _, server = self._link.open()
        self._tty = os.open(server, os.O_RDWR | os.O_NOCTTY)
        if not self.restart_on_open:
            self.restart()
        return self.path

    def restart(self) -> None:
        """Kill the firmware (if running) and start it again from the EEPROM file: a power cycle."""
        with self._lock:
            self._kill()
            with contextlib.suppress(termios.error):
                termios.tcflush(self._tty, termios.TCIOFLUSH)  # nothing of the old run is left
            shutil.copyfile(self.eeprom, self._folder / "EEPROM.DAT")
            self._process = subprocess.Popen(
                [*_COMMAND, str(self.exe), *_SIM_OPTIONS],
                cwd=self._folder,
                stdin=self._tty,
                stdout=self._tty,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
            self.starts += 1

    def alive(self) -> bool:
        """Whether the firmware process is running."""
        return self._process is not None and self._process.poll() is None

    def stop(self) -> None:
        """Stop the firmware and the relay, remove the scratch folder (idempotent)."""
        with self._lock:
            self._kill()
        self._link.close()
        if self._tty >= 0:
            with contextlib.suppress(OSError):
                os.close(self._tty)
            self._tty = -1
        shutil.rmtree(self._folder, ignore_errors=True)

    def _kill(self) -> None:
        process, self._process = self._process, None
        if process is None or process.poll() is not None:
            return
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=5)

    def __enter__(self) -> FirmwareBridge:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.stop()


def wait_until(predicate: object, timeout: float, interval: float = 0.01) -> bool:
    """Poll ``predicate()`` until it is true or ``timeout`` seconds passed."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():  # type: ignore[operator]
            return True
        time.sleep(interval)
    return bool(predicate())  # type: ignore[operator]
