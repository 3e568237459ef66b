"""JSON endpoints the browser pages call, under ``/web/api``, authenticated by the session
cookie (``POST /api/v1/session``) instead of a club API key.

They reuse the REST API's route functions with the signed-in user's club, so an upload from
the page and one through the API go through the same checks. A performer sees only their own
analyses; coaches see the club's and alone may manage references.
"""

from __future__ import annotations

import json
import tempfile
import uuid
from datetime import timedelta
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Body, File, Form, Header, Query, Request, Response, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse
from pydantic import BaseModel, Field
from starlette.background import BackgroundTask

from app import crud
from app.api.deps import (
    CurrentUser,
    NotifierDep,
    QueueDep,
    SessionDep,
    SettingsDep,
    StorageDep,
)
from app.api.errors import ApiError, not_found
from app.api.routes import analyses as api_analyses
from app.api.routes import references as api_references
from app.core import validation
from app.core.reflect import reflect
from app.core.storage import Storage
from app.models import Analysis, Club, Comment, Reference, User
from engine.errors import InvalidInput
from web import invites
from web.live import NothingToShowYet, ViewerUnavailable, get_viewers
from web.pages import compare, media

router = APIRouter(prefix="/web/api", include_in_schema=False)


# ---- access
def club_of(session, user: User) -> Club:
    club = crud.get_club(session, user.club_id)
    if club is None:
        raise ApiError(401, "unauthorized", "your club no longer exists")
    return club


def require_coach(user: User) -> None:
    if user.role != "coach":
        raise ApiError(403, "forbidden", "only a coach may do this")


def get_analysis_for(session, user: User, analysis_id: str) -> Analysis:
    try:
        uuid.UUID(analysis_id)
    except ValueError:
        raise not_found("analysis", analysis_id) from None
    a = crud.get_analysis(session, club_id=user.club_id, analysis_id=analysis_id)
    if a is None or (user.role != "coach" and a.performer_id != user.id):
        raise not_found("analysis", analysis_id)
    return a


def get_reference_for(session, user: User, reference_id: int) -> Reference:
    ref = crud.get_reference(session, club_id=user.club_id, reference_id=reference_id)
    if ref is None:
        raise not_found("reference", reference_id)
    return ref


def load_result(session, analysis: Analysis, notifier) -> dict[str, Any]:
    reflect(session, analysis, on_final=notifier)
    if analysis.status != "done" or not analysis.result_path:
        raise ApiError(
            409, "not_ready", f"the analysis is {analysis.status}, not done",
            {"status": analysis.status},
        )  # fmt: skip
    result = Storage.read_json(Path(analysis.result_path))
    if result is None:
        raise ApiError(409, "not_ready", "the result file cannot be read yet")
    return result


def segment_names(ref: Reference, n: int) -> list[str]:
    names = list(((ref.domain_config or {}).get("segment_names")) or [])
    return [names[i] if i < len(names) else f"segment {i + 1}" for i in range(n)]


def reference_public(ref: Reference) -> dict[str, Any]:
    derived = ref.derived or {}
    bounds = list(derived.get("segments") or [])
    n_segments = max(len(bounds) - 1, 0) or len(
        (ref.domain_config or {}).get("segment_names") or []
    )
    return {
        "id": ref.id,
        "name": ref.name,
        "frames": derived.get("frames"),
        "fps": derived.get("fps"),
        "duration_s": derived.get("duration_s"),
        "segment_names": segment_names(ref, n_segments) if n_segments else [],
        "domain": validation.engine_domain(ref.domain_config or {}),
        "thumbnail": f"/web/api/references/{ref.id}/thumbnail.svg",
        "strip": f"/web/api/references/{ref.id}/strip.svg",
        "preview": f"/web/api/references/{ref.id}/preview.json",
    }


# ---- references
@router.get("/references")
def list_references(user: CurrentUser, session: SessionDep):
    refs = crud.list_references(session, club_id=user.club_id, limit=1000, offset=0)
    return [reference_public(r) for r in refs]


_SVG_HEADERS = {"Cache-Control": "private, max-age=300"}


@router.get("/references/{reference_id}/thumbnail.svg")
async def reference_thumbnail(reference_id: int, user: CurrentUser, session: SessionDep):
    ref = get_reference_for(session, user, reference_id)
    first = int((ref.derived or {}).get("first_motion_frame") or 0)
    svg = await run_in_threadpool(media.reference_thumbnail, ref.bvh_path, first)
    return Response(svg, media_type="image/svg+xml", headers=_SVG_HEADERS)


