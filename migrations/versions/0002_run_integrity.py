"""Run integrity: config hash and lease on runs, plates by place, completed_with_errors.

Revision ID: 0002
Revises: 0001
Create Date: 2026-12-02

* ``runs.config_hash``: the SHA-256 of the run's effective config (resume is refused when the
  config differs, unless the operator names the run).
* ``runs.lease_token``, ``lease_pid``, ``lease_host``, ``lease_heartbeat_at``: the process that
  owns the run and its last heartbeat (one writer per run).
* ``runs.state`` gains ``completed_with_errors`` (the CHECK constraint is rebuilt).
* ``images.position``: the plate's place in its run; ``UNIQUE(run_id, position)`` replaces
  ``UNIQUE(run_id, sha256)`` (plates are identified by place, not by their pixels).

Plain SQLAlchemy types, as in 0001. SQLite runs these as batch (copy and move) operations.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | Sequence[str] | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

OLD_RUN_STATES = ("idle", "running", "paused", "stopping", "stopped", "failed", "succeeded")
NEW_RUN_STATES = (*OLD_RUN_STATES, "completed_with_errors")


def _enum(values: tuple[str, ...]) -> sa.Enum:
    return sa.Enum(
        *values,
        name="run_state",
        native_enum=False,
        create_constraint=True,
        length=max(len(v) for v in values),
    )


def upgrade() -> None:
    """Add the run lease and config hash, the new run state, and plate positions."""
    with op.batch_alter_table("runs") as batch:
        batch.alter_column(
            "state",
            existing_type=_enum(OLD_RUN_STATES),
            type_=_enum(NEW_RUN_STATES),
            existing_nullable=False,
        )
        batch.add_column(sa.Column("config_hash", sa.String(length=64), nullable=True))
        batch.add_column(sa.Column("lease_token", sa.String(length=64), nullable=True))
        batch.add_column(sa.Column("lease_pid", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("lease_host", sa.String(length=255), nullable=True))
        batch.add_column(sa.Column("lease_heartbeat_at", sa.DateTime(timezone=True), nullable=True))
    with op.batch_alter_table("images") as batch:
        batch.add_column(sa.Column("position", sa.Integer(), nullable=True))
        batch.drop_constraint(op.f("uq_images_run_id_sha256"), type_="unique")
        batch.create_unique_constraint(op.f("uq_images_run_id_position"), ["run_id", "position"])


def downgrade() -> None:
    """Back to 0001: ``completed_with_errors`` runs become ``failed``; positions are dropped.

    Fails (and rolls back) if a run holds two images with the same pixels, which 0001 cannot
    store.
    """
    op.execute("UPDATE runs SET state = 'failed' WHERE state = 'completed_with_errors'")
    with op.batch_alter_table("images") as batch:
        batch.drop_constraint(op.f("uq_images_run_id_position"), type_="unique")
        batch.create_unique_constraint(op.f("uq_images_run_id_sha256"), ["run_id", "sha256"])
        batch.drop_column("position")
    with op.batch_alter_table("runs") as batch:
        for column in ("lease_heartbeat_at", "lease_host", "lease_pid", "lease_token"):
            batch.drop_column(column)
        batch.drop_column("config_hash")
        batch.alter_column(
            "state",
            existing_type=_enum(NEW_RUN_STATES),
            type_=_enum(OLD_RUN_STATES),
            existing_nullable=False,
        )
