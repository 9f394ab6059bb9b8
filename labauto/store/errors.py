"""Errors raised by the store. All derive from :class:`StoreError`."""

from __future__ import annotations

from labauto.errors import LabautoError


class StoreError(LabautoError):
    """Base class for every storage failure (a ``LabautoError``: the CLI shows it as one line)."""


class DatabaseUnavailable(StoreError):
    """The database URL is malformed, its driver is missing, or the database cannot be opened.

    The message names the URL with any password replaced by ``***``.
    """


class MigrationError(StoreError):
    """An Alembic upgrade or downgrade failed (the message names the URL and the revision)."""


class NotFound(StoreError):
    """A row asked for by id does not exist (the message names the table and the id)."""


class InvalidTransition(StoreError):
    """A state change that the run or pick state machine does not allow.

    Attributes
    ----------
    entity : str
        ``"run"`` or ``"pick"``.
    entity_id : int
        Id of the run or pick.
    current, requested : str
        The state the row is in and the state that was asked for.
    """

    def __init__(
        self, entity: str, entity_id: int, current: str, requested: str, allowed: list[str]
    ) -> None:
        allowed_text = ", ".join(allowed) if allowed else "none (final state)"
        super().__init__(
            f"{entity} {entity_id}: cannot go from {current!r} to {requested!r}; "
            f"allowed from {current!r}: {allowed_text}"
        )
        self.entity = entity
        self.entity_id = entity_id
        self.current = current
        self.requested = requested


class IntegrityViolation(StoreError):
    """A write broke a database constraint (foreign key, unique, not-null, check).

    The message names the operation and carries the database's own message.
    """


class InvalidValue(StoreError, ValueError):
    """A value handed to the store is not acceptable (the message names the field and value)."""
