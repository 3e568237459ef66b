"""Database reads and writes. Every query of club data filters by ``club_id``.

Functions return the row or None and never raise HTTP errors: the route decides.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import Select, func, select
from sqlalchemy.orm import Session

from app.core import security
from app.models import (
    Analysis,
    ApiKey,
    Capture,
    Club,
    Reference,
    User,
    WebhookEndpoint,
    utcnow,
)

#: last_used_at is written at most this often per key (one write per request is wasteful).
LAST_USED_RESOLUTION = timedelta(seconds=60)


# ---- clubs
def create_club(session: Session, *, name: str) -> Club:
    club = Club(name=name)
    session.add(club)
    session.flush()
    return club


def get_club(session: Session, club_id: int) -> Club | None:
    return session.get(Club, club_id)


def get_club_by_name(session: Session, name: str) -> Club | None:
    return session.scalars(select(Club).where(Club.name == name).limit(1)).first()


def update_club(
    session: Session, club: Club, *, name: str | None, webhook_url: str | None, rotate: bool
) -> str | None:
    """Apply an update; returns a newly generated webhook secret, if one was made."""
    new_secret = None
    if name is not None:
        club.name = name
    if webhook_url is not None:
        club.webhook_url = webhook_url or None
    if club.webhook_url and (rotate or not club.webhook_secret):
        club.webhook_secret = new_secret = security.new_webhook_secret()
    session.commit()
    return new_secret


# ---- webhook endpoints
def create_webhook_endpoint(
    session: Session, *, club_id: int, url: str, events: list[str], description: str
) -> WebhookEndpoint:
    row = WebhookEndpoint(
        club_id=club_id, url=url, events=events, description=description,
        secret=security.new_webhook_secret(),
    )  # fmt: skip
    session.add(row)
    session.commit()
    return row


def count_webhook_endpoints(session: Session, *, club_id: int) -> int:
    stmt = select(func.count()).where(WebhookEndpoint.club_id == club_id)
    return int(session.scalar(stmt) or 0)


def list_webhook_endpoints(
    session: Session, *, club_id: int, limit: int, offset: int
) -> tuple[list[WebhookEndpoint], int]:
    stmt = select(WebhookEndpoint).where(WebhookEndpoint.club_id == club_id)
    return page_of(session, stmt.order_by(WebhookEndpoint.id), limit=limit, offset=offset)


def get_webhook_endpoint(
    session: Session, *, club_id: int, endpoint_id: int
) -> WebhookEndpoint | None:
    return session.scalars(
        select(WebhookEndpoint).where(
            WebhookEndpoint.club_id == club_id, WebhookEndpoint.id == endpoint_id
        )
    ).first()


def update_webhook_endpoint(
    session: Session,
    row: WebhookEndpoint,
    *,
    url: str | None,
    events: list[str] | None,
    description: str | None,
    enabled: bool | None,
    rotate: bool,
) -> str | None:
    """Apply an update (None: unchanged); returns the new secret when ``rotate``."""
    if url is not None:
        row.url = url
    if events is not None:
        row.events = events
    if description is not None:
        row.description = description
    if enabled is not None and enabled == (row.disabled_at is not None):
        row.disabled_at = None if enabled else utcnow()
    new_secret = security.new_webhook_secret() if rotate else None
    if new_secret:
        row.secret = new_secret
    session.commit()
    return new_secret


def delete_webhook_endpoint(session: Session, row: WebhookEndpoint) -> None:
    session.delete(row)
    session.commit()


def webhook_targets(session: Session, *, club_id: int, event: str) -> list[tuple[str, str]]:
    """(url, secret) of every receiver of ``event`` in the club: its default webhook (every
    event) first, then its enabled endpoints that name the event."""
    club = session.get(Club, club_id)
    if club is None:
        return []
    targets: list[tuple[str, str]] = []
    if club.webhook_url and club.webhook_secret:
        targets.append((club.webhook_url, club.webhook_secret))
    stmt = select(WebhookEndpoint).where(
        WebhookEndpoint.club_id == club_id, WebhookEndpoint.disabled_at.is_(None)
    )
    # JSON containment differs per backend; a club has few endpoints, so filter here.
    targets += [(e.url, e.secret) for e in session.scalars(stmt.order_by(WebhookEndpoint.id))
                if event in e.events]  # fmt: skip
    return targets


# ---- API keys
def create_api_key(session: Session, *, club_id: int, name: str = "") -> tuple[ApiKey, str]:
    key, prefix, key_hash = security.new_api_key()
    row = ApiKey(club_id=club_id, name=name, prefix=prefix, key_hash=key_hash)
    session.add(row)
    session.commit()
    return row, key


def get_active_api_key(session: Session, key: str) -> ApiKey | None:
    row = session.scalars(
        select(ApiKey).where(ApiKey.key_hash == security.hash_api_key(key))
    ).first()
    if row is None or row.revoked_at is not None:
        return None
    return row


def touch_api_key(session: Session, row: ApiKey) -> None:
    now = utcnow()
    if row.last_used_at is None or now - row.last_used_at > LAST_USED_RESOLUTION:
        row.last_used_at = now
        session.commit()


def page_of(session: Session, stmt: Select, *, limit: int, offset: int) -> tuple[list, int]:
    """One page of ``stmt``'s rows and how many rows it has in all."""
    total = session.scalar(select(func.count()).select_from(stmt.order_by(None).subquery()))
    return list(session.scalars(stmt.limit(limit).offset(offset))), int(total or 0)


