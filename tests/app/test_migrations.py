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


def test_references_get_the_segments_their_analyses_use(tmp_path, cmu_bvh):
    """0004: a reference stored before it keeps its coach's starts, now as the engine's."""
    import json
    from datetime import UTC, datetime

    from alembic import command
    from sqlalchemy import text

    from app.core.db import alembic_config

    engine = make_engine(f"sqlite:///{tmp_path / 'old.db'}")
    cfg = alembic_config(engine.url.render_as_string(hide_password=False))
    with engine.begin() as conn:
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "0003")
    domain_file = tmp_path / "reference.domain.json"
    domain_file.write_text("{}")  # before 0004 the starts were kept out of the engine's file
    old = {"segments": [1, 200, 400], "segment_names": ["a", "b", "c"]}
    now = datetime.now(UTC).isoformat()
    with engine.begin() as conn:
        club = text("INSERT INTO clubs (id, name, created_at) VALUES (1, 'c', :t)")
        conn.execute(club, {"t": now})
        for rid, bvh, dom, cfg_json in (
            (1, str(cmu_bvh), str(domain_file), json.dumps(old)),
            (2, str(cmu_bvh), None, None),
            (3, str(tmp_path / "gone.bvh"), None, None),
        ):
            conn.execute(
                text(
                    'INSERT INTO "references" (id, club_id, name, bvh_path, domain_path, '
                    "domain_config, derived, created_at) VALUES (:i, 1, 'r', :b, :d, :c, :v, :t)"
                ),
                {"i": rid, "b": bvh, "d": dom, "c": cfg_json, "v": '{"segments": []}', "t": now},
            )
    run_migrations(engine)
    with engine.connect() as conn:
        rows = conn.execute(text('SELECT id, derived FROM "references" ORDER BY id')).all()
    derived = {i: json.loads(d) for i, d in rows}
    assert derived[1]["segments"] == [1, 200, 400, 579]  # the coach's starts, then the end
    assert len(derived[2]["segments"]) == 4  # 64_29's three detected segments
    assert derived[3] == {"segments": []}  # its BVH is gone: left as it was
    # 0005: the domain lives only in domain_config; the file beside the BVH and its column go
    assert not domain_file.exists()
    with engine.connect() as conn:
        columns = [c[1] for c in conn.execute(text('PRAGMA table_info("references")')).all()]
        config = conn.execute(text('SELECT domain_config FROM "references" WHERE id = 1')).scalar()
    assert "domain_path" not in columns and json.loads(config) == old
