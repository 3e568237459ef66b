"""references: drop ``domain_path``; the domain is stored once, in ``domain_config``

Analyses used to find the reference's domain in a ``reference.domain.json`` file beside the BVH
(``domain_path`` pointed at it). Every analysis request now carries the stored
``domain_config`` as data, so the column and the files are gone.

Revision ID: 0005
Revises: 0004
"""

from collections.abc import Sequence
from pathlib import Path

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    conn = op.get_bind()
    for (path,) in conn.execute(sa.text('SELECT domain_path FROM "references"')).all():
        if path:
            Path(path).unlink(missing_ok=True)
    with op.batch_alter_table("references", schema=None) as batch_op:
        batch_op.drop_column("domain_path")


def downgrade() -> None:
    """The column comes back empty; nothing reads it."""
    with op.batch_alter_table("references", schema=None) as batch_op:
        batch_op.add_column(sa.Column("domain_path", sa.String(length=1000), nullable=True))
