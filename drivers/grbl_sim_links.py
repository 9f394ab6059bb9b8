"""The simulated gantry's two ways to a host: its end of a pty link, and a one-client TCP socket."""

from __future__ import annotations

import contextlib
import os
import socket
import tty
from collections.abc import Callable

from .pty_link import PtyLink

__all__ = ["PtyEnd", "TcpLink"]


class PtyEnd:
    """The simulator's end of a :class:`PtyLink`: the server tty, opened raw and non-blocking."""

    def __init__(self, name: str, on_open: Callable[[], None] | None, latency_s: float) -> None:
        self.link = PtyLink(name, on_client_open=on_open, latency_s=latency_s)
        self.link_path, server_path = self.link.open()
        self.fd = os.open(server_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)

    @property
    def device(self) -> str:
        return os.path.realpath(self.link_path)

    def fds(self) -> list[int]:
        return [self.fd]

    def read(self, fd: int) -> bytes | None:
        try:
            return os.read(self.fd, 4096)
        except (BlockingIOError, OSError):
            return b""

    def write(self, data: bytes) -> None:
        with contextlib.suppress(BlockingIOError, OSError):
            os.write(self.fd, data)  # a full tty buffer drops output, as a cable would

    def drop(self) -> None:
        """Hang up the host's pty; a fresh one appears behind the same link path."""
        self.link.request_hang_up()

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self.fd)
        self.link.close()


class TcpLink:
    """A listening TCP socket serving one client at a time (a newer client replaces the old)."""

    def __init__(self, port: int) -> None:
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind(("127.0.0.1", port))
        self.server.listen(2)
        self.server.setblocking(False)
        self.client: socket.socket | None = None

    @property
    def port(self) -> int:
        return self.server.getsockname()[1]

    def fds(self) -> list[int]:
        fds = [self.server.fileno()]
        if self.client is not None:
            fds.append(self.client.fileno())
        return fds

    def read(self, fd: int) -> bytes | None:
        """Return received bytes, ``b""`` if none, ``None`` when the client went away."""
        if fd == self.server.fileno():
            with contextlib.suppress(BlockingIOError):
                client, _ = self.server.accept()
                client.setblocking(False)
                client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.drop()
                self.client = client
            return b""
        if self.client is None:
            return b""
        try:
            data = self.client.recv(4096)
        except BlockingIOError:
            return b""
        except OSError:
            data = b""
        if not data:
            self.drop()
            return None
        return data

    def write(self, data: bytes) -> None:
        if self.client is None:
            return
        try:
            self.client.sendall(data)
        except OSError:
            self.drop()

    def drop(self) -> None:
        if self.client is not None:
            with contextlib.suppress(OSError):
                self.client.close()
            self.client = None

    def close(self) -> None:
        self.drop()
        self.server.close()
