"""A software null-modem cable: two pseudo-terminals joined by a relay thread.

A serial server (e.g. a simulated RTU device) opens one end, the driver under test opens the other,
and every byte written on one side comes out of the other, as on a real RS-232/RS-485 link. Both
ends are ordinary tty devices, so pyserial and pymodbus open them like ``/dev/ttyUSB0``.

The client end is published as a stable symbolic link (like ``/dev/serial/by-id/...`` made by
udev). :meth:`PtyLink.hang_up_client` simulates a pulled cable or a USB adapter that was
unplugged and plugged back: the client's current pty is hung up (its reads and writes fail) and a
fresh pty appears behind the same link path, so a driver that closes and re-opens the path
reconnects.

Linux/POSIX only (uses :func:`os.openpty`).
"""

from __future__ import annotations

import contextlib
import os
import select
import shutil
import tempfile
import threading
import time
import tty
from pathlib import Path
from types import TracebackType

_CHUNK = 4096
_WRITE_PATIENCE_S = 1.0  # bytes nobody reads for this long are dropped, as on a real line


class _Pty:
    """One pseudo-terminal: the master fd the relay uses, and a held slave fd.

    The relay keeps its own slave fd open so that reading the master never fails with EIO while
    no client has the slave open (Linux reports EIO on a master with no open slave).
    """

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line editing, 8-bit clean until the user configures it
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)

    def close(self) -> None:
        for fd in (self.master, self.slave):
            with contextlib.suppress(OSError):
                os.close(fd)


class PtyLink:
    """Relay bytes between two pseudo-terminals in a background thread.

    Parameters
    ----------
    name : str
        File name of the client-side link inside a private temporary folder (``client_path``).

    Examples
    --------
    >>> with PtyLink() as link:                                   # doctest: +SKIP
    ...     server_port, client_port = link.server_path, link.client_path
    """

    def __init__(self, name: str = "analyzer") -> None:
        self._folder = Path(tempfile.mkdtemp(prefix="labauto-pty-"))
        self.client_path = str(self._folder / name)
        self._client: _Pty | None = None
        self._server: _Pty | None = None
        self._wake_r, self._wake_w = -1, -1
        self._hang_up_requested = threading.Event()
        self._hung_up = threading.Event()
        self._stopping = False
        self._thread: threading.Thread | None = None

    @property
    def server_path(self) -> str:
        """Path of the server-side tty (a ``/dev/pts/N`` device)."""
        if self._server is None:
            raise RuntimeError("PtyLink is not open")
        return self._server.path

    def open(self) -> tuple[str, str]:
        """Create both ptys, publish the client link and start the relay.

        Returns
        -------
        tuple of str
            ``(client_path, server_path)``.
        """
        if self._thread is not None:
            raise RuntimeError("PtyLink is already open")
        self._server = _Pty()
        self._client = _Pty()
        self._publish(self._client.path)
        self._wake_r, self._wake_w = os.pipe()
        self._stopping = False
        self._thread = threading.Thread(target=self._relay, name="labauto-pty-link", daemon=True)
        self._thread.start()
        return self.client_path, self._server.path

    def hang_up_client(self, timeout: float = 2.0) -> None:
        """Hang up the client's pty and put a fresh one behind ``client_path``.

        Whoever has the old pty open sees its reads and writes fail (``EIO``), as with an
        unplugged USB-serial adapter; opening ``client_path`` again gives a working line.
        Safe to call from any thread; returns once the new pty is in place.
        """
        if self._thread is None:
            raise RuntimeError("PtyLink is not open")
        self._hung_up.clear()
        self._hang_up_requested.set()
        os.write(self._wake_w, b"h")
        if not self._hung_up.wait(timeout):
            raise TimeoutError("pty relay did not hang up the client end in time")

    def request_hang_up(self) -> None:
        """Ask the relay to hang up the client end soon, without waiting (any thread, any loop)."""
        if self._thread is None:
            return
        self._hung_up.clear()
        self._hang_up_requested.set()
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"h")

    def close(self) -> None:
        """Stop the relay, close both ptys and remove the link folder. Idempotent."""
        if self._thread is not None:
            self._stopping = True
            with contextlib.suppress(OSError):
                os.write(self._wake_w, b"q")
            self._thread.join(timeout=5)
            self._thread = None
        for fd in (self._wake_r, self._wake_w):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._wake_r, self._wake_w = -1, -1
        for pty in (self._client, self._server):
            if pty is not None:
                pty.close()
        self._client = self._server = None
        shutil.rmtree(self._folder, ignore_errors=True)

    def __enter__(self) -> PtyLink:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- relay thread ---------------------------------------------------------------------------
    def _publish(self, target: str) -> None:
        """Point ``client_path`` at ``target`` atomically (replace, never a missing link)."""
        tmp = f"{self.client_path}.new"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        os.symlink(target, tmp)
        os.replace(tmp, self.client_path)

    def _swap_client(self) -> None:
        assert self._client is not None
        old = self._client
        self._client = _Pty()
        self._publish(self._client.path)
        old.close()  # the old slave sees a hang-up once its master is closed

    def _relay(self) -> None:
        assert self._client is not None and self._server is not None
        while not self._stopping:
            if self._hang_up_requested.is_set():
                self._hang_up_requested.clear()
                self._swap_client()
                self._hung_up.set()
            client, server = self._client.master, self._server.master
            readable, _, _ = select.select([client, server, self._wake_r], [], [], 0.5)
            if self._wake_r in readable:
                with contextlib.suppress(BlockingIOError):
                    os.read(self._wake_r, 64)
            if client in readable:
                self._forward(client, server)
            if server in readable:
                self._forward(server, client)

    @staticmethod
    def _forward(source: int, target: int) -> None:
        try:
            data = os.read(source, _CHUNK)
        except (BlockingIOError, OSError):
            return
        deadline = time.monotonic() + _WRITE_PATIENCE_S
        while data and time.monotonic() < deadline:
            try:
                data = data[os.write(target, data) :]
            except BlockingIOError:  # nobody is reading the other end and its buffer is full
                select.select([], [target], [], 0.05)
            except OSError:
                return  # the other end is gone; the bytes are lost, as on a real cable
