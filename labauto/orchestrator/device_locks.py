"""One owner per device: an advisory lock per real device, held while a run uses it.

Two runs configured for the same serial port (or the same Modbus server) must not both drive
it. Before a run opens its devices it takes an exclusive ``flock`` on a lock file named after
each real device (a serial port by its resolved path, a TCP analyzer by host and port) in the
lock folder (``run.lock_dir``, default ``<tmp>/labauto-locks``), and writes who holds it into
the file. The operating system releases the lock when the process ends, however it ends, so a
killed run never leaves a device locked. Simulated devices are not locked: each run starts its
own.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import tempfile
from collections.abc import Iterator
from pathlib import Path

from labauto.config import Config
from labauto.errors import RunError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no advisory locks
    fcntl = None  # type: ignore[assignment]


def device_keys(config: Config) -> list[tuple[str, str]]:
    """``(device, key)`` of every real device of a config, e.g. ``("robot", "/dev/ttyUSB0")``."""
    keys = []
    if not config.robot.simulate:
        keys.append(("robot", _port_key(config.robot.port)))
    analyzer = config.analyzer
    if not analyzer.simulate:
        if analyzer.transport == "tcp":
            keys.append(("analyzer", f"tcp://{analyzer.host}:{analyzer.port}"))
        else:
            keys.append(("analyzer", _port_key(analyzer.serial_port)))
    return keys


def _port_key(port: str) -> str:
    """A serial port by its resolved path (two names of one device are one key)."""
    if "://" in port:
        return port
    return os.path.realpath(port)


def lock_dir(config: Config) -> Path:
    return Path(config.run.lock_dir or Path(tempfile.gettempdir()) / "labauto-locks")


def _lock_file(folder: Path, key: str) -> Path:
    readable = "".join(c if c.isalnum() else "_" for c in key).strip("_")[-60:]
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    return folder / f"{readable}-{digest}.lock"


@contextlib.contextmanager
def device_locks(config: Config, run_label: str) -> Iterator[list[Path]]:
    """Hold the lock of every real device of ``config`` for the ``with`` block.

    Raises
    ------
    RunError
        A device is locked by another process (the message names the device, its port and
        the holder), or the lock folder cannot be used.
    """
    keys = device_keys(config)
    if not keys or fcntl is None:
        yield []
        return
    folder = lock_dir(config)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunError(f"{folder}: cannot create the device lock folder ({exc.strerror})") from None
    held: list[tuple[int, Path]] = []
    try:
        for device, key in keys:
            path = _lock_file(folder, key)
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _holder(fd)
                os.close(fd)
                raise RunError(
                    f"{device} {key} is in use by {holder}: one device, one run at a time"
                ) from None
            os.ftruncate(fd, 0)
            os.write(
                fd,
                json.dumps(
                    {"pid": os.getpid(), "host": socket.gethostname(), "run": run_label}
                ).encode(),
            )
            held.append((fd, path))
        yield [path for _, path in held]
    finally:
        for fd, _path in held:
            with contextlib.suppress(OSError):
                os.close(fd)  # closing the descriptor releases the lock


def _holder(fd: int) -> str:
    try:
        info = json.loads(os.pread(fd, 4096, 0) or b"{}")
        return f"{info.get('run', 'a run')} (pid {info.get('pid')} on host {info.get('host')})"
    except (OSError, ValueError):
        return "another process"
