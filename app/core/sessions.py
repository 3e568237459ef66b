"""Browser sessions, stored server-side (``user_sessions``).

The signed cookie (Starlette's SessionMiddleware) carries one random token; the database holds
its hash, its user and its expiry. A forged cookie needs the signing secret *and* a live token,
and signing out or changing the password deletes the rows, so a captured cookie dies with them.
"""

from __future__ import annotations

from datetime import timedelta

from fastapi import Request
from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from app.core import security
from app.models import User, UserSession, utcnow

#: The cookie's key holding the session token.
TOKEN = "sid"


def start(request: Request, db: Session, user: User, max_age_s: int) -> None:
    """Sign ``user`` in on this browser: a new token (never reuse one an attacker may have
    planted before sign-in) and a row that expires with the cookie."""
    end(request, db)
    token, token_hash = security.new_session_token()
    db.add(
        UserSession(
            user_id=user.id, token_hash=token_hash,
            expires_at=utcnow() + timedelta(seconds=max_age_s),
        )
    )  # fmt: skip
    db.commit()
    request.session.clear()
    request.session[TOKEN] = token


def current_user(request: Request, db: Session) -> User | None:
    """The user of this browser's live session, if any."""
    token = request.session.get(TOKEN)
    if not isinstance(token, str) or not token:
        return None
    row = db.scalar(
        select(UserSession).where(UserSession.token_hash == security.hash_api_key(token))
    )
    if row is None or row.expires_at <= utcnow():
        return None
    return db.get(User, row.user_id)


def end(request: Request, db: Session) -> None:
    """Sign this browser out: its row goes, so the cookie is worthless even if copied."""
    token = request.session.get(TOKEN)
    if isinstance(token, str) and token:
        db.execute(
            delete(UserSession).where(UserSession.token_hash == security.hash_api_key(token))
        )
        db.commit()
    request.session.clear()


def revoke_all(db: Session, user_id: int) -> None:
    """Sign a user out everywhere (after a password change); also drops expired rows."""
    db.execute(
        delete(UserSession).where(
            (UserSession.user_id == user_id) | (UserSession.expires_at <= utcnow())
        )
    )
    db.commit()
