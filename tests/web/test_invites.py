"""Invite links: hashed, expiring, single-use tokens (app.core.invites) and their endpoints."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest
from sqlalchemy import select

from app import crud
from app.core import invites
from app.core.db import make_engine, make_sessionmaker, run_migrations
from app.models import Invite, User

T0 = datetime(2030, 1, 1, 12, 0, tzinfo=UTC)
DETAILS = {"display_name": "Nina New", "email": "Nina@Example.com", "password": "a long password"}


@pytest.fixture
def session(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'db.sqlite'}")
    run_migrations(engine)
    with make_sessionmaker(engine)() as s:
        yield s


@pytest.fixture
def club(session):
    return crud.create_club(session, name="Club")


def test_token_is_stored_only_as_its_hash(session, club):
    invite, token = invites.create_invite(session, club_id=club.id, created_by=None, now=T0)
    assert len(token) >= 40
    assert invite.token_hash == invites.hash_token(token) != token
    assert token not in str(session.execute(select(Invite.__table__)).all())
    assert invite.expires_at == T0 + invites.DEFAULT_TTL


def test_redeem_creates_a_performer_once(session, club):
    _, token = invites.create_invite(session, club_id=club.id, created_by=None, now=T0)
    user = invites.redeem_invite(session, token, now=T0 + timedelta(hours=1), **DETAILS)
    assert (user.role, user.email) == ("performer", "nina@example.com")
    assert user.display_name == "Nina New"
    assert crud.authenticate(session, email="nina@example.com", password="a long password")
    invite = session.scalars(select(Invite)).one()
    assert invite.user_id == user.id and invite.used_at is not None
    with pytest.raises(invites.InviteError, match="already been used") as e:
        invites.redeem_invite(session, token, now=T0 + timedelta(hours=2),
                              **dict(DETAILS, email="other@example.com"))  # fmt: skip
    assert e.value.reason == "used"
    assert session.scalar(select(User).where(User.email == "other@example.com")) is None


def test_expired_token_is_refused(session, club):
    _, token = invites.create_invite(
        session, club_id=club.id, created_by=None, ttl=timedelta(days=1), now=T0
    )
    with pytest.raises(invites.InviteError, match="expired") as e:
        invites.redeem_invite(session, token, now=T0 + timedelta(days=1, seconds=1), **DETAILS)
    assert e.value.reason == "expired"
    assert session.scalars(select(User)).all() == []


def test_unknown_token_is_refused(session, club):
    invites.create_invite(session, club_id=club.id, created_by=None, now=T0)
    with pytest.raises(invites.InviteError, match="not valid") as e:
        invites.find_invite(session, "not-a-token", now=T0)
    assert e.value.reason == "unknown"


def test_bad_details_leave_the_link_usable(session, club):
    _, token = invites.create_invite(session, club_id=club.id, created_by=None, now=T0)
    with pytest.raises(invites.InviteError, match="at least"):
        invites.redeem_invite(session, token, now=T0, **dict(DETAILS, password="short"))
    crud.create_user(session, club_id=club.id, role="performer", email="nina@example.com",
                     display_name="Taken")  # fmt: skip
    with pytest.raises(invites.InviteError, match="already uses that email"):
        invites.redeem_invite(session, token, now=T0, **DETAILS)
    user = invites.redeem_invite(session, token, now=T0, **dict(DETAILS, email="n2@example.com"))
    assert user.email == "n2@example.com"


def test_ttl_must_be_positive(session, club):
    with pytest.raises(ValueError, match="ttl"):
        invites.create_invite(session, club_id=club.id, created_by=None, ttl=timedelta(0))
