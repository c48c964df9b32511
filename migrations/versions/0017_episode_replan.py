"""How a closed-loop episode replans: ``episodes.replan``, ``search`` (the whole way to the goal) or
``step`` (to the next state of the high-level plans); NULL for an open-loop episode. Closed-loop episodes
stored before replanned by ``search``, and get it. docs/DESIGN.md sections 15.4 and 15.5.

Revision ID: 0017_episode_replan
Revises: 0016_episodes
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0017_episode_replan"
down_revision = "0016_episodes"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.add_column("episodes", sa.Column("replan", sa.String(length=8), nullable=True))
    op.execute("UPDATE episodes SET replan = 'search' WHERE closed_loop")


def downgrade() -> None:
    op.drop_column("episodes", "replan")
