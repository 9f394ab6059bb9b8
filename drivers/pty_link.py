"""A software null-modem cable: two pseudo-terminals joined by a relay thread.

A serial server (e.g. a simulated RTU device) opens one end, the driver under test opens the other,
and every byte written on one side comes out of the other, as on a real RS-232/RS-485 link. Both
ends are ordinary tty devices, so pyserial and pymodbus open them like ``/dev/ttyUSB0``.

The client end is published as a stable symbolic link (like ``/dev/serial/by-id/...`` made by
udev). Two options make the line behave like a USB-serial adapter in front of a microcontroller
board: ``on_client_open`` is called each time a client opens the port (an Arduino resets on
the DTR edge of that open), and ``latency_s`` holds bytes going to the client and delivers them
in batches (an FTDI chip's latency timer).

:meth:`PtyLink.hang_up_client` simulates a pulled cable or a USB adapter that was unplugged
and plugged back: the client's current pty is hung up (its reads and writes fail) and a fresh
pty appears behind the same link path, so a driver that closes and re-opens the path reconnects.

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
from collections.abc import Callable
from pathlib import Path
from types import TracebackType

_CHUNK = 4096
_WRITE_PATIENCE_S = 1.0  # bytes nobody reads for this long are dropped, as on a real line


class _Pty:
    """One pseudo-terminal: the master fd the relay uses, and (normally) a held slave fd.

    The relay keeps its own slave fd open so that reading the master never fails with EIO while
    no client has the slave open (Linux reports EIO on a master with no open slave). A watched
    pty (``hold_slave=False``) lets it go instead, so that the master shows ``POLLHUP`` exactly
    while no client has the port open.
    """

    def __init__(self, *, hold_slave: bool = True) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line editing, 8-bit clean until the user configures it
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        if not hold_slave:
            os.close(self.slave)
            self.slave = -1

    def close(self) -> None:
        for fd in (self.master, self.slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)


class PtyLink:
    """Relay bytes between two pseudo-terminals in a background thread.

    Parameters
    ----------
    name : str
        File name of the client-side link inside a private temporary folder (``client_path``).
    on_client_open : callable, optional
        Called (in the relay thread, without arguments) each time a client opens
        ``client_path`` after nobody had it open, e.g. to restart a device as a DTR reset
        would. Bytes sent towards the client while nobody has it open are dropped.
    latency_s : float
        Hold bytes going to the client until this long after the first of them arrived, then
        deliver them at once (0: at once).

    Examples
    --------
    >>> with PtyLink() as link:                                   # doctest: +SKIP
    ...     server_port, client_port = link.server_path, link.client_path
    """

    def __init__(
        self,
        name: str = "analyzer",
        *,
        on_client_open: Callable[[], None] | None = None,
        latency_s: float = 0.0,
    ) -> None:
        if not latency_s >= 0:
            raise ValueError(f"latency_s must be >= 0, got {latency_s!r}")
        self.on_client_open = on_client_open
        self.latency_s = float(latency_s)
        self._batch = bytearray()
        self._batch_due = 0.0
        self._client_present = False
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
        self._client = self._new_client()
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

    def _new_client(self) -> _Pty:
        self._client_present = False
        return _Pty(hold_slave=self.on_client_open is None)

    def _swap_client(self) -> None:
        assert self._client is not None
        old = self._client
        self._client = self._new_client()
        self._publish(self._client.path)
        old.close()  # the old slave sees a hang-up once its master is closed

    def _relay(self) -> None:
        assert self._client is not None and self._server is not None
        watched = self.on_client_open is not None
        while not self._stopping:
            if self._hang_up_requested.is_set():
                self._hang_up_requested.clear()
                self._swap_client()
                self._hung_up.set()
            client, server = self._client.master, self._server.master
            if watched:
                self._watch_client(client)
            sources = [server, self._wake_r] + (
                [client] if not watched or self._client_present else []
            )
            timeout = 0.5
            if watched and not self._client_present:
                timeout = 0.01
            if self._batch:
                timeout = max(0.0, min(timeout, self._batch_due - time.monotonic()))
            readable, _, _ = select.select(sources, [], [], timeout)
            if self._wake_r in readable:
                with contextlib.suppress(BlockingIOError):
                    os.read(self._wake_r, 64)
            if client in readable:
                self._forward(client, server)
            if server in readable:
                if watched and not self._client_present:
                    with contextlib.suppress(BlockingIOError, OSError):
                        os.read(server, _CHUNK)  # nobody listens: lost, as on a real line
                else:
                    self._to_client(server, client)
            if self._batch and time.monotonic() >= self._batch_due:
                self._deliver(bytes(self._batch), client)
                self._batch.clear()

    def _watch_client(self, client: int) -> None:
        """Track whether a client has the port open; call ``on_client_open`` when one opens it."""
        poller = select.poll()
        poller.register(client, select.POLLIN)
        hung_up = any(event & select.POLLHUP for _, event in poller.poll(0))
        if hung_up:
            self._client_present = False
            return
        if not self._client_present:
            self._client_present = True
            self._batch.clear()
            assert self.on_client_open is not None
            self.on_client_open()

    def _to_client(self, server: int, client: int) -> None:
        if not self.latency_s:
            self._forward(server, client)
            return
        try:
            data = os.read(server, _CHUNK)
        except (BlockingIOError, OSError):
            return
        if data and not self._batch:
            self._batch_due = time.monotonic() + self.latency_s
        self._batch += data

    @classmethod
    def _forward(cls, source: int, target: int) -> None:
        try:
            data = os.read(source, _CHUNK)
        except (BlockingIOError, OSError):
            return
        cls._deliver(data, target)

    @staticmethod
    def _deliver(data: bytes, target: int) -> None:
        deadline = time.monotonic() + _WRITE_PATIENCE_S
        while data and time.monotonic() < deadline:
            try:
                data = data[os.write(target, data) :]
            except BlockingIOError:  # nobody is reading the other end and its buffer is full
                select.select([], [target], [], 0.05)
            except OSError:
                return  # the other end is gone; the bytes are lost, as on a real cable
