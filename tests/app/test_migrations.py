from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import inspect

from app.core.db import make_engine, run_migrations
from app.models import Base


def test_migrations_create_the_schema_from_empty(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'empty.db'}")
    run_migrations(engine)
    tables = set(inspect(engine).get_table_names())
    assert {"clubs", "users", "api_keys", "references", "analyses", "alembic_version"} <= tables
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    assert diff == [], f"models and migrations disagree: {diff}"
    run_migrations(engine)  # idempotent at head
