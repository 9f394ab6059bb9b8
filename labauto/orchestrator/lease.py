"""Holding a run's lease while the run goes on: a heartbeat thread.

The lease itself (take, refresh, release, in one transaction each) is the store's
(:mod:`labauto.store.leases`). :class:`LeaseKeeper` refreshes it every ``heartbeat_s``; if another
process has taken it over, the keeper asks the run to stop at its next safe point, so two
processes never go on driving one workcell. The run's safe points also look themselves
(:meth:`LeaseKeeper.verify`, in the run's thread): a beat a tenth of a second late, or one that
found the database busy, would otherwise let the run start another pick on a lease it no
longer holds.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from labauto.store import Store
from labauto.store.leases import LeaseLost, LeaseOwner


class LeaseKeeper(threading.Thread):
    """Refresh the lease of ``run_id`` every ``period_s``; call ``on_lost`` if it was taken."""

    def __init__(
        self,
        store: Store,
        run_id: int,
        owner: LeaseOwner,
        period_s: float,
        on_lost: Callable[[str], None],
    ) -> None:
        super().__init__(name=f"labauto-lease-{run_id}", daemon=True)
        self.store, self.run_id, self.owner, self.period_s = store, run_id, owner, period_s
        self.on_lost = on_lost
        self.lost: str | None = None
        self._done = threading.Event()
        self._lock = threading.Lock()

    def run(self) -> None:
        while not self._done.wait(self.period_s):
            if not self.beat():
                return

    def verify(self) -> None:
        """Refresh the lease now, in the caller's thread (a safe point of the run)."""
        self.beat()

    def beat(self) -> bool:
        """Refresh the lease; False (and ``on_lost`` called, once) if it was taken over.

        A busy database counts as held: the next beat tries again.
        """
        with self._lock:
            if self.lost is not None:
                return False
            try:
                self.store.heartbeat(self.run_id, self.owner)
                return True
            except LeaseLost as exc:
                self.lost = str(exc)
            except Exception:  # a busy database: try again at the next beat
                return True
        self.on_lost(self.lost)
        return False

    def stop(self) -> None:
        self._done.set()
        if self.is_alive():
            self.join(timeout=2.0)
