"""Builds the FastAPI application: ``create_app(settings)``.

``uvicorn --factory app.main:create_app`` or ``coach serve``. The app runs the database
migrations when it is built, keeps its resources on ``app.state`` and starts the background
reflector (worker progress -> database -> webhooks) for its lifetime.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import entry_points

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from starlette.middleware.sessions import SessionMiddleware
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.api import errors
from app.api.routes import api_router
from app.core.config import Settings, get_settings
from app.core.db import make_engine, make_sessionmaker, run_migrations
from app.core.ratelimit import RateLimiter
from app.core.reflect import Notifier, Reflector
from app.core.storage import Storage

log = logging.getLogger("app")

API_PREFIX = "/api/v1"
#: Body limit for requests that carry no file (JSON, forms).
SMALL_BODY_BYTES = 1024 * 1024


class _BodyTooLarge(Exception):
    pass


class BodyLimitMiddleware:
    """Refuses request bodies over a per-route limit with 413, before they are parsed.

    Checks Content-Length up front and counts the bytes of bodies sent without it, so a
    client cannot make the multipart parser spool an unbounded upload.
    """

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        extra = settings.multipart_overhead_bytes
        self.limits = {
            f"{API_PREFIX}/analyses": settings.max_video_bytes + extra,
            f"{API_PREFIX}/references": settings.max_bvh_bytes + settings.max_domain_bytes + extra,
        }

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] in ("GET", "HEAD", "OPTIONS"):
            await self.app(scope, receive, send)
            return
        limit = self.limits.get(scope["path"].rstrip("/"), SMALL_BODY_BYTES)
        headers = dict(scope.get("headers") or [])
        declared = headers.get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            await self._refuse(send, limit)
            return
        received = 0
        started = False

        async def counting_receive() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    raise _BodyTooLarge
            return message

        async def tracking_send(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counting_receive, tracking_send)
        except _BodyTooLarge:
            if not started:
                await self._refuse(send, limit)

    @staticmethod
    async def _refuse(send: Send, limit: int) -> None:
        response = errors.error_response(
            413, "too_large", f"the request body is larger than the limit of {limit} bytes",
            {"limit_bytes": limit},
        )  # fmt: skip
        await send(
            {
                "type": "http.response.start",
                "status": 413,
                "headers": [(k.encode(), v.encode()) for k, v in response.headers.items()],
            }
        )
        await send({"type": "http.response.body", "body": response.body})


class SecurityHeadersMiddleware:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                message.setdefault("headers", [])
                message["headers"] = list(message["headers"]) + [
                    (b"x-content-type-options", b"nosniff"),
                    (b"referrer-policy", b"same-origin"),
                    (b"x-frame-options", b"SAMEORIGIN"),
                ]
            await send(message)

        await self.app(scope, receive, send_with_headers if scope["type"] == "http" else send)


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or get_settings()
    storage = Storage(settings.data_dir)
    engine = make_engine(settings.sqlalchemy_url)
    run_migrations(engine)
    sessions = make_sessionmaker(engine)
    notifier = Notifier(settings, sessions)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        reflector = None
        if settings.reflect_interval_s > 0:
            reflector = Reflector(sessions, notifier, settings.reflect_interval_s)
            reflector.start()
        try:
            yield
        finally:
            if reflector is not None:
                reflector.stop()
            notifier.wait(timeout=2.0)

    app = FastAPI(
        title="Motion coach",
        version="1",
        summary="Register a performer's video against an expert's 3D reference motion.",
        openapi_url=f"{API_PREFIX}/openapi.json",
        docs_url=f"{API_PREFIX}/docs",
        redoc_url=None,
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.engine = engine
    app.state.sessionmaker = sessions
    app.state.storage = storage
    app.state.notifier = notifier
    app.state.rate_limiter = RateLimiter(settings.rate_limit_per_s, settings.rate_limit_burst)

    errors.install(app)
    app.include_router(api_router, prefix=API_PREFIX)
    _mount_declared(app)

    # Outermost last: body limits run first, then CORS (closed unless origins are set).
    app.add_middleware(
        SessionMiddleware,
        secret_key=settings.secret_key,
        session_cookie="coach_session",
        max_age=settings.session_max_age_s,
        same_site="lax",
        https_only=not settings.is_development,
    )
    app.add_middleware(
        CORSMiddleware,
        allow_origins=settings.cors_origins,
        allow_methods=["GET", "POST", "PUT", "PATCH", "DELETE"],
        allow_headers=["X-API-Key", "Content-Type", "Idempotency-Key"],
        allow_credentials=False,
    )
    app.add_middleware(SecurityHeadersMiddleware)
    app.add_middleware(BodyLimitMiddleware, settings=settings)
    return app


#: Entry-point group of the packages that add routes to the app (pyproject.toml declares the
#: web pages' ``web.routes:register``); the app itself imports none of them.
MOUNTS = "coach.mounts"


def _mount_declared(app: FastAPI) -> None:
    """Call every declared ``register(app)`` (``coach.mounts``), in name order."""
    for ep in sorted(entry_points(group=MOUNTS), key=lambda e: e.name):
        ep.load()(app)