def list_api_keys(
    session: Session, *, club_id: int, limit: int = 1000, offset: int = 0
) -> tuple[list[ApiKey], int]:
    stmt = select(ApiKey).where(ApiKey.club_id == club_id).order_by(ApiKey.id)
    return page_of(session, stmt, limit=limit, offset=offset)


def get_api_key(session: Session, *, club_id: int, key_id: int) -> ApiKey | None:
    return session.scalars(
        select(ApiKey).where(ApiKey.club_id == club_id, ApiKey.id == key_id)
    ).first()


def revoke_api_key(session: Session, row: ApiKey) -> None:
    if row.revoked_at is None:
        row.revoked_at = utcnow()
        session.commit()


# ---- users
def create_user(
    session: Session,
    *,
    club_id: int,
    role: str,
    email: str,
    display_name: str,
    password: str | None = None,
) -> User:
    user = User(
        club_id=club_id,
        role=role,
        email=email.lower(),
        display_name=display_name,
        password_hash=security.hash_password(password) if password else None,
    )
    session.add(user)
    session.commit()
    return user


def get_user_by_email(session: Session, *, club_id: int, email: str) -> User | None:
    return session.scalars(
        select(User).where(User.club_id == club_id, User.email == email.lower())
    ).first()


def get_user(session: Session, user_id: int) -> User | None:
    return session.get(User, user_id)


def get_performer(session: Session, *, club_id: int, user_id: int) -> User | None:
    return session.scalars(
        select(User).where(User.club_id == club_id, User.id == user_id, User.role == "performer")
    ).first()


def list_performers(
    session: Session, *, club_id: int, limit: int, offset: int
) -> tuple[list[User], int]:
    stmt = select(User).where(User.club_id == club_id, User.role == "performer").order_by(User.id)
    return page_of(session, stmt, limit=limit, offset=offset)


def authenticate(session: Session, *, email: str, password: str) -> User | None:
    """The user with this email whose password matches (emails are unique per club)."""
    users = [u for u in session.scalars(select(User).where(User.email == email.lower()))
             if u.password_hash]  # fmt: skip
    if not users:  # as slow as a wrong password, so timing does not tell who has an account
        security.verify_nothing(password)
    for user in users:
        if security.verify_password(password, user.password_hash):
            return user
    return None


