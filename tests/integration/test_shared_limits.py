"""Rate limits and sign-in throttles shared by several API processes through a real Redis
(issue 26: N processes must not give an attacker N times the attempts), and what happens
while that Redis is down (limits per process, never a 500 or a lock-out of everybody)."""

from __future__ import annotations

import pytest
import redis
from fastapi.testclient import TestClient

from app import crud
from app.core.config import Settings
from app.core.ratelimit import RedisRateLimiter, RedisSignInThrottle, limits_for
from app.main import create_app

PASSWORD = "correct horse battery"
EMAIL = "coach@alpha.org"


def settings_for(data_dir, url: str, **extra) -> Settings:
    return Settings(data_dir=data_dir, reflect_interval_s=0, limits_url=url, **extra)


@pytest.fixture
def two_apps(tmp_path, redis_url):
    """Two API processes' apps on one database and one Redis, and a coach and an API key."""
    redis.Redis.from_url(redis_url).flushdb()
    apps = [
        create_app(settings_for(tmp_path / "data", redis_url, rate_limit_per_s=0.01,
                                rate_limit_burst=3))
        for _ in range(2)
    ]  # fmt: skip
    with apps[0].state.sessionmaker() as session:
        club = crud.create_club(session, name="alpha")
        session.commit()
        _, key = crud.create_api_key(session, club_id=club.id, name="test")
        crud.create_user(
            session, club_id=club.id, role="coach", email=EMAIL, display_name="Coach",
            password=PASSWORD,
        )  # fmt: skip
    with TestClient(apps[0]) as a, TestClient(apps[1]) as b:
        yield a, b, key


def sign_in(client: TestClient, password: str = PASSWORD, email: str = EMAIL) -> int:
    return client.post("/api/v1/session", json={"email": email, "password": password}).status_code


def test_limits_are_shared_when_a_redis_url_is_given(tmp_path, redis_url):
    rate, throttle = limits_for(settings_for(tmp_path, redis_url))
    assert isinstance(rate, RedisRateLimiter) and isinstance(throttle, RedisSignInThrottle)
    # the broker's Redis is used when no limits URL is given; embedded mode keeps them in memory
    rate, _ = limits_for(Settings(data_dir=tmp_path, broker_url=redis_url))
    assert isinstance(rate, RedisRateLimiter)
    rate, throttle = limits_for(Settings(data_dir=tmp_path))
    assert type(rate).__name__ == "RateLimiter" and type(throttle).__name__ == "SignInThrottle"


def test_failures_on_one_process_lock_the_account_on_the_other(two_apps, redis_url):
    a, b, _ = two_apps
    free = a.app.state.settings.signin_free_per_account
    codes = [sign_in(a if i % 2 else b, password=f"guess {i}") for i in range(free)]
    assert codes == [401] * free
    # Per process, each would still have free attempts left; shared, the account is locked.
    r = b.post("/api/v1/session", json={"email": EMAIL, "password": PASSWORD})
    assert r.status_code == 429 and int(r.headers["Retry-After"]) >= 1
    assert sign_in(a) == 429
    # Redis holds hashed keys only, never the email address
    names = [k.decode() for k in redis.Redis.from_url(redis_url).keys("coach:signin:*")]
    assert names and not any("alpha" in n for n in names)


def test_an_api_key_has_one_bucket_across_processes(two_apps):
    a, b, key = two_apps
    headers = {"X-API-Key": key}
    codes = [(a if i % 2 else b).get("/api/v1/references", headers=headers).status_code
             for i in range(4)]  # fmt: skip
    assert codes == [200, 200, 200, 429]  # burst 3 in all, not 3 per process


def test_a_right_password_on_one_process_clears_the_account_on_both(two_apps):
    a, b, _ = two_apps
    free = a.app.state.settings.signin_free_per_account
    for i in range(free - 1):
        assert sign_in(a, password=f"guess {i}") == 401
    assert sign_in(b) == 200  # clears the account's count
    for i in range(free - 1):  # as many again are free, on either process
        assert sign_in(b, password=f"again {i}") == 401
    assert sign_in(a) == 200


def test_with_redis_down_limits_hold_per_process_and_nothing_fails(tmp_path, own_redis):
    app = create_app(settings_for(tmp_path / "data", own_redis.url))
    with app.state.sessionmaker() as session:
        club = crud.create_club(session, name="alpha")
        session.commit()
        crud.create_user(
            session, club_id=club.id, role="coach", email=EMAIL, display_name="Coach",
            password=PASSWORD,
        )  # fmt: skip
    own_redis.stop()
    with TestClient(app) as client:
        assert sign_in(client) == 200
        free = app.state.settings.signin_free_per_account
        codes = [sign_in(client, password=f"guess {i}") for i in range(free + 1)]
        assert codes[:free] == [401] * free and codes[-1] == 429
        # and once Redis is back, the shared counts are used again (it is empty: not locked)
        own_redis.start()
        assert sign_in(client) == 200
