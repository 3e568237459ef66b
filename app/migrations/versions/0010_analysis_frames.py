"""analyses.frames_start / frames_end: the video frames an analysis covers (one repetition
of several), NULL for the whole video

Revision ID: 0010
Revises: 0009
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0010"
down_revision: str | None = "0009"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("analyses", schema=None) as batch_op:
        batch_op.add_column(sa.Column("frames_start", sa.Integer(), nullable=True))
        batch_op.add_column(sa.Column("frames_end", sa.Integer(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("analyses", schema=None) as batch_op:
        batch_op.drop_column("frames_end")
        batch_op.drop_column("frames_start")
