"""Training jobs on the league's trainers and the events they report.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-28
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

UTC_TIME = sa.DateTime(timezone=True)


def _fk(table: str, column: str, target: str, ondelete: str = "CASCADE") -> sa.ForeignKeyConstraint:
    return sa.ForeignKeyConstraint(
        [column], [f"{target}.id"], name=op.f(f"fk_{table}_{column}_{target}"), ondelete=ondelete
    )


def upgrade() -> None:
    """Create ``training_jobs`` and ``training_events``."""
    op.create_table(
        "training_jobs",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("owner_id", sa.Integer(), nullable=False),
        sa.Column("name", sa.String(length=64), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("priority", sa.Integer(), nullable=False),
        sa.Column("spec", sa.JSON(), nullable=False),
        sa.Column("reward_source", sa.Text(), nullable=False),
        sa.Column("minutes", sa.Float(), nullable=False),
        sa.Column("clone_of_id", sa.Integer(), nullable=True),
        sa.Column("attempts", sa.Integer(), nullable=False),
        sa.Column("max_attempts", sa.Integer(), nullable=False),
        sa.Column("lease_owner", sa.String(length=128), nullable=True),
        sa.Column("lease_expires_at", UTC_TIME, nullable=True),
        sa.Column("stop_requested_at", UTC_TIME, nullable=True),
        sa.Column("error", sa.Text(), nullable=True),
        sa.Column("compute_seconds", sa.Float(), nullable=False),
        sa.Column("best_lap_ms", sa.Integer(), nullable=True),
        sa.Column("run_sha256", sa.String(length=64), nullable=True),
        sa.Column("model_id", sa.Integer(), nullable=True),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.Column("started_at", UTC_TIME, nullable=True),
        sa.Column("finished_at", UTC_TIME, nullable=True),
        sa.Column("updated_at", UTC_TIME, nullable=False),
        sa.CheckConstraint(
            "status IN ('queued', 'running', 'done', 'failed', 'stopped')",
            name=op.f("ck_training_jobs_status"),
        ),
        _fk("training_jobs", "owner_id", "racers"),
        _fk("training_jobs", "clone_of_id", "training_jobs", "SET NULL"),
        _fk("training_jobs", "model_id", "models", "SET NULL"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_training_jobs")),
    )
    op.create_index(op.f("ix_training_jobs_owner_id"), "training_jobs", ["owner_id"])
    op.create_index(
        "ix_training_jobs_status_lease", "training_jobs", ["status", "lease_expires_at"]
    )
    op.create_table(
        "training_events",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("job_id", sa.Integer(), nullable=False),
        sa.Column("kind", sa.String(length=16), nullable=False),
        sa.Column("data", sa.JSON(), nullable=False),
        sa.Column("created_at", UTC_TIME, nullable=False),
        sa.CheckConstraint(
            "kind IN ('iteration', 'poses', 'log', 'status')",
            name=op.f("ck_training_events_kind"),
        ),
        _fk("training_events", "job_id", "training_jobs"),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_training_events")),
    )
    op.create_index("ix_training_events_job_id_id", "training_events", ["job_id", "id"])


def downgrade() -> None:
    """Drop both tables."""
    op.drop_index("ix_training_events_job_id_id", table_name="training_events")
    op.drop_table("training_events")
    op.drop_index("ix_training_jobs_status_lease", table_name="training_jobs")
    op.drop_index(op.f("ix_training_jobs_owner_id"), table_name="training_jobs")
    op.drop_table("training_jobs")