@router.get("/references/{reference_id}/strip.svg")
async def reference_strip(reference_id: int, user: CurrentUser, session: SessionDep):
    ref = get_reference_for(session, user, reference_id)
    derived = ref.derived or {}
    svg = await run_in_threadpool(
        media.reference_strip, ref.bvh_path, list(derived.get("segments") or []),
        int(derived.get("first_motion_frame") or 0),
    )  # fmt: skip
    return Response(svg, media_type="image/svg+xml", headers=_SVG_HEADERS)


@router.get("/references/{reference_id}/preview.json")
async def reference_preview(reference_id: int, user: CurrentUser, session: SessionDep):
    """Sampled postures (front and side view) for the picker's looping preview."""
    ref = get_reference_for(session, user, reference_id)
    derived = ref.derived or {}
    data = await run_in_threadpool(
        media.reference_preview, ref.bvh_path, int(derived.get("first_motion_frame") or 0),
        fps=float(derived.get("fps") or 0.0),
    )  # fmt: skip
    return JSONResponse(data, headers=_SVG_HEADERS)


@router.post("/references", status_code=201)
async def create_reference(
    user: CurrentUser,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    file: Annotated[UploadFile, File()],
    name: Annotated[str | None, Form(min_length=1, max_length=200)] = None,
    domain: Annotated[UploadFile | None, File()] = None,
):
    require_coach(user)
    ref = await api_references.create_reference(
        club_of(session, user), session, settings, storage, file, name, domain
    )
    return reference_public(ref)


class DomainUpdate(BaseModel):
    """The coach-editable part of a domain file (engine.reference.domain)."""

    name: str | None = Field(default=None, min_length=1, max_length=200)
    segment_names: list[Annotated[str, Field(max_length=100)]] = Field(default=[], max_length=64)
    bone_weights: dict[str, float] = Field(default={}, max_length=32)
    tolerances_deg: dict[str, float] = Field(default={}, max_length=32)
    default_tolerance_deg: float = Field(default=0.0, ge=0, le=180)


@router.put("/references/{reference_id}/domain")
def update_domain(
    reference_id: int, body: DomainUpdate, user: CurrentUser, session: SessionDep,
    storage: StorageDep,
):  # fmt: skip
    require_coach(user)
    ref = get_reference_for(session, user, reference_id)
    config = dict(ref.domain_config or {})
    config.update(
        segment_names=[s.strip() for s in body.segment_names],
        bone_weights=body.bone_weights,
        tolerances_deg=body.tolerances_deg,
        default_tolerance_deg=body.default_tolerance_deg,
    )
    try:
        config = validation.parse_domain(json.dumps(config).encode())
    except InvalidInput as exc:
        raise ApiError(422, "invalid_domain", str(exc)) from None
    n = len((ref.derived or {}).get("segments") or []) - 1  # boundaries: n + 1 frames
    if config["segment_names"] and n > 0 and len(config["segment_names"]) != n:
        raise ApiError(
            422, "invalid_domain",
            f"the reference has {n} segments, got {len(config['segment_names'])} names",
        )  # fmt: skip
    path = storage.reference_dir(ref.id) / "reference.domain.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(validation.engine_domain(config), indent=1))
    tmp.replace(path)
    ref.domain_path = str(path)
    ref.domain_config = config
    if body.name:
        ref.name = body.name
    session.commit()
    return reference_public(ref)


# ---- analyses
@router.post("/analyses", status_code=201)
async def create_analysis(
    response: Response,
    user: CurrentUser,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    queue: QueueDep,
    video: Annotated[UploadFile, File()],
    reference_id: Annotated[int, Form(ge=1)],
    performer_id: Annotated[int | None, Form(ge=1)] = None,
    idempotency_key: Annotated[str | None, Header(alias="Idempotency-Key", max_length=255)] = None,
):
    if user.role != "coach" or performer_id is None:
        performer_id = user.id  # a performer uploads for themselves
    if user.role == "coach" and performer_id == user.id:
        raise ApiError(422, "invalid_request", "choose the performer this video shows")
    a = await api_analyses.create_analysis(
        response, club_of(session, user), session, settings, storage, queue, video,
        reference_id, performer_id, idempotency_key,
    )  # fmt: skip
    return {"id": a.id, "status": a.status, "url": f"/analyses/{a.id}"}


@router.get("/analyses/{analysis_id}")
def read_analysis(analysis_id: str, user: CurrentUser, session: SessionDep, notifier: NotifierDep):
    a = get_analysis_for(session, user, analysis_id)
    reflect(session, a, on_final=notifier)
    return api_analyses._public(a).model_dump(mode="json")


