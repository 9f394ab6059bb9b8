"""PtyLink's USB-adapter options: a callback on each open (DTR reset) and batched output."""

from __future__ import annotations

import os
import time

import serial
from grbl_fixtures import wait_for

from labauto.drivers.pty_link import PtyLink


def test_on_client_open_is_called_once_per_open_and_output_meanwhile_is_dropped() -> None:
    opens: list[float] = []
    with PtyLink("board", on_client_open=lambda: opens.append(time.monotonic())) as link:
        server = os.open(link.server_path, os.O_RDWR | os.O_NOCTTY)
        try:
            os.write(server, b"nobody listens\n")  # dropped: no client has the port open
            time.sleep(0.05)
            assert opens == []
            port = serial.serial_for_url(link.client_path, timeout=0.05)
            assert wait_for(lambda: len(opens) == 1)
            os.write(server, b"hello\n")
            assert port.readline() == b"hello\n"
            port.write(b"ping\n")
            assert os.read(server, 100) == b"ping\n"
            port.close()
            time.sleep(0.05)
            port = serial.serial_for_url(link.client_path, timeout=0.05)
            assert wait_for(lambda: len(opens) == 2)
            port.close()
        finally:
            os.close(server)


def test_latency_delivers_output_in_batches() -> None:
    with PtyLink("usb", latency_s=0.1) as link:
        server = os.open(link.server_path, os.O_RDWR | os.O_NOCTTY)
        port = serial.serial_for_url(link.client_path, timeout=0.01)
        try:
            sent = time.monotonic()
            os.write(server, b"ok\r\n")
            time.sleep(0.03)
            os.write(server, b"ALARM:3\r\n")
            data = b""
            while b"ALARM:3\r\n" not in data and time.monotonic() - sent < 2:
                chunk = port.read(100)
                if chunk and not data:
                    first = time.monotonic() - sent
                data += chunk
            assert data == b"ok\r\nALARM:3\r\n"
            assert 0.09 <= first < 0.5  # nothing came before the latency timer, then both
        finally:
            port.close()
            os.close(server)
