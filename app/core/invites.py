"""Single-use invite links a coach sends to a new performer: ``/join/<token>``.

The token is 32 random bytes (url-safe base64); only its sha256 is stored, so a database
leak gives no working links. A link expires after ``ttl`` and works once: redeeming claims
the row with a conditional ``UPDATE ... WHERE used_at IS NULL`` in the same transaction as
the new user, so two people opening the same link cannot both join, and a failed sign-up
(e.g. an email already in the club) leaves the link usable.
"""

from __future__ import annotations

import hashlib
import secrets
from datetime import UTC, datetime, timedelta

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from app import crud
from app.models import Invite, User

#: How long a link works unless the coach says otherwise.
DEFAULT_TTL = timedelta(days=7)
MIN_PASSWORD_LEN = 10


class InviteError(Exception):
    """The invite cannot be used; ``reason`` is ``unknown``, ``expired``, ``used`` or
    ``invalid`` (the sign-up details), and the message is for the person holding the link."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def _now(now: datetime | None) -> datetime:
    return now if now is not None else datetime.now(UTC)


def create_invite(
    session: Session,
    *,
    club_id: int,
    created_by: int | None,
    display_name: str = "",
    ttl: timedelta = DEFAULT_TTL,
    now: datetime | None = None,
) -> tuple[Invite, str]:
    """A new invite and its token (shown once; only the hash is stored)."""
    if ttl <= timedelta(0):
        raise ValueError(f"ttl: must be positive, got {ttl}")
    token = secrets.token_urlsafe(32)
    invite = Invite(
        club_id=club_id, created_by=created_by, token_hash=hash_token(token),
        display_name=display_name.strip()[:200], expires_at=_now(now) + ttl,
    )  # fmt: skip
    session.add(invite)
    session.commit()
    return invite, token


def find_invite(session: Session, token: str, *, now: datetime | None = None) -> Invite:
    """The usable invite for ``token``; raises :class:`InviteError` otherwise."""
    if not token or len(token) > 200:
        raise InviteError("unknown", "This invite link is not valid.")
    invite = session.scalars(select(Invite).where(Invite.token_hash == hash_token(token))).first()
    if invite is None:
        raise InviteError("unknown", "This invite link is not valid.")
    if invite.used_at is not None:
        raise InviteError("used", "This invite link has already been used. Sign in instead, "
                                  "or ask your coach for a new link.")  # fmt: skip
    if invite.expires_at <= _now(now):
        raise InviteError("expired", "This invite link has expired. Ask your coach for a new one.")
    return invite


def redeem_invite(
    session: Session,
    token: str,
    *,
    display_name: str,
    email: str,
    password: str,
    now: datetime | None = None,
) -> User:
    """Create the performer the invite is for and use up the invite.

    Raises
    ------
    InviteError
        Unknown, expired or used link (nothing changes), or invalid details (the link stays
        usable).
    """
    invite = find_invite(session, token, now=now)
    name, email = display_name.strip(), email.strip().lower()
    if not name or len(name) > 200:
        raise InviteError("invalid", "Enter your name (up to 200 characters).")
    if "@" not in email or len(email) > 320:
        raise InviteError("invalid", "Enter a valid email address.")
    if len(password) < MIN_PASSWORD_LEN:
        raise InviteError(
            "invalid", f"Choose a password of at least {MIN_PASSWORD_LEN} characters."
        )
    if crud.get_user_by_email(session, club_id=invite.club_id, email=email) is not None:
        raise InviteError(
            "invalid", "Someone in this club already uses that email; sign in instead."
        )
    t = _now(now)
    claimed = session.execute(
        update(Invite)
        .where(Invite.id == invite.id, Invite.used_at.is_(None), Invite.expires_at > t)
        .values(used_at=t)
    ).rowcount
    if claimed != 1:  # someone else redeemed it between the read and now
        session.rollback()
        raise InviteError("used", "This invite link has already been used.")
    try:
        user = crud.create_user(  # commits the claim and the user together
            session, club_id=invite.club_id, role="performer", email=email,
            display_name=name, password=password,
        )  # fmt: skip
    except Exception:
        session.rollback()
        raise
    invite.user_id = user.id
    session.commit()
    return user