@router.get("/analyses/{analysis_id}/events")
async def analysis_events(
    analysis_id: str, request: Request, user: CurrentUser, session: SessionDep,
    settings: SettingsDep, notifier: NotifierDep,
):  # fmt: skip
    get_analysis_for(session, user, analysis_id)
    club = club_of(session, user)
    return await api_analyses.analysis_events(
        analysis_id, request, club, session, settings, notifier
    )


@router.post("/analyses/{analysis_id}/cancel")
def cancel_analysis(
    analysis_id: str, user: CurrentUser, session: SessionDep, queue: QueueDep,
    notifier: NotifierDep,
):  # fmt: skip
    get_analysis_for(session, user, analysis_id)
    a = api_analyses.cancel_analysis(analysis_id, club_of(session, user), session, queue, notifier)
    return api_analyses._public(a).model_dump(mode="json")


@router.get("/analyses/{analysis_id}/result")
def read_result(analysis_id: str, user: CurrentUser, session: SessionDep, notifier: NotifierDep):
    a = get_analysis_for(session, user, analysis_id)
    load_result(session, a, notifier)
    return FileResponse(a.result_path, media_type="application/json")


@router.get("/analyses/{analysis_id}/summary")
def read_summary(analysis_id: str, user: CurrentUser, session: SessionDep, notifier: NotifierDep):
    """Segments with names, tempo and worst bones, plus what the page header shows."""
    a = get_analysis_for(session, user, analysis_id)
    result = load_result(session, a, notifier)
    try:
        segments = api_analyses.summarise_segments(result)
    except (KeyError, TypeError, ValueError) as exc:
        raise ApiError(500, "bad_result", f"the result has malformed segments ({exc})") from None
    names = segment_names(a.reference, len(segments))
    raw = result.get("segments") or []
    out = []
    for s, name in zip(segments, names, strict=True):
        d = s.model_dump()
        own = raw[s.index].get("name") if s.index < len(raw) else None
        d["name"] = (
            name if (a.reference.domain_config or {}).get("segment_names") else (own or name)
        )
        # (bone, mean error, width of its range over the candidates the video cannot tell
        # apart, or None for results that predate it)
        worst = sorted(s.bone_mean_errors_deg.items(), key=lambda kv: -kv[1])[:3]
        d["worst_bones"] = [(b, e, s.bone_uncertainty_deg.get(b)) for b, e in worst]
        d["score"] = raw[s.index].get("score_deg", s.mean_error_deg) if s.index < len(raw) else None
        out.append(d)
    return {
        "analysis_id": a.id,
        "reference": a.reference.name,
        "performer": a.performer.display_name,
        "segments": out,
    }


@router.get("/analyses/{analysis_id}/video.mp4")
async def read_video(analysis_id: str, user: CurrentUser, session: SessionDep):
    a = get_analysis_for(session, user, analysis_id)
    try:
        path = await run_in_threadpool(media.playable_video, a.video_path, a.work_dir)
    except Exception as exc:  # a broken upload: say so instead of a 500 page
        raise ApiError(422, "invalid_video", f"the video cannot be converted ({exc})") from None
    return FileResponse(path, media_type="video/mp4")


@router.get("/analyses/{analysis_id}/export.csv")
def export_csv(analysis_id: str, user: CurrentUser, session: SessionDep, notifier: NotifierDep):
    a = get_analysis_for(session, user, analysis_id)
    text = media.result_csv(load_result(session, a, notifier))
    return PlainTextResponse(
        text, media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="analysis-{a.id[:8]}.csv"'},
    )  # fmt: skip


@router.get("/analyses/{analysis_id}/export.bvh")
async def export_bvh(
    analysis_id: str, user: CurrentUser, session: SessionDep, notifier: NotifierDep
):
    a = get_analysis_for(session, user, analysis_id)
    result = load_result(session, a, notifier)
    tmp = Path(tempfile.mkdtemp(prefix="coach-bvh-"))
    path = await run_in_threadpool(media.result_bvh, result, tmp / "performer.bvh")
    return FileResponse(
        path, media_type="application/octet-stream", filename=f"performer-{a.id[:8]}.bvh",
        background=BackgroundTask(Storage.remove, tmp),
    )  # fmt: skip


# ---- progress over time
def get_performer_for(session, user: User, performer_id: int) -> User:
    """A performer of the user's club whom the user may see: a coach any, a performer only
    themselves."""
    p = crud.get_performer(session, club_id=user.club_id, user_id=performer_id)
    if p is None or (user.role != "coach" and p.id != user.id):
        raise not_found("performer", performer_id)
    return p


