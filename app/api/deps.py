"""Dependencies as ``Annotated`` aliases: ``SessionDep``, ``CurrentClub``, ``QueueDep``, ..."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import Depends, Query, Request, Security
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session

from app import crud
from app.api.errors import ApiError, invalid, rate_limited
from app.core import sessions
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
bearer_header = HTTPBearer(
    auto_error=False, description="The same API key as `Authorization: Bearer <key>`."
)


def _check_key(request: Request, session: Session, key: str, scheme: str) -> ApiKey:
    """The active API key ``key``, rate limited; 401 or 429 otherwise."""
    row = crud.get_active_api_key(session, key[:200])
    if row is None:
        raise ApiError(
            401, "unauthorized", "the API key is not valid or was revoked",
            headers={"WWW-Authenticate": scheme},
        )  # fmt: skip
    limiter: RateLimiter = request.app.state.rate_limiter
    wait = limiter.take(row.id)
    if wait > 0:
        raise rate_limited(wait, "too many requests for this key")
    crud.touch_api_key(session, row)
    return row


def _signed_in(request: Request, session: Session) -> User | None:
    """The browser user signed in through ``POST /api/v1/session`` (signed session cookie)."""
    return sessions.current_user(request, session)


@dataclass(frozen=True)
class Principal:
    """Who calls: a club's API key (acts as the club's coach), or a signed-in user.

    Every route scopes its queries through this: to ``club`` always, and for a performer to
    their own rows (:attr:`own_performer_id`).
    """

    club: Club
    user: User | None = None

    @property
    def is_coach(self) -> bool:
        return self.user is None or self.user.role == "coach"

    @property
    def own_performer_id(self) -> int | None:
        """The performer whose rows alone this caller may see (None: the whole club)."""
        return None if self.is_coach or self.user is None else self.user.id

    def require_coach(self) -> None:
        if not self.is_coach:
            raise ApiError(403, "forbidden", "only a coach may do this")

    def require_user(self) -> User:
        """The signed-in user, for what a person does (comments, invites)."""
        if self.user is None:
            raise ApiError(403, "forbidden", "sign in as a person to do this")
        return self.user


def get_principal(
    request: Request,
    session: SessionDep,
    key: Annotated[str | None, Security(api_key_header)],
    bearer: Annotated[HTTPAuthorizationCredentials | None, Security(bearer_header)],
) -> Principal:
    """An API key (``X-API-Key`` or ``Authorization: Bearer``), else the session cookie; 401
    without either. A key that is sent but wrong is a 401, never a fall back to the cookie."""
    token = bearer.credentials if bearer is not None else None
    if key and token and key != token:
        raise ApiError(
            401, "unauthorized", "X-API-Key and Authorization: Bearer name different keys",
            headers={"WWW-Authenticate": "Bearer"},
        )  # fmt: skip
    if key or token:
        row = _check_key(request, session, key or token or "", "X-API-Key" if key else "Bearer")
        club = crud.get_club(session, row.club_id)
        if club is None:  # the key outlived its club (cascade should prevent this)
            raise ApiError(401, "unauthorized", "the API key's club no longer exists")
        return Principal(club)
    user = _signed_in(request, session)
    if user is None:
        raise ApiError(
            401, "unauthorized",
            "an API key (X-API-Key or Authorization: Bearer) or a signed-in session is required",
            headers={"WWW-Authenticate": "X-API-Key"},
        )  # fmt: skip
    return principal_of(session, user)


def principal_of(session: Session, user: User) -> Principal:
    """A signed-in user as a principal (the pages use it too, so they see what the API
    shows); 401 when their club is gone."""
    club = crud.get_club(session, user.club_id)
    if club is None:
        raise ApiError(401, "unauthorized", "your club no longer exists")
    return Principal(club, user)


CurrentPrincipal = Annotated[Principal, Depends(get_principal)]


def get_coach(principal: CurrentPrincipal) -> Principal:
    principal.require_coach()
    return principal


#: A caller with a coach's rights: an API key or a signed-in coach (403 for a performer).
CurrentCoach = Annotated[Principal, Depends(get_coach)]


def get_coach_club(who: CurrentCoach) -> Club:
    return who.club


#: The club of a caller with a coach's rights (club settings, keys, performers).
CoachClub = Annotated[Club, Depends(get_coach_club)]


def get_current_user(request: Request, session: SessionDep) -> User:
    """The signed-in user (session cookie); 401 when nobody is."""
    user = _signed_in(request, session)
    if user is None:
        raise ApiError(401, "unauthorized", "sign in first")
    return user


CurrentUser = Annotated[User, Depends(get_current_user)]


#: The largest page size a server may be configured for (``Settings.max_page_size``).
MAX_PAGE_SIZE = 1000


@dataclass(frozen=True)
class Page:
    limit: int
    offset: int


def get_page(
    settings: SettingsDep,
    limit: Annotated[
        int,
        Query(
            ge=1,
            le=MAX_PAGE_SIZE,
            description=(
                "Items per page: 1 to the server's page size limit, `COACH_MAX_PAGE_SIZE` "
                f"(100 unless the operator changed it; never over {MAX_PAGE_SIZE}). A larger "
                "limit is refused with 422 giving the limit in `details.max_page_size`."
            ),
        ),
    ] = 20,
    offset: Annotated[int, Query(ge=0, le=1_000_000, description="Items to skip.")] = 0,
) -> Page:
    if limit > settings.max_page_size:
        raise invalid(
            "query.limit", f"at most {settings.max_page_size} items per page", "less_than_equal",
            max_page_size=settings.max_page_size,
        )  # fmt: skip
    return Page(limit=limit, offset=offset)


PageDep = Annotated[Page, Depends(get_page)]


#: For route decorators of creating routes: documents the ``Location`` of their 201.
CREATED: dict[int | str, dict[str, Any]] = {
    201: {
        "description": "Created",
        "headers": {
            "Location": {
                "description": "The path of the created resource.",
                "schema": {"type": "string"},
            }
        },
    }
}


def location(request: Request, route: str, **params: object) -> str:
    """The path of the resource a 201 created (its ``Location``), from its read route."""
    return request.app.url_path_for(route, **{k: str(v) for k, v in params.items()})
