"""Database tables (SQLAlchemy 2.0 ORM). Every row but the club itself belongs to one club."""

from __future__ import annotations

import uuid
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

ROLES = ("coach", "performer")
ANALYSIS_STATES = ("queued", "running", "done", "failed", "cancelled")
TERMINAL_STATES = ("done", "failed", "cancelled")
#: What webhooks announce: an analysis reaching a final state.
WEBHOOK_EVENTS = tuple(f"analysis.{state}" for state in TERMINAL_STATES)


def utcnow() -> datetime:
    return datetime.now(UTC)


def new_uuid() -> str:
    return str(uuid.uuid4())


class UTCDateTime(TypeDecorator):
    """A timezone-aware UTC datetime on every backend (SQLite stores no zone)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            value = value.replace(tzinfo=UTC)
        return value.astimezone(UTC)

    def process_result_value(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


class Base(DeclarativeBase):
    pass


class Club(Base):
    __tablename__ = "clubs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    webhook_url: Mapped[str | None] = mapped_column(String(2000), default=None)
    webhook_secret: Mapped[str | None] = mapped_column(String(128), default=None)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)


class WebhookEndpoint(Base):
    """A further receiver of the club's webhooks, for the events it names (the club's own
    ``webhook_url`` is the default endpoint and receives every event)."""

    __tablename__ = "webhook_endpoints"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    club_id: Mapped[int] = mapped_column(ForeignKey("clubs.id", ondelete="CASCADE"), index=True)
    url: Mapped[str] = mapped_column(String(2000))
    #: Signs this endpoint's deliveries; shown when made or rotated, kept to sign with.
    secret: Mapped[str] = mapped_column(String(128))
    #: Names from WEBHOOK_EVENTS this endpoint receives.
    events: Mapped[list[str]] = mapped_column(JSON, default=list)
    description: Mapped[str] = mapped_column(String(200), default="")
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    #: Set while deliveries to it are paused.
    disabled_at: Mapped[datetime | None] = mapped_column(UTCDateTime(), default=None)


class User(Base):
    __tablename__ = "users"
    __table_args__ = (
        UniqueConstraint("club_id", "email", name="uq_users_club_email"),
        CheckConstraint("role IN ('coach', 'performer')", name="ck_users_role"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    club_id: Mapped[int] = mapped_column(ForeignKey("clubs.id", ondelete="CASCADE"), index=True)
    role: Mapped[str] = mapped_column(String(16))
    email: Mapped[str] = mapped_column(String(320))
    display_name: Mapped[str] = mapped_column(String(200))
    #: argon2 hash; None for a performer who never signs in.
    password_hash: Mapped[str | None] = mapped_column(String(256), default=None)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    club: Mapped[Club] = relationship()


class ApiKey(Base):
    __tablename__ = "api_keys"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    club_id: Mapped[int] = mapped_column(ForeignKey("clubs.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(100), default="")
    #: The first characters of the key, shown in lists so a person can tell keys apart.
    prefix: Mapped[str] = mapped_column(String(16))
    #: sha256 hex of the whole key; the key itself is shown once and never stored.
    key_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    last_used_at: Mapped[datetime | None] = mapped_column(UTCDateTime(), default=None)
    revoked_at: Mapped[datetime | None] = mapped_column(UTCDateTime(), default=None)


class UserSession(Base):
    """A signed-in browser. The cookie carries only the token; signing out, or changing the
    password, deletes the row, so a captured cookie stops working at once."""

    __tablename__ = "user_sessions"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    #: sha256 hex of the cookie's token.
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    expires_at: Mapped[datetime] = mapped_column(UTCDateTime())


def segment_names(domain_config: dict | None, n: int) -> list[str]:
    """The coach's names of a reference's ``n`` segments ("segment i" where unnamed)."""
    names = list(((domain_config or {}).get("segment_names")) or [])
    return [names[i] if i < len(names) else f"segment {i + 1}" for i in range(n)]


class Reference(Base):
    __tablename__ = "references"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    club_id: Mapped[int] = mapped_column(ForeignKey("clubs.id", ondelete="CASCADE"), index=True)
    name: Mapped[str] = mapped_column(String(200))
    bvh_path: Mapped[str] = mapped_column(String(1000))
    domain_config: Mapped[dict | None] = mapped_column(JSON, default=None)
    #: What the importer learned: frames, fps, duration_s, segments, joints.
    derived: Mapped[dict] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)


class Analysis(Base):
    __tablename__ = "analyses"
    __table_args__ = (
        UniqueConstraint("club_id", "idempotency_key", name="uq_analyses_club_idempotency"),
        Index("ix_analyses_club_created", "club_id", "created_at"),
    )

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_uuid)
    club_id: Mapped[int] = mapped_column(ForeignKey("clubs.id", ondelete="CASCADE"), index=True)
    performer_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    reference_id: Mapped[int] = mapped_column(ForeignKey("references.id"), index=True)
    video_path: Mapped[str] = mapped_column(String(1000))
    work_dir: Mapped[str] = mapped_column(String(1000))
    status: Mapped[str] = mapped_column(String(16), default="queued", index=True)
    stage: Mapped[str] = mapped_column(String(64), default="")
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    message: Mapped[str] = mapped_column(String(1000), default="")
    error: Mapped[str | None] = mapped_column(Text, default=None)
    result_path: Mapped[str | None] = mapped_column(String(1000), default=None)
    timings: Mapped[dict | None] = mapped_column(JSON, default=None)
    task_id: Mapped[str | None] = mapped_column(String(255), default=None)
    #: Times recovery queued the analysis again (its publish, worker or broker message was
    #: lost: app.core.recovery); also the claim that keeps two API processes from both doing it.
    recoveries: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    #: The video frames analysed, start..end-1 (one repetition of several); None: the whole
    #: video, or whatever the engine picks (it analyses the first of several repetitions).
    frames_start: Mapped[int | None] = mapped_column(Integer, default=None)
    frames_end: Mapped[int | None] = mapped_column(Integer, default=None)
    idempotency_key: Mapped[str | None] = mapped_column(String(255), default=None)
    #: sha256 hex of what the upload sent under that key (reference, performer, video), so
    #: the key reused for a different upload is refused (None: made before it was kept).
    idempotency_fingerprint: Mapped[str | None] = mapped_column(String(64), default=None)
    #: The headline of a done analysis: its mean posture error eps_t' over the frames, kept
    #: here (set when the result is reflected) so that lists need not read every result.
    mean_error_deg: Mapped[float | None] = mapped_column(Float, default=None)
    #: What the video's first frame says about the filming (feet out of the picture...), known
    #: once stages 0-2 are done (``framing.json``); None before.
    warnings: Mapped[list | None] = mapped_column(JSON, default=None)
    #: The coach's "reviewed" mark (None: still to review), and who set it.
    reviewed_at: Mapped[datetime | None] = mapped_column(UTCDateTime(), default=None)
    reviewed_by_id: Mapped[int | None] = mapped_column(
        ForeignKey("users.id", ondelete="SET NULL", name="fk_analyses_reviewed_by"), default=None
    )
    #: Set when the completion webhook was handed to the sender (so it fires once).
    notified_at: Mapped[datetime | None] = mapped_column(UTCDateTime(), default=None)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow, onupdate=utcnow)

    performer: Mapped[User] = relationship(foreign_keys=[performer_id])
    reference: Mapped[Reference] = relationship()
    reviewed_by: Mapped[User | None] = relationship(foreign_keys=[reviewed_by_id])


class Capture(Base):
    """A reference-free capture (issue 23): a performer's 3D motion from one video."""

    __tablename__ = "captures"
    __table_args__ = (Index("ix_captures_club_created", "club_id", "created_at"),)

    id: Mapped[str] = mapped_column(String(36), primary_key=True, default=new_uuid)
    club_id: Mapped[int] = mapped_column(ForeignKey("clubs.id", ondelete="CASCADE"), index=True)
    performer_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    name: Mapped[str] = mapped_column(String(200))
    video_path: Mapped[str] = mapped_column(String(1000))
    work_dir: Mapped[str] = mapped_column(String(1000))
    height_m: Mapped[float] = mapped_column(Float, default=1.75)
    #: The user's answers to the capture's questions: question id -> -1 towards, +1 away.
    answers: Mapped[dict | None] = mapped_column(JSON, default=None)
    status: Mapped[str] = mapped_column(String(16), default="queued", index=True)
    progress: Mapped[float] = mapped_column(Float, default=0.0)
    message: Mapped[str] = mapped_column(String(1000), default="")
    error: Mapped[str | None] = mapped_column(Text, default=None)
    task_id: Mapped[str | None] = mapped_column(String(255), default=None)
    #: The reference made from this capture ("use as reference"), if any.
    reference_id: Mapped[int | None] = mapped_column(
        ForeignKey("references.id", ondelete="SET NULL"), default=None
    )
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow, onupdate=utcnow)