def history_of(session, performer: User, notifier) -> list[dict[str, Any]]:
    """The performer's analyses, oldest first, with their mean error once done."""
    items, _ = crud.list_analyses(
        session, club_id=performer.club_id, performer_id=performer.id, limit=1000, offset=0
    )
    out = []
    for a in reversed(items):
        reflect(session, a, on_final=notifier)
        done = a.status == "done" and a.result_path
        out.append({
            "id": a.id, "created_at": a.created_at.isoformat(), "status": a.status,
            "reference_id": a.reference_id, "reference": a.reference.name,
            "mean_error_deg": compare.mean_error_of_file(a.result_path) if done else None,
            "url": f"/analyses/{a.id}",
        })  # fmt: skip
    return out


@router.get("/performers/{performer_id}/history")
def performer_history(
    performer_id: int, user: CurrentUser, session: SessionDep, notifier: NotifierDep
):
    p = get_performer_for(session, user, performer_id)
    return {
        "performer": {"id": p.id, "display_name": p.display_name},
        "analyses": history_of(session, p, notifier),
    }


def _attempt(a: Analysis) -> dict[str, Any]:
    return {
        "id": a.id, "created_at": a.created_at.isoformat(), "url": f"/analyses/{a.id}",
        "video": f"/web/api/analyses/{a.id}/video.mp4",
    }  # fmt: skip


@router.get("/performers/{performer_id}/compare")
def compare_attempts(
    performer_id: int,
    user: CurrentUser,
    session: SessionDep,
    notifier: NotifierDep,
    a: Annotated[str, Query(max_length=36)],
    b: Annotated[str, Query(max_length=36)],
):
    """Two finished analyses of one performer against the same reference: per-segment error
    and tempo with the change from A to B, both error curves over the reference's frames."""
    p = get_performer_for(session, user, performer_id)
    first, second = get_analysis_for(session, user, a), get_analysis_for(session, user, b)
    if first.performer_id != p.id or second.performer_id != p.id:
        raise ApiError(422, "invalid_request", "both analyses must be this performer's")
    if first.reference_id != second.reference_id:
        raise ApiError(422, "invalid_request", "the two analyses use different references")
    ra, rb = load_result(session, first, notifier), load_result(session, second, notifier)
    n = max(len(ra.get("segments") or []), len(rb.get("segments") or []))
    try:
        data = compare.compare_results(ra, rb, segment_names(first.reference, n))
    except (KeyError, TypeError, ValueError) as exc:
        raise ApiError(500, "bad_result", f"a result has malformed segments ({exc})") from None
    return {
        "performer": {"id": p.id, "display_name": p.display_name},
        "reference": {"id": first.reference_id, "name": first.reference.name},
        "a": _attempt(first), "b": _attempt(second), **data,
    }  # fmt: skip


# ---- comments
class CommentCreate(BaseModel):
    body: str = Field(min_length=1, max_length=4000)
    frame: int | None = Field(default=None, ge=0, le=1_000_000)
    segment: int | None = Field(default=None, ge=0, le=1000)


def comment_public(c: Comment) -> dict[str, Any]:
    return {
        "id": c.id,
        "body": c.body,
        "frame": c.frame,
        "segment": c.segment,
        "author": c.author.display_name if c.author else "(removed)",
        "author_id": c.author_id,
        "created_at": c.created_at.isoformat(),
    }


def list_comment_rows(session, analysis: Analysis) -> list[Comment]:
    from sqlalchemy import select

    q = select(Comment).where(
        Comment.club_id == analysis.club_id, Comment.analysis_id == analysis.id
    )
    return list(session.scalars(q.order_by(Comment.frame.is_(None), Comment.frame, Comment.id)))


@router.get("/analyses/{analysis_id}/comments")
def list_comments(analysis_id: str, user: CurrentUser, session: SessionDep):
    a = get_analysis_for(session, user, analysis_id)
    return [comment_public(c) for c in list_comment_rows(session, a)]


@router.post("/analyses/{analysis_id}/comments", status_code=201)
def create_comment(analysis_id: str, body: CommentCreate, user: CurrentUser, session: SessionDep):
    a = get_analysis_for(session, user, analysis_id)
    c = Comment(
        club_id=a.club_id, analysis_id=a.id, author_id=user.id, frame=body.frame,
        segment=body.segment, body=body.body.strip(),
    )  # fmt: skip
    session.add(c)
    session.commit()
    return comment_public(c)


