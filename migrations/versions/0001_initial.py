"""Initial schema: plates, runs, events, images, detections, colonies, picks, analyzer results.

Revision ID: 0001
Revises:
Create Date: 2026-11-22

Written out in plain SQLAlchemy types (no imports from labauto) so this revision keeps meaning
the same schema whatever later happens to the models. ``UTCDateTime`` columns are
``DateTime(timezone=True)`` here (the type decorator only converts values). Constraint names
come from the naming convention of the target metadata (``ck_<table>_<enum name>`` etc.).
"""

from __future__ import annotations

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0001"
down_revision: str | Sequence[str] | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

RUN_STATES = ("idle", "running", "paused", "stopping", "stopped", "failed", "succeeded")
PICK_STATES = ("planned", "moving", "picked", "delivered", "analyzed", "failed", "unknown")
COLONY_CLASSES = ("authentic", "merged", "mixed")


def _enum(values: tuple[str, ...], name: str) -> sa.Enum:
    return sa.Enum(
        *values,
        name=name,
        native_enum=False,
        create_constraint=True,
        length=max(len(v) for v in values),
    )


def _timestamp(name: str, nullable: bool = False) -> sa.Column:
    return sa.Column(name, sa.DateTime(timezone=True), nullable=nullable)


def _id() -> sa.Column:
    return sa.Column("id", sa.Integer(), nullable=False)


def _fk(column: str, table: str, target: str) -> sa.ForeignKeyConstraint:
    return sa.ForeignKeyConstraint(
        [column], [f"{target}.id"], name=op.f(f"fk_{table}_{column}_{target}")
    )


def _pk(table: str) -> sa.PrimaryKeyConstraint:
    return sa.PrimaryKeyConstraint("id", name=op.f(f"pk_{table}"))


