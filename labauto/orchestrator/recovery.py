"""Bringing a failed device back: a retry policy with a growing delay between tries.

A short outage (an analyzer unreachable for a few seconds, a robot re-enumerating on USB) must
not fail a whole run. :func:`with_retries` calls ``action`` up to ``attempts`` times, waiting
``initial_delay_s * factor**i`` (at most ``max_delay_s``) between tries, and reports every
failed try. The wait ends early when ``cancelled()`` turns true (an operator's stop or e-stop).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TypeVar

from labauto.config import RetryConfig

T = TypeVar("T")


def with_retries(
    action: Callable[[], T],
    policy: RetryConfig,
    *,
    on_failure: Callable[[int, int, float, BaseException], None],
    retry_on: tuple[type[BaseException], ...],
    cancelled: Callable[[], bool] = lambda: False,
) -> T:
    """Run ``action`` until it succeeds or the tries run out.

    Parameters
    ----------
    action : callable
        The recovery step (e.g. reconnect and reset).
    policy : RetryConfig
        Tries and delays.
    on_failure : callable
        ``on_failure(attempt, attempts, delay_s, error)`` after each failed try (``delay_s`` is
        the wait before the next try, 0 after the last).
    retry_on : tuple of exception types
        Errors that are retried; others are raised at once.
    cancelled : callable
        Checked while waiting: a true value ends the retries with the last error.

    Raises
    ------
    Exception
        The last error, once every try failed.
    """
    delays = policy.delays()
    waiter = threading.Event()
    for attempt in range(1, policy.attempts + 1):
        try:
            return action()
        except retry_on as exc:
            delay = delays[attempt - 1] if attempt <= len(delays) else 0.0
            on_failure(attempt, policy.attempts, delay, exc)
            if attempt == policy.attempts or cancelled():
                raise
            end = delay
            while end > 0 and not cancelled():
                step = min(0.05, end)
                waiter.wait(step)
                end -= step
            if cancelled():
                raise
    raise AssertionError("unreachable")  # pragma: no cover
