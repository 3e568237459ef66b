from tests.app.conftest import make_club


def test_health_needs_no_key(client):
    r = client.get("/api/v1/health")
    assert r.status_code == 200
    assert r.json()["database"] == "ok"


def test_missing_key_is_401_with_the_error_shape(client, club):
    r = client.get("/api/v1/references")
    assert r.status_code == 401
    assert r.json()["error"]["code"] == "unauthorized"
    assert set(r.json()["error"]) == {"code", "message", "details"}


def test_wrong_key_is_401(client, club):
    assert client.get("/api/v1/references", headers={"X-API-Key": "mc_nope"}).status_code == 401


def test_keys_are_shown_once_listed_by_prefix_and_revocable(client, club):
    r = client.post("/api/v1/keys", headers=club.headers, json={"name": "ci"})
    assert r.status_code == 201
    new = r.json()
    assert new["key"].startswith(new["prefix"])
    listed = client.get("/api/v1/keys", headers=club.headers).json()["items"]
    assert [k["prefix"] for k in listed if k["id"] == new["id"]] == [new["prefix"]]
    assert all("key" not in k for k in listed)
    new_headers = {"X-API-Key": new["key"]}
    assert client.get("/api/v1/references", headers=new_headers).status_code == 200
    assert client.delete(f"/api/v1/keys/{new['id']}", headers=club.headers).status_code == 204
    r = client.get("/api/v1/references", headers=new_headers)
    assert r.status_code == 401
    assert "revoked" in r.json()["error"]["message"]


def test_other_clubs_keys_are_404(client, app, club):
    other = make_club(app, "beta")
    keys = client.get("/api/v1/keys", headers=other.headers).json()["items"]
    r = client.delete(f"/api/v1/keys/{keys[0]['id']}", headers=club.headers)
    assert r.status_code == 404


def test_rate_limit_gives_429_with_retry_after(client, app, club):
    from app.core.ratelimit import RateLimiter

    app.state.rate_limiter = RateLimiter(rate_per_s=0.01, burst=3)
    codes = [client.get("/api/v1/keys", headers=club.headers).status_code for _ in range(4)]
    assert codes == [200, 200, 200, 429]
    r = client.get("/api/v1/keys", headers=club.headers)
    assert r.json()["error"]["code"] == "rate_limited"
    assert int(r.headers["Retry-After"]) >= 1


def test_unknown_path_and_bad_input_use_the_error_shape(client, club):
    r = client.get("/api/v1/nothing-here")
    assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"
    r = client.get("/api/v1/analyses?limit=5000", headers=club.headers)
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_request"
    r = client.post("/api/v1/performers", headers=club.headers, json={"email": "x"})
    assert r.status_code == 422 and r.json()["error"]["details"]["errors"]


def test_browser_session_sign_in(client, app, club):
    from app import crud

    with app.state.sessionmaker() as s:
        crud.create_user(
            s, club_id=club.id, role="coach", email="c@alpha.org", display_name="C",
            password="a long password",
        )  # fmt: skip
    assert client.get("/api/v1/session").status_code == 401
    bad = {"email": "c@alpha.org", "password": "wrong password"}
    assert client.post("/api/v1/session", json=bad).status_code == 401
    good = {"email": "c@alpha.org", "password": "a long password"}
    assert client.post("/api/v1/session", json=good).status_code == 200
    assert client.get("/api/v1/session").json()["role"] == "coach"
    assert client.delete("/api/v1/session").status_code == 204
    assert client.get("/api/v1/session").status_code == 401


def test_cors_is_closed_by_default(client):
    r = client.options(
        "/api/v1/health",
        headers={"Origin": "https://evil.example", "Access-Control-Request-Method": "GET"},
    )
    assert "access-control-allow-origin" not in r.headers


def test_metrics_are_prometheus_text_for_the_operators_token_only(client, settings, club):
    from worker import metrics

    metrics.configure(settings.data_dir / "metrics")
    try:
        metrics.inc("coach_analyses_total", state="done")
    finally:
        metrics.configure(None)
    assert client.get("/api/v1/metrics").status_code == 404  # off without a token
    client.app.state.settings.metrics_token = "scrape-me-please-0123"
    assert client.get("/api/v1/metrics").status_code == 401
    assert client.get("/api/v1/metrics", headers=club.headers).status_code == 401  # not a club's
    r = client.get("/api/v1/metrics", headers={"Authorization": "Bearer scrape-me-please-0123"})
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("text/plain")
    assert 'coach_analyses_total{state="done"} 1' in r.text


def test_the_embedded_worker_uses_every_core_by_default():
    import os

    from app.core.config import Settings

    assert Settings().worker_concurrency == len(os.sched_getaffinity(0))
