from app import crud
from app.commands import DEMO_CLUB, seed
from app.models import ApiKey, Club, Reference, User


def test_seed_is_idempotent_and_prints_a_working_dev_key(app, client):
    printed = []
    for _ in range(2):
        with app.state.sessionmaker() as s:
            seed(s, app.state.settings, app.state.storage, out=printed.append)
    with app.state.sessionmaker() as s:
        assert s.query(Club).filter_by(name=DEMO_CLUB).count() == 1
        assert s.query(User).count() == 2
        assert s.query(Reference).count() <= 1
        active = [k for k in s.query(ApiKey) if k.revoked_at is None]
        assert len(active) == 1
        key = [line for line in printed if "API key" in line][-1].rsplit(" ", 1)[1]
        assert crud.get_active_api_key(s, key) is not None
    assert client.get("/api/v1/performers", headers={"X-API-Key": key}).status_code == 200
