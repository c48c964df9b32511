"""Expert iteration: improve_generations (twisted/store/improve.py), on the models branch.

Revision ID: 0011
Revises: 0003
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0011"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "improve_generations",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("lineage", sa.String(length=64), nullable=False),
        sa.Column("generation", sa.Integer(), nullable=False),
        sa.Column("status", sa.String(length=16), nullable=False),
        sa.Column("seed", sa.BigInteger(), nullable=False),
        sa.Column("parameters", sa.JSON(), nullable=False),
        sa.Column("parent_model_id", sa.Integer(), nullable=True),
        sa.Column("model_id", sa.Integer(), nullable=True),
        sa.Column("training_run_id", sa.Integer(), nullable=True),
        sa.Column("training_goals", sa.JSON(), nullable=False),
        sa.Column("data", sa.JSON(), nullable=False),
        sa.Column("tune_set", sa.String(length=64), nullable=True),
        sa.Column("tune_results", sa.JSON(), nullable=False),
        sa.Column("tune_runs", sa.Integer(), nullable=False),
        sa.Column("tune_solved", sa.Integer(), nullable=False),
        sa.Column("tune_calls", sa.Integer(), nullable=False),
        sa.Column("success_at_6", sa.JSON(), nullable=True),
        sa.Column("wall_s", sa.Float(), nullable=False),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("updated_at", sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(
            ["parent_model_id"], ["models.id"], name=op.f("fk_improve_generations_parent_model_id_models")
        ),
        sa.ForeignKeyConstraint(
            ["model_id"], ["models.id"], name=op.f("fk_improve_generations_model_id_models")
        ),
        sa.ForeignKeyConstraint(
            ["training_run_id"],
            ["training_runs.id"],
            name=op.f("fk_improve_generations_training_run_id_training_runs"),
        ),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_improve_generations")),
        sa.UniqueConstraint("lineage", "generation", name=op.f("uq_improve_generations_lineage")),
    )
    op.create_index(op.f("ix_improve_generations_lineage"), "improve_generations", ["lineage"])
    op.create_index(op.f("ix_improve_generations_model_id"), "improve_generations", ["model_id"])


def downgrade() -> None:
    op.drop_index(op.f("ix_improve_generations_model_id"), table_name="improve_generations")
    op.drop_index(op.f("ix_improve_generations_lineage"), table_name="improve_generations")
    op.drop_table("improve_generations")
