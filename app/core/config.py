"""Service settings: environment variables prefixed ``COACH_`` (``COACH_DATA_DIR``, ...)."""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

#: Placeholder secrets found in examples; refused in every environment, since anyone can
#: sign a session cookie with them.
PLACEHOLDER_SECRETS = frozenset({"changethis", "change-me", "changeme", "secret", "dev"})
#: Shortest secret accepted from the environment (a generated one has 64 characters).
MIN_SECRET_CHARS = 16


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="COACH_", env_file=".env", extra="ignore")

    environment: Literal["development", "staging", "production"] = "development"
    data_dir: Path = Path("./data")
    #: Any SQLAlchemy URL; empty means a SQLite file ``coach.db`` in the data dir.
    database_url: str = ""
    #: Signs browser session cookies. Empty (the default): a random secret generated at first
    #: start and kept in ``<data_dir>/secret_key`` (app.core.security.stored_secret).
    secret_key: str = ""
    #: "embedded" runs a local worker without Redis (``coach serve``); else a Celery broker URL.
    broker_url: str = "embedded"
    #: Processes of the embedded worker (``coach serve``): one per core, so an analysis' stage-3
    #: parts run side by side.
    worker_concurrency: int = Field(
        default_factory=lambda: len(os.sched_getaffinity(0)), ge=1, le=64
    )
    #: Engine settings preset sent with every analysis ("fast" for demos and tests); "" = default.
    engine_preset: str = ""
    #: Bearer token of ``GET /api/v1/metrics`` (the operator's scraper); empty turns them off.
    metrics_token: str = ""
    #: Browser origins allowed by CORS; empty (the default) allows none.
    cors_origins: list[str] = []

    # Input limits.
    max_video_bytes: int = Field(default=200 * 1024 * 1024, gt=0)
    max_video_duration_s: float = Field(default=60.0, gt=0)
    max_bvh_bytes: int = Field(default=20 * 1024 * 1024, gt=0)
    #: BVH references beyond these are refused while they are read (engine.io.bvh.BvhLimits):
    #: 10 minutes at 60 fps; nodes with end sites (a Mixamo body with fingers has about 90).
    max_reference_frames: int = Field(default=36_000, gt=0)
    max_reference_joints: int = Field(default=256, gt=0)
    max_reference_duration_s: float = Field(default=600.0, gt=0)
    #: A reference built from takes keeps the expert's spread per frame in its domain
    #: (16 numbers a frame: ~100 KB for 10 s at 120 fps), so a domain may be this large.
    max_domain_bytes: int = Field(default=1024 * 1024, gt=0)
    #: Most takes one reference may be built from (every pair is synchronised).
    max_reference_takes: int = Field(default=12, ge=2)
    max_page_size: int = Field(default=100, ge=1, le=1000)
    #: An upload left in ``tmp/`` this long is from a process that died; removed at start.
    stale_upload_s: float = Field(default=3600.0, gt=0)
    #: Extra bytes a multipart body may carry beyond the file (boundaries, other fields).
    multipart_overhead_bytes: int = 64 * 1024

    # Per-key rate limit (token bucket): sustained requests per second and burst size.
    rate_limit_per_s: float = Field(default=5.0, gt=0)
    rate_limit_burst: int = Field(default=60, ge=1)
    #: Redis URL where every API process keeps the rate limits and sign-in throttles, so N
    #: processes do not give an attacker N times the attempts. Empty: the broker's URL when
    #: it is Redis, else each process keeps its own in memory (``coach serve``: one process).
    limits_url: str = ""

    # Progress reflection and server-sent events.
    sse_poll_s: float = Field(default=0.5, gt=0)
    sse_max_s: float = Field(default=3600.0, gt=0)
    #: Seconds between background syncs of running analyses (fires webhooks, and recovery:
    #: app.core.recovery); 0 disables.
    reflect_interval_s: float = Field(default=2.0, ge=0)
    #: Recovery: an analysis whose heartbeat is this old is run by nobody and is queued again
    #: (the workers read the same COACH_LOST_AFTER_S); one whose message the broker does not
    #: hold, or was never published, is queued again after publish_grace_s.
    lost_after_s: float = Field(default=60.0, gt=0)
    publish_grace_s: float = Field(default=30.0, gt=0)

    # Webhooks: bounded retries with exponential backoff.
    webhook_attempts: int = Field(default=5, ge=1, le=20)
    webhook_backoff_s: float = Field(default=2.0, ge=0)
    webhook_timeout_s: float = Field(default=10.0, gt=0)
    #: Lets webhooks go to private, loopback and link-local addresses (tests, a receiver on
    #: the same host). Off, a club cannot make the service call its internal network.
    webhook_allow_private: bool = False

    session_max_age_s: int = 14 * 24 * 3600
    # Sign-in throttle: free failures per account and per client address, then a lock that
    # doubles with each further failure, from signin_backoff_s up to signin_max_lock_s.
    signin_free_per_account: int = Field(default=5, ge=1)
    signin_free_per_ip: int = Field(default=20, ge=1)
    signin_backoff_s: float = Field(default=1.0, gt=0)
    signin_max_lock_s: float = Field(default=900.0, gt=0)

    @property
    def shared_limits_url(self) -> str | None:
        """Where the limits are shared (app.core.ratelimit), None for in-process ones."""
        url = self.limits_url or self.broker_url
        return url if url.startswith(("redis://", "rediss://", "unix://")) else None

    @property
    def sqlalchemy_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'coach.db').resolve()}"

    @property
    def is_development(self) -> bool:
        return self.environment == "development"

    @model_validator(mode="after")
    def _refuse_weak_secrets(self) -> Settings:
        if not self.secret_key:
            return self
        if (
            self.secret_key.lower() in PLACEHOLDER_SECRETS
            or len(self.secret_key) < MIN_SECRET_CHARS
        ):
            raise ValueError(
                "COACH_SECRET_KEY is a placeholder or shorter than "
                f"{MIN_SECRET_CHARS} characters: anyone could sign a session with it. Set a "
                "random one (python -c 'import secrets; print(secrets.token_urlsafe(48))') "
                "or leave it unset to have one generated in the data directory"
            )
        return self


@lru_cache
def get_settings() -> Settings:
    return Settings()
