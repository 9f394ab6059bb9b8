"""The lease on a run: which process owns it, and when that owner last showed it was alive.

A run is driven by one process at a time. The owner is written on the run's row (``lease_token``,
``lease_pid``, ``lease_host``, ``lease_heartbeat_at``) and refreshed by a heartbeat. Taking the
lease is one transaction that reads the row under a write lock (SQLite ``BEGIN IMMEDIATE``;
``SELECT ... FOR UPDATE`` elsewhere) and changes it only if it is free, already ours, or stale,
so two processes can never both believe they own the run, on SQLite or any SQL server.

A lease is stale when its heartbeat is older than the timeout, or at once when its owner is a
process on this host that no longer exists (a killed ``labauto run``). Taking over a stale lease
writes a ``run.lease`` event naming the previous owner.
"""

from __future__ import annotations

import os
import secrets
import socket
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime

from .errors import StoreError


@dataclass(frozen=True)
class LeaseOwner:
    """A process that may own runs: a random token, its pid and its host name."""

    token: str
    pid: int
    host: str

    @classmethod
    def this_process(cls) -> LeaseOwner:
        """The calling process, with a fresh token."""
        return cls(secrets.token_hex(16), os.getpid(), socket.gethostname())

    def describe(self) -> str:
        return f"pid {self.pid} on host {self.host}"


class LeaseHeld(StoreError):
    """The run is owned by another live process.

    Attributes
    ----------
    run_id : int
    pid : int or None
    host : str or None
    heartbeat_age_s : float or None
        Seconds since the owner's last heartbeat.
    """

    def __init__(
        self, run_id: int, pid: int | None, host: str | None, heartbeat_age_s: float | None
    ) -> None:
        age = "" if heartbeat_age_s is None else f", last heartbeat {heartbeat_age_s:.1f} s ago"
        super().__init__(
            f"run {run_id} is owned by pid {pid} on host {host}{age}: "
            "another labauto process is driving it; wait for it to end or stop it "
            f"(labauto runs stop {run_id})"
        )
        self.run_id = run_id
        self.pid = pid
        self.host = host
        self.heartbeat_age_s = heartbeat_age_s


class LeaseLost(StoreError):
    """The lease this process held was taken by another process."""


def pid_alive(pid: int) -> bool:
    """True if a process with this pid exists on this host (or cannot be checked)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, owned by someone else
        return True
    except OSError:
        return True
    return True


def owner_dead(pid: int | None, host: str | None) -> bool:
    """True when the owner is known to be gone: a process of this host that does not exist."""
    return pid is not None and host == socket.gethostname() and not pid_alive(pid)


@dataclass(frozen=True)
class StaleCheck:
    """When a lease counts as stale (see the module docstring)."""

    timeout_s: float
    is_dead: Callable[[int | None, str | None], bool] = owner_dead

    def verdict(
        self, pid: int | None, host: str | None, heartbeat: datetime | None, now: datetime
    ) -> tuple[bool, str]:
        """``(stale, why)`` for a lease held by ``pid`` on ``host``."""
        age = None if heartbeat is None else (now - heartbeat).total_seconds()
        if self.is_dead(pid, host):
            return True, f"its process is gone (pid {pid} on {host} does not exist)"
        if age is None or age > self.timeout_s:
            shown = "never" if age is None else f"{age:.1f} s ago"
            return True, f"its last heartbeat was {shown} (timeout {self.timeout_s:g} s)"
        return False, ""


def heartbeat_age(heartbeat: datetime | None, now: datetime) -> float | None:
    return None if heartbeat is None else (now - heartbeat).total_seconds()
