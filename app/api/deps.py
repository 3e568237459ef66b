"""Dependencies as ``Annotated`` aliases: ``SessionDep``, ``CurrentClub``, ``QueueDep``, ..."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Query, Request, Security
from fastapi.security import APIKeyHeader
from sqlalchemy.orm import Session

from app import crud
from app.api.errors import ApiError
from app.core.config import Settings
from app.core.queue import JobQueue, get_queue
from app.core.ratelimit import RateLimiter
from app.core.reflect import Notifier
from app.core.storage import Storage
from app.models import ApiKey, Club, User


def get_settings_dep(request: Request) -> Settings:
    return request.app.state.settings


def get_db(request: Request) -> Iterator[Session]:
    with request.app.state.sessionmaker() as session:
        yield session


def get_storage(request: Request) -> Storage:
    return request.app.state.storage


def get_notifier(request: Request) -> Notifier:
    return request.app.state.notifier


SettingsDep = Annotated[Settings, Depends(get_settings_dep)]
SessionDep = Annotated[Session, Depends(get_db)]
StorageDep = Annotated[Storage, Depends(get_storage)]
QueueDep = Annotated[JobQueue, Depends(get_queue)]
NotifierDep = Annotated[Notifier, Depends(get_notifier)]

api_key_header = APIKeyHeader(
    name="X-API-Key", auto_error=False, description="A club API key (POST /api/v1/keys)."
)


def get_current_key(
    request: Request,
    session: SessionDep,
    key: Annotated[str | None, Security(api_key_header)],
) -> ApiKey:
    if not key:
        raise ApiError(
            401, "unauthorized", "an X-API-Key header is required",
            headers={"WWW-Authenticate": "X-API-Key"},
        )  # fmt: skip
    row = crud.get_active_api_key(session, key[:200])
    if row is None:
        raise ApiError(
            401, "unauthorized", "the API key is not valid or was revoked",
            headers={"WWW-Authenticate": "X-API-Key"},
        )  # fmt: skip
    limiter: RateLimiter = request.app.state.rate_limiter
    wait = limiter.take(row.id)
    if wait > 0:
        retry = limiter.retry_after(wait)
        raise ApiError(
            429, "rate_limited", f"too many requests for this key; retry in {retry} s",
            {"retry_after_s": retry}, headers={"Retry-After": str(retry)},
        )  # fmt: skip
    crud.touch_api_key(session, row)
    return row


CurrentKey = Annotated[ApiKey, Depends(get_current_key)]


def get_current_club(session: SessionDep, key: CurrentKey) -> Club:
    club = crud.get_club(session, key.club_id)
    if club is None:  # the key outlived its club (cascade should prevent this)
        raise ApiError(401, "unauthorized", "the API key's club no longer exists")
    return club


CurrentClub = Annotated[Club, Depends(get_current_club)]


def get_current_user(request: Request, session: SessionDep) -> User:
    """The browser user signed in through ``POST /api/v1/session`` (signed session cookie)."""
    user_id = request.session.get("user_id")
    user = crud.get_user(session, int(user_id)) if isinstance(user_id, int) else None
    if user is None:
        raise ApiError(401, "unauthorized", "sign in first")
    return user


CurrentUser = Annotated[User, Depends(get_current_user)]


@dataclass(frozen=True)
class Page:
    limit: int
    offset: int


def get_page(
    settings: SettingsDep,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size.")] = 20,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
) -> Page:
    if limit > settings.max_page_size:
        raise ApiError(
            422, "invalid_request", f"limit: at most {settings.max_page_size} items per page",
            {"max_page_size": settings.max_page_size},
        )  # fmt: skip
    return Page(limit=limit, offset=offset)


PageDep = Annotated[Page, Depends(get_page)]
