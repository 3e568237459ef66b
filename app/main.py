"""Builds the FastAPI application: ``create_app(settings)``.

``uvicorn --factory app.main:create_app`` or ``coach serve``. The app runs the database
migrations when it is built, keeps its resources on ``app.state`` and starts the background
reflector (worker progress -> database -> webhooks) for its lifetime.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from functools import partial
from importlib.metadata import entry_points

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import HTMLResponse
from starlette.middleware.sessions import SessionMiddleware

from app.api import errors
from app.api.middleware import (
    API_PREFIX,
    BodyLimitMiddleware,
    CrossOriginGuard,
    SecurityHeadersMiddleware,
)
from app.api.routes import api_router
from app.core import recovery
from app.core.config import Settings, get_settings
from app.core.db import make_engine, make_sessionmaker, run_migrations
from app.core.queue import get_queue
from app.core.ratelimit import limits_for
from app.core.reflect import Notifier, Reflector
from app.core.security import stored_secret
from app.core.storage import Storage

log = logging.getLogger("app")

def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or get_settings()
    storage = Storage(settings.data_dir)
    if removed := storage.clean_tmp(older_than_s=settings.stale_upload_s):
        log.info("storage.tmp_cleaned uploads=%d", removed)
    engine = make_engine(settings.sqlalchemy_url)
    run_migrations(engine)
    sessions = make_sessionmaker(engine)
    notifier = Notifier(settings, sessions)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        reflector = None
        if settings.reflect_interval_s > 0:
            # Each tick also queues lost analyses again (app.core.recovery).
            recover = partial(recovery.recover, settings=settings, queue=get_queue())
            reflector = Reflector(sessions, notifier, settings.reflect_interval_s, recover)
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
        docs_url=None,  # served from the swagger-ui-bundle wheel below, not from a CDN
        redoc_url=None,
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.engine = engine
    app.state.sessionmaker = sessions
    app.state.storage = storage
    app.state.notifier = notifier
    app.state.rate_limiter, app.state.signin_throttle = limits_for(settings)

    errors.install(app)
    app.include_router(api_router, prefix=API_PREFIX)
    _offline_docs(app)
    _mount_declared(app)
    _document_page_size(app, settings.max_page_size)

    # Outermost last: body limits run first, then CORS (closed unless origins are set).
    app.add_middleware(
        SessionMiddleware,
        secret_key=settings.secret_key or stored_secret(settings.data_dir),
        session_cookie="coach_session",
        max_age=settings.session_max_age_s,
        same_site="lax",
        https_only=not settings.is_development,
    )
    app.add_middleware(
        CORSMiddleware,
        allow_origins=settings.cors_origins,
        allow_methods=["GET", "POST", "PUT", "PATCH", "DELETE"],
        allow_headers=["X-API-Key", "Authorization", "Content-Type", "Idempotency-Key"],
        allow_credentials=False,
    )
    app.add_middleware(CrossOriginGuard, settings=settings)
    app.add_middleware(SecurityHeadersMiddleware, settings=settings)
    app.add_middleware(BodyLimitMiddleware, settings=settings)
    return app


#: Entry-point group of the packages that add routes to the app (pyproject.toml declares the
#: web pages' ``web.routes:register``); the app itself imports none of them.
MOUNTS = "coach.mounts"


def _offline_docs(app: FastAPI) -> None:
    """Swagger UI at ``/api/v1/docs`` with its assets from the swagger-ui-bundle wheel, so
    the API docs work offline (FastAPI's default loads them from a CDN)."""
    import swagger_ui_bundle
    from fastapi.openapi.docs import get_swagger_ui_html
    from fastapi.staticfiles import StaticFiles

    assets = f"{API_PREFIX}/docs-assets"
    app.mount(assets, StaticFiles(directory=swagger_ui_bundle.swagger_ui_path), name="docs")

    @app.get(f"{API_PREFIX}/docs", include_in_schema=False)
    def docs() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=app.openapi_url or "", title=f"{app.title} API",
            swagger_js_url=f"{assets}/swagger-ui-bundle.js",
            swagger_css_url=f"{assets}/swagger-ui.css",
            swagger_favicon_url=f"{assets}/favicon-32x32.png",
        )  # fmt: skip


def _mount_declared(app: FastAPI) -> None:
    """Call every declared ``register(app)`` (``coach.mounts``), in name order."""
    for ep in sorted(entry_points(group=MOUNTS), key=lambda e: e.name):
        ep.load()(app)


def _document_page_size(app: FastAPI, max_page_size: int) -> None:
    """The OpenAPI document states this deployment's page size limit (``limit``'s maximum),
    which the route signatures cannot: it is a setting, checked in ``get_page``."""
    build = app.openapi

    def openapi() -> dict:
        if app.openapi_schema is not None:
            return app.openapi_schema
        doc = build()  # FastAPI keeps it as app.openapi_schema: edited once, here
        for operation in (op for path in doc["paths"].values() for op in path.values()):
            for p in operation.get("parameters", []):
                if p.get("in") == "query" and p.get("name") == "limit":
                    p["schema"]["maximum"] = max_page_size
        return doc

    app.openapi = openapi  # type: ignore[method-assign]