def upgrade() -> None:
    """Create every table and index."""
    op.create_table(
        "plates",
        _id(),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("source", sa.Text(), nullable=True),
        _timestamp("created_at"),
        _pk("plates"),
        sa.UniqueConstraint("name", name=op.f("uq_plates_name")),
    )
    op.create_table(
        "runs",
        _id(),
        sa.Column("name", sa.String(length=200), nullable=False),
        sa.Column("state", _enum(RUN_STATES, "run_state"), nullable=False),
        sa.Column("config", sa.JSON(), nullable=True),
        _timestamp("created_at"),
        _timestamp("started_at", nullable=True),
        _timestamp("finished_at", nullable=True),
        sa.Column("error", sa.Text(), nullable=True),
        _pk("runs"),
    )
    op.create_index(op.f("ix_runs_state"), "runs", ["state"])

    op.create_table(
        "events",
        _id(),
        sa.Column("run_id", sa.Integer(), nullable=True),
        _timestamp("ts"),
        sa.Column("kind", sa.String(length=64), nullable=False),
        sa.Column("source", sa.String(length=64), nullable=False),
        sa.Column("message", sa.Text(), nullable=False),
        sa.Column("data", sa.JSON(), nullable=True),
        _fk("run_id", "events", "runs"),
        _pk("events"),
    )
    op.create_index(op.f("ix_events_run_id_kind"), "events", ["run_id", "kind"])

    op.create_table(
        "images",
        _id(),
        sa.Column("plate_id", sa.Integer(), nullable=False),
        sa.Column("run_id", sa.Integer(), nullable=True),
        sa.Column("path", sa.Text(), nullable=False),
        sa.Column("width", sa.Integer(), nullable=False),
        sa.Column("height", sa.Integer(), nullable=False),
        sa.Column("sha256", sa.String(length=64), nullable=False),
        _timestamp("captured_at"),
        _fk("plate_id", "images", "plates"),
        _fk("run_id", "images", "runs"),
        _pk("images"),
        sa.UniqueConstraint("run_id", "sha256", name=op.f("uq_images_run_id_sha256")),
    )
    op.create_index(op.f("ix_images_plate_id"), "images", ["plate_id"])
    op.create_index(op.f("ix_images_sha256"), "images", ["sha256"])

    op.create_table(
        "detections",
        _id(),
        sa.Column("run_id", sa.Integer(), nullable=True),
        sa.Column("image_id", sa.Integer(), nullable=False),
        sa.Column("object_index", sa.Integer(), nullable=False),
        sa.Column("method", sa.String(length=32), nullable=False),
        sa.Column("centroid_x", sa.Float(), nullable=False),
        sa.Column("centroid_y", sa.Float(), nullable=False),
        sa.Column("n_points", sa.Integer(), nullable=False),
        sa.Column("closed", sa.Boolean(), nullable=False),
        sa.Column("d_alpha_median", sa.Float(), nullable=True),
        sa.Column("d_alpha_mean", sa.Float(), nullable=True),
        sa.Column("centroid_inside", sa.Boolean(), nullable=True),
        sa.Column("is_des", sa.Boolean(), nullable=False),
        sa.Column("shape", sa.String(length=32), nullable=True),
        sa.Column("ellipse_cx", sa.Float(), nullable=True),
        sa.Column("ellipse_cy", sa.Float(), nullable=True),
        sa.Column("ellipse_a", sa.Float(), nullable=True),
        sa.Column("ellipse_b", sa.Float(), nullable=True),
        sa.Column("ellipse_angle", sa.Float(), nullable=True),
        sa.Column("area_px", sa.Float(), nullable=True),
        _fk("run_id", "detections", "runs"),
        _fk("image_id", "detections", "images"),
        _pk("detections"),
    )
    op.create_index(op.f("ix_detections_run_id"), "detections", ["run_id"])
    op.create_index(op.f("ix_detections_image_id"), "detections", ["image_id"])

    op.create_table(
        "colonies",
        _id(),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("image_id", sa.Integer(), nullable=False),
        sa.Column("detection_id", sa.Integer(), nullable=True),
        sa.Column("colony_index", sa.Integer(), nullable=False),
        sa.Column("klass", _enum(COLONY_CLASSES, "colony_class"), nullable=False),
        sa.Column("centroid_x", sa.Float(), nullable=False),
        sa.Column("centroid_y", sa.Float(), nullable=False),
        sa.Column("area_px", sa.Float(), nullable=True),
        sa.Column("d_alpha_median", sa.Float(), nullable=True),
        sa.Column("estimated_count", sa.Integer(), nullable=False),
        sa.Column("mix_score", sa.Float(), nullable=True),
        sa.Column("contour", sa.JSON(), nullable=True),
        _fk("run_id", "colonies", "runs"),
        _fk("image_id", "colonies", "images"),
        _fk("detection_id", "colonies", "detections"),
        _pk("colonies"),
    )
    op.create_index(op.f("ix_colonies_run_id_image_id"), "colonies", ["run_id", "image_id"])
    op.create_index(op.f("ix_colonies_image_id"), "colonies", ["image_id"])
    op.create_index(op.f("ix_colonies_detection_id"), "colonies", ["detection_id"])

    op.create_table(
        "picks",
        _id(),
        sa.Column("run_id", sa.Integer(), nullable=False),
        sa.Column("colony_id", sa.Integer(), nullable=False),
        sa.Column("sequence", sa.Integer(), nullable=False),
        sa.Column("state", _enum(PICK_STATES, "pick_state"), nullable=False),
        sa.Column("deck_x_mm", sa.Float(), nullable=True),
        sa.Column("deck_y_mm", sa.Float(), nullable=True),
        sa.Column("sample_id", sa.String(length=100), nullable=True),
        sa.Column("needs_attention", sa.Boolean(), nullable=False),
        sa.Column("error", sa.Text(), nullable=True),
        _timestamp("created_at"),
        _timestamp("updated_at"),
        _fk("run_id", "picks", "runs"),
        _fk("colony_id", "picks", "colonies"),
        _pk("picks"),
        sa.UniqueConstraint("run_id", "colony_id", name=op.f("uq_picks_run_id_colony_id")),
    )
    op.create_index(op.f("ix_picks_run_id_state"), "picks", ["run_id", "state"])
    op.create_index(op.f("ix_picks_colony_id"), "picks", ["colony_id"])

    op.create_table(
        "analyzer_results",
        _id(),
        sa.Column("pick_id", sa.Integer(), nullable=False),
        sa.Column("sample_id", sa.String(length=100), nullable=False),
        sa.Column("values", sa.JSON(), nullable=True),
        sa.Column("error_code", sa.Integer(), nullable=True),
        _timestamp("created_at"),
        _fk("pick_id", "analyzer_results", "picks"),
        _pk("analyzer_results"),
        sa.UniqueConstraint("pick_id", name=op.f("uq_analyzer_results_pick_id")),
    )


def downgrade() -> None:
    """Drop every table (indexes go with their tables), dependents first."""
    for table in (
        "analyzer_results",
        "picks",
        "colonies",
        "detections",
        "images",
        "events",
        "runs",
        "plates",
    ):
        op.drop_table(table)
