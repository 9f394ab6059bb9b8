"""Calibrations: stored camera and deck calibrations (issue 14).

Revision ID: 0003
Revises: 0002
Create Date: 2026-12-02

* ``calibrations``: name (several rows may share one; the newest is in force), kind (camera or
  deck), creation time, image size, reprojection RMS (px), deck residual (mm), camera matrix
  and distortion coefficients (JSON lists), and the whole calibration document (JSON).

Plain SQLAlchemy types, as in 0001.
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0003"
down_revision: str | Sequence[str] | None = "0002"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    """Create the calibrations table."""
    op.create_table(
        "calibrations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("image_width", sa.Integer(), nullable=False),
        sa.Column("image_height", sa.Integer(), nullable=False),
        sa.Column("rms_px", sa.Float(), nullable=True),
        sa.Column("residual_mm", sa.Float(), nullable=True),
        sa.Column("camera_matrix", sa.JSON(), nullable=False),
        sa.Column("dist_coeffs", sa.JSON(), nullable=False),
        sa.Column("data", sa.JSON(), nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_calibrations")),
    )
    op.create_index(op.f("ix_calibrations_name"), "calibrations", ["name"])


def downgrade() -> None:
    """Drop the calibrations table."""
    op.drop_index(op.f("ix_calibrations_name"), table_name="calibrations")
    op.drop_table("calibrations")