@router.delete("/analyses/{analysis_id}/comments/{comment_id}", status_code=204)
def delete_comment(analysis_id: str, comment_id: int, user: CurrentUser, session: SessionDep):
    a = get_analysis_for(session, user, analysis_id)
    c = session.get(Comment, comment_id)
    if c is None or c.analysis_id != a.id:
        raise not_found("comment", comment_id)
    if c.author_id != user.id and user.role != "coach":
        raise ApiError(403, "forbidden", "you can delete only your own comments")
    session.delete(c)
    session.commit()
    return Response(status_code=204)


# ---- invite links
class InviteCreate(BaseModel):
    display_name: str = Field(default="", max_length=200)
    days: int = Field(default=7, ge=1, le=30)


@router.post("/invites", status_code=201)
def create_invite(body: InviteCreate, request: Request, user: CurrentUser, session: SessionDep):
    """A coach's single-use link for a new performer; the token is in the answer only."""
    require_coach(user)
    invite, token = invites.create_invite(
        session, club_id=user.club_id, created_by=user.id, display_name=body.display_name,
        ttl=timedelta(days=body.days),
    )  # fmt: skip
    return {
        "url": str(request.base_url).rstrip("/") + f"/join/{token}",
        "path": f"/join/{token}",
        "display_name": invite.display_name,
        "expires_at": invite.expires_at.isoformat(),
    }


class JoinBody(BaseModel):
    display_name: str = Field(min_length=1, max_length=200)
    email: str = Field(min_length=3, max_length=320)
    password: str = Field(min_length=1, max_length=1000)


_INVITE_STATUS = {"unknown": 404, "used": 410, "expired": 410, "invalid": 422}


@router.post("/join/{token}")
def join(token: str, body: JoinBody, request: Request, session: SessionDep):
    """Redeem an invite: create the performer and sign them in."""
    try:
        user = invites.redeem_invite(
            session, token, display_name=body.display_name, email=body.email,
            password=body.password,
        )  # fmt: skip
    except invites.InviteError as exc:
        raise ApiError(_INVITE_STATUS[exc.reason], f"invite_{exc.reason}", str(exc)) from None
    request.session.clear()
    request.session["user_id"] = user.id
    request.session["club_id"] = user.club_id
    return {"id": user.id, "display_name": user.display_name, "url": "/upload"}


# ---- the embedded 3D view
@router.post("/analyses/{analysis_id}/viewer")
async def start_viewer(
    analysis_id: str, request: Request, user: CurrentUser, session: SessionDep,
    notifier: NotifierDep,
):  # fmt: skip
    a = get_analysis_for(session, user, analysis_id)
    result = load_result(session, a, notifier)
    bvh = a.reference.bvh_path

    def load():
        return media.reference_joints(bvh), result

    try:
        port = await run_in_threadpool(get_viewers().ensure, a.id, load)
    except ViewerUnavailable as exc:
        raise ApiError(503, "viewer_unavailable", str(exc)) from None
    host = request.url.hostname or "127.0.0.1"
    return {"port": port, "url": f"{request.url.scheme}://{host}:{port}/"}


@router.post("/analyses/{analysis_id}/viewer/live")
async def start_live_viewer(
    analysis_id: str, request: Request, user: CurrentUser, session: SessionDep,
    notifier: NotifierDep,
):  # fmt: skip
    """The 3D view of a running analysis, filled in from its folder as stages finish.

    409 ``not_ready`` until stage 2's output exists (the page asks again); once the analysis
    is done the same server shows the finished scene (``phase`` "done").
    """
    a = get_analysis_for(session, user, analysis_id)
    reflect(session, a, on_final=notifier)
    if a.status in ("failed", "cancelled") or not a.work_dir:
        raise ApiError(409, "not_ready", f"the analysis is {a.status}", {"status": a.status})
    try:
        port, state = await run_in_threadpool(get_viewers().ensure_running, a.id, a.work_dir)
    except NothingToShowYet as exc:
        raise ApiError(409, "not_ready", str(exc), {"status": a.status}) from None
    except ViewerUnavailable as exc:
        raise ApiError(503, "viewer_unavailable", str(exc)) from None
    host = request.url.hostname or "127.0.0.1"
    return {"port": port, "url": f"{request.url.scheme}://{host}:{port}/", **state}


class FrameBody(BaseModel):
    frame: int = Field(ge=0, le=1_000_000)


@router.post("/analyses/{analysis_id}/viewer/frame", status_code=204)
async def viewer_frame(
    analysis_id: str, body: Annotated[FrameBody, Body()], user: CurrentUser, session: SessionDep
):
    a = get_analysis_for(session, user, analysis_id)
    await run_in_threadpool(get_viewers().set_frame, a.id, body.frame)
    return Response(status_code=204)