class Comment(Base):
    """A coach's (or performer's) note on an analysis, pinned to a video frame or a segment."""

    __tablename__ = "comments"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    club_id: Mapped[int] = mapped_column(ForeignKey("clubs.id", ondelete="CASCADE"), index=True)
    analysis_id: Mapped[str] = mapped_column(
        ForeignKey("analyses.id", ondelete="CASCADE"), index=True
    )
    author_id: Mapped[int | None] = mapped_column(
        ForeignKey("users.id", ondelete="SET NULL"), default=None
    )
    #: Video frame t' the comment is pinned to, or None.
    frame: Mapped[int | None] = mapped_column(Integer, default=None)
    #: Segment index the comment is pinned to, or None.
    segment: Mapped[int | None] = mapped_column(Integer, default=None)
    body: Mapped[str] = mapped_column(Text)
    #: Strokes drawn over the pinned frame: lists of [x, y], shares of the video's width and
    #: height; None without a drawing.
    drawing: Mapped[list | None] = mapped_column(JSON, default=None)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)

    author: Mapped[User | None] = relationship()


class Invite(Base):
    """A single-use link (``/join/<token>``) a coach sends to a new performer.

    Only the sha256 of the token is stored (like API keys); the link is shown once.
    """

    __tablename__ = "invites"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    club_id: Mapped[int] = mapped_column(ForeignKey("clubs.id", ondelete="CASCADE"), index=True)
    created_by: Mapped[int | None] = mapped_column(
        ForeignKey("users.id", ondelete="SET NULL"), default=None
    )
    #: sha256 hex of the token.
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    #: The name the coach suggested; the performer may change it.
    display_name: Mapped[str] = mapped_column(String(200), default="")
    expires_at: Mapped[datetime] = mapped_column(UTCDateTime())
    used_at: Mapped[datetime | None] = mapped_column(UTCDateTime(), default=None)
    #: The performer who joined through it.
    user_id: Mapped[int | None] = mapped_column(
        ForeignKey("users.id", ondelete="SET NULL"), default=None
    )
    created_at: Mapped[datetime] = mapped_column(UTCDateTime(), default=utcnow)
