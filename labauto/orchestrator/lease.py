"""Holding a run's lease while the run goes on: a heartbeat thread.

The lease itself (take, refresh, release, in one transaction each) is the store's
(:mod:`labauto.store.leases`). :class:`LeaseKeeper` refreshes it every ``heartbeat_s``; if another
process has taken it over, the keeper asks the run to stop at its next safe point, so two
processes never go on driving one workcell.
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

    def run(self) -> None:
        while not self._done.wait(self.period_s):
            try:
                self.store.heartbeat(self.run_id, self.owner)
            except LeaseLost as exc:
                self.lost = str(exc)
                self.on_lost(self.lost)
                return
            except Exception:  # a busy database: try again at the next beat
                continue

    def stop(self) -> None:
        self._done.set()
        if self.is_alive():
            self.join(timeout=2.0)
