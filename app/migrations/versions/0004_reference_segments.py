"""references: store the segments every analysis uses, and pass the coach's starts to the engine

Until now the domain's ``segments`` were kept out of ``<ref>.domain.json`` (the engine never
saw them) and ``derived.segments`` held them as given, or nothing when the engine detected the
boundaries. Each reference is re-inspected: ``derived.segments`` becomes the starts every
analysis uses, then the last frame. A reference whose BVH is gone is left as it was. (It also
rewrote the domain file beside the BVH; since 0005 no domain file is read, analyses carry the
stored ``domain_config``, so that step is gone.)

Revision ID: 0004
Revises: 0003
"""

from collections.abc import Sequence
from pathlib import Path

import sqlalchemy as sa
from alembic import op

revision: str = "0004"
down_revision: str | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

REFERENCES = sa.table(
    "references",
    sa.column("id", sa.Integer),
    sa.column("bvh_path", sa.String),
    sa.column("domain_config", sa.JSON),
    sa.column("derived", sa.JSON),
)


def _derived(bvh: Path, config: dict | None) -> dict | None:
    from app.core import validation
    from worker.engine_surface import InvalidInput

    try:
        return validation.inspect_reference(bvh, config)
    except validation.InvalidDomain:
        # names that never matched the detected segments (the engine dropped them): the
        # segments are still those every analysis used
        rest = {k: v for k, v in (config or {}).items() if k != "segment_names"}
        return _derived(bvh, rest) if config and "segment_names" in config else None
    except (InvalidInput, OSError):
        return None


def upgrade() -> None:
    conn = op.get_bind()
    for row in conn.execute(sa.select(REFERENCES)).all():
        derived = _derived(Path(row.bvh_path), row.domain_config)
        if derived is None:
            continue
        conn.execute(REFERENCES.update().where(REFERENCES.c.id == row.id).values(derived=derived))


def downgrade() -> None:
    """Nothing to undo in the schema; the re-derived descriptions stay."""