# ---- references
def create_reference(session: Session, *, club_id: int, name: str) -> Reference:
    """A row with an id (flushed, not committed) so files can be placed under it."""
    ref = Reference(club_id=club_id, name=name, bvh_path="", derived={})
    session.add(ref)
    session.flush()
    return ref


def get_reference(session: Session, *, club_id: int, reference_id: int) -> Reference | None:
    return session.scalars(
        select(Reference).where(Reference.club_id == club_id, Reference.id == reference_id)
    ).first()


def get_reference_by_name(session: Session, *, club_id: int, name: str) -> Reference | None:
    return session.scalars(
        select(Reference).where(Reference.club_id == club_id, Reference.name == name)
    ).first()


def list_references(
    session: Session, *, club_id: int, limit: int, offset: int
) -> tuple[list[Reference], int]:
    stmt = select(Reference).where(Reference.club_id == club_id).order_by(Reference.id)
    return page_of(session, stmt, limit=limit, offset=offset)


def reference_in_use(session: Session, reference: Reference) -> bool:
    stmt = select(func.count()).where(Analysis.reference_id == reference.id)
    return bool(session.scalar(stmt))


# ---- analyses
def get_analysis(session: Session, *, club_id: int, analysis_id: str) -> Analysis | None:
    return session.scalars(
        select(Analysis).where(Analysis.club_id == club_id, Analysis.id == analysis_id)
    ).first()


def get_analysis_by_idempotency_key(session: Session, *, club_id: int, key: str) -> Analysis | None:
    return session.scalars(
        select(Analysis).where(Analysis.club_id == club_id, Analysis.idempotency_key == key)
    ).first()


def list_analyses(
    session: Session,
    *,
    club_id: int,
    limit: int,
    offset: int,
    performer_id: int | None = None,
    reference_id: int | None = None,
    status: str | None = None,
    created_after: datetime | None = None,
    created_before: datetime | None = None,
    reviewed: bool | None = None,
) -> tuple[list[Analysis], int]:
    conditions: list[Any] = [Analysis.club_id == club_id]
    if reviewed is not None:
        conditions.append(Analysis.reviewed_at.is_not(None) if reviewed
                          else Analysis.reviewed_at.is_(None))  # fmt: skip
    if performer_id is not None:
        conditions.append(Analysis.performer_id == performer_id)
    if reference_id is not None:
        conditions.append(Analysis.reference_id == reference_id)
    if status is not None:
        conditions.append(Analysis.status == status)
    if created_after is not None:
        conditions.append(Analysis.created_at >= created_after)
    if created_before is not None:
        conditions.append(Analysis.created_at < created_before)
    total = session.scalar(select(func.count()).select_from(Analysis).where(*conditions)) or 0
    stmt = (
        select(Analysis)
        .where(*conditions)
        .order_by(Analysis.created_at.desc(), Analysis.id)
        .limit(limit)
        .offset(offset)
    )
    return list(session.scalars(stmt)), int(total)


def list_active_analyses(session: Session, *, limit: int = 500) -> list[Analysis]:
    """Analyses a worker may still be working on (every club: used by the reflector)."""
    stmt = select(Analysis).where(Analysis.status.in_(("queued", "running"))).limit(limit)
    return list(session.scalars(stmt))


def get_capture(session: Session, *, club_id: int, capture_id: str) -> Capture | None:
    row = session.get(Capture, capture_id)
    return row if row is not None and row.club_id == club_id else None


def list_captures(
    session: Session, *, club_id: int, limit: int, offset: int, performer_id: int | None = None
) -> tuple[list[Capture], int]:
    conditions: list[Any] = [Capture.club_id == club_id]
    if performer_id is not None:
        conditions.append(Capture.performer_id == performer_id)
    total = session.scalar(select(func.count()).select_from(Capture).where(*conditions)) or 0
    stmt = (
        select(Capture)
        .where(*conditions)
        .order_by(Capture.created_at.desc(), Capture.id)
        .limit(limit)
        .offset(offset)
    )
    return list(session.scalars(stmt)), int(total)
