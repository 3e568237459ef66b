import asyncio
import json
import logging
import time
import uuid
from collections.abc import AsyncIterator
from datetime import datetime
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, File, Form, Header, Query, Request, Response, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, StreamingResponse
from sqlalchemy.exc import IntegrityError

from app import crud
from app.api.deps import (
    CurrentClub,
    NotifierDep,
    PageDep,
    QueueDep,
    SessionDep,
    SettingsDep,
    StorageDep,
)
from app.api.errors import ApiError, errors, not_found
from app.core import validation
from app.core.queue import QueueUnavailable, analysis_job
from app.core.reflect import reflect
from app.core.storage import Storage, UploadTooLarge
from app.models import TERMINAL_STATES, Analysis, Club
from app.schemas import (
    AnalysesPublic,
    AnalysisPublic,
    AnalysisState,
    SegmentPublic,
    SegmentsPublic,
)
from engine.body.skeleton import BONE_CHILD, BONE_NAMES, BONE_PARENT
from engine.errors import InvalidInput
from engine.report import ONE_CAMERA_NOTE

log = logging.getLogger("app.analyses")

router = APIRouter(prefix="/analyses", tags=["analyses"], responses=errors(401, 429))

IdempotencyKey = Annotated[
    str | None,
    Header(
        alias="Idempotency-Key",
        min_length=1,
        max_length=255,
        description="Retrying an upload with the same key returns the same analysis (200).",
    ),
]


def _get(session, club: Club, analysis_id: str) -> Analysis:
    try:
        uuid.UUID(analysis_id)
    except ValueError:
        raise not_found("analysis", analysis_id) from None
    analysis = crud.get_analysis(session, club_id=club.id, analysis_id=analysis_id)
    if analysis is None:
        raise not_found("analysis", analysis_id)
    return analysis


def _public(analysis: Analysis) -> AnalysisPublic:
    return AnalysisPublic.model_validate(analysis)


@router.post(
    "",
    status_code=201,
    response_model=AnalysisPublic,
    summary="Upload a performer's video and start its analysis",
    description=(
        "The video is streamed to disk, size-limited and decoded (first frames) before it is "
        "accepted. 201 for a new analysis; 200 with the existing one when the Idempotency-Key "
        "was already used by this club."
    ),
    responses={200: {"model": AnalysisPublic, "description": "Idempotent replay"}}
    | errors(404, 413, 422, 503),
)
async def create_analysis(
    response: Response,
    club: CurrentClub,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    queue: QueueDep,
    video: Annotated[UploadFile, File(description="The performer's video.")],
    reference_id: Annotated[int, Form(ge=1)],
    performer_id: Annotated[int, Form(ge=1)],
    idempotency_key: IdempotencyKey = None,
):
    if idempotency_key is not None:
        existing = crud.get_analysis_by_idempotency_key(
            session, club_id=club.id, key=idempotency_key
        )
        if existing is not None:
            response.status_code = 200
            return existing
    reference = crud.get_reference(session, club_id=club.id, reference_id=reference_id)
    if reference is None:
        raise not_found("reference", reference_id)
    if crud.get_performer(session, club_id=club.id, user_id=performer_id) is None:
        raise not_found("performer", performer_id)

    analysis_id = str(uuid.uuid4())
    suffix = Storage.video_suffix(video.filename)
    tmp = storage.new_tmp_dir()
    work_dir = storage.analysis_dir(analysis_id)
    try:
        upload = tmp / f"video{suffix}"
        try:
            await storage.receive(video, upload, settings.max_video_bytes)
        except UploadTooLarge as exc:
            raise ApiError(
                413, "too_large", f"the video is larger than the limit of {exc.limit} bytes",
                {"limit_bytes": exc.limit},
            ) from None  # fmt: skip
        try:
            info = await run_in_threadpool(validation.probe_video, upload, settings)
        except InvalidInput as exc:
            raise ApiError(422, "invalid_video", str(exc)) from None
        video_path = storage.move(upload, work_dir / f"video{suffix}")
        analysis = Analysis(
            id=analysis_id,
            club_id=club.id,
            performer_id=performer_id,
            reference_id=reference_id,
            video_path=str(video_path),
            work_dir=str(work_dir),
            status="queued",
            message=f"queued ({info['frames']} frames at {info['fps']:.1f} fps)",
            idempotency_key=idempotency_key,
        )
        session.add(analysis)
        try:
            session.commit()
        except IntegrityError:
            # A concurrent retry with the same Idempotency-Key won the race.
            session.rollback()
            Storage.remove(work_dir)
            existing = crud.get_analysis_by_idempotency_key(
                session, club_id=club.id, key=idempotency_key or ""
            )
            if existing is None:
                raise
            response.status_code = 200
            return existing
        job = analysis_job(analysis, reference, settings.engine_preset)
        try:
            analysis.task_id = await run_in_threadpool(queue.enqueue, job)
        except QueueUnavailable as exc:
            session.delete(analysis)
            session.commit()
            raise ApiError(503, "queue_unavailable", str(exc)) from None
        session.commit()
        log.info("analysis.queued analysis=%s task=%s", analysis_id, analysis.task_id)
        return analysis
    except BaseException:
        session.rollback()
        if crud.get_analysis(session, club_id=club.id, analysis_id=analysis_id) is None:
            Storage.remove(work_dir)
        raise
    finally:
        Storage.remove(tmp)


@router.get("", response_model=AnalysesPublic, summary="The club's analyses, newest first")
def list_analyses(
    club: CurrentClub,
    session: SessionDep,
    page: PageDep,
    notifier: NotifierDep,
    performer_id: Annotated[int | None, Query(ge=1)] = None,
    reference_id: Annotated[int | None, Query(ge=1)] = None,
    status: Annotated[AnalysisState | None, Query()] = None,
    created_after: Annotated[datetime | None, Query()] = None,
    created_before: Annotated[datetime | None, Query()] = None,
):
    items, total = crud.list_analyses(
        session,
        club_id=club.id,
        limit=page.limit,
        offset=page.offset,
        performer_id=performer_id,
        reference_id=reference_id,
        status=status,
        created_after=created_after,
        created_before=created_before,
    )
    for a in items:
        reflect(session, a, on_final=notifier)
    return AnalysesPublic(
        items=[_public(a) for a in items], total=total, limit=page.limit, offset=page.offset
    )


@router.get(
    "/{analysis_id}", response_model=AnalysisPublic, summary="Status and progress",
    responses=errors(404),
)  # fmt: skip
def read_analysis(analysis_id: str, club: CurrentClub, session: SessionDep, notifier: NotifierDep):
    analysis = _get(session, club, analysis_id)
    reflect(session, analysis, on_final=notifier)
    return analysis


def _done(session, club: Club, analysis_id: str, notifier) -> Analysis:
    analysis = _get(session, club, analysis_id)
    reflect(session, analysis, on_final=notifier)
    if analysis.status != "done" or not analysis.result_path:
        raise ApiError(
            409, "not_ready", f"analysis {analysis_id} is {analysis.status}, not done",
            {"status": analysis.status, "progress": analysis.progress},
        )  # fmt: skip
    return analysis


@router.get(
    "/{analysis_id}/result",
    summary="The result JSON (DESIGN.md) once the analysis is done",
    description=ONE_CAMERA_NOTE,
    responses={200: {"content": {"application/json": {}}}} | errors(404, 409),
)
def read_result(analysis_id: str, club: CurrentClub, session: SessionDep, notifier: NotifierDep):
    analysis = _done(session, club, analysis_id, notifier)
    return FileResponse(analysis.result_path, media_type="application/json")


def misfit_bones(frames: list[dict[str, Any]], height: float) -> list[str]:
    """Up to two bones whose picture differs most between the reported posture and the one
    that fits the video best, over ``image_misfit`` frames carrying ``image_best_joints_2d``.

    Bone vectors are compared in pixels, so a shift of the whole body does not count; a bone
    must differ by what a viewer notices (``height`` / 80, at least 3 px).
    """
    pairs = [(f["joints_2d"], f["image_best_joints_2d"]) for f in frames
             if f.get("image_best_joints_2d") and f.get("joints_2d")]  # fmt: skip
    if not pairs:
        return []
    p, g = (np.asarray(x, float) for x in zip(*pairs, strict=True))  # (k, 17, 2) each
    diff = (g[:, BONE_CHILD] - g[:, BONE_PARENT]) - (p[:, BONE_CHILD] - p[:, BONE_PARENT])
    d = np.linalg.norm(diff, axis=-1).mean(0)  # (16,)
    px = max(3.0, height / 80)
    return [BONE_NAMES[b] for b in np.argsort(-d)[:2] if d[b] >= px]


def summarise_segments(result: dict[str, Any]) -> list[SegmentPublic]:
    out = []
    misfit = [
        f for f in result.get("frames") or [] if "image_misfit" in (f.get("flags") or ())
    ]
    height = float((result.get("video") or {}).get("height") or 0)
    for i, seg in enumerate(result.get("segments") or []):
        inside = [f for f in misfit if seg["performer_start"] <= f["t"] <= seg["performer_end"]]
        bones = [float(e) for e in seg.get("bone_mean_errors_deg") or []]
        named = dict(zip(BONE_NAMES, bones, strict=False))
        worst = max(named, key=named.__getitem__) if named else None
        ref_len = seg["reference_end"] - seg["reference_start"]
        perf_len = seg["performer_end"] - seg["performer_start"]
        ref_fps = float((result.get("reference") or {}).get("fps") or 0)
        vid_fps = float((result.get("video") or {}).get("fps") or 0)
        tempo = None
        if ref_len > 0 and ref_fps > 0 and vid_fps > 0:
            tempo = (perf_len / vid_fps) / (ref_len / ref_fps)
        out.append(
            SegmentPublic(
                index=i,
                reference_start=seg["reference_start"],
                reference_end=seg["reference_end"],
                performer_start=seg["performer_start"],
                performer_end=seg["performer_end"],
                tempo_ratio=tempo,
                mean_error_deg=float(seg.get("mean_error_deg", 0.0)),
                worst_bone=worst,
                worst_bone_error_deg=named[worst] if worst else None,
                bone_mean_errors_deg=named,
                misfit_frames=len(inside),
                misfit_bones=misfit_bones(inside, height),
                bone_uncertainty_deg=dict(
                    zip(BONE_NAMES, seg.get("bone_uncertainty_deg", []), strict=False)
                ),
            )
        )
    return out


@router.get(
    "/{analysis_id}/segments",
    response_model=SegmentsPublic,
    summary="Per-segment summary: timing against the reference and the worst bone",
    description=ONE_CAMERA_NOTE,
    responses=errors(404, 409),
)
def read_segments(analysis_id: str, club: CurrentClub, session: SessionDep, notifier: NotifierDep):
    analysis = _done(session, club, analysis_id, notifier)
    result = Storage.read_json(analysis.result_path)
    if result is None:
        raise ApiError(409, "not_ready", "the result file cannot be read yet")
    try:
        segments = summarise_segments(result)
    except (KeyError, TypeError, ValueError) as exc:
        raise ApiError(500, "bad_result", f"the result has malformed segments ({exc})") from None
    return SegmentsPublic(analysis_id=analysis.id, segments=segments)


def _revoke(queue, analysis: Analysis) -> None:
    if analysis.task_id:
        try:
            queue.revoke(analysis.task_id)
        except QueueUnavailable as exc:
            log.warning("analysis.revoke_failed analysis=%s error=%s", analysis.id, exc)


@router.post(
    "/{analysis_id}/cancel", response_model=AnalysisPublic, summary="Cancel a running analysis",
    responses=errors(404, 409),
)  # fmt: skip
def cancel_analysis(
    analysis_id: str, club: CurrentClub, session: SessionDep, queue: QueueDep,
    notifier: NotifierDep,
):  # fmt: skip
    analysis = _get(session, club, analysis_id)
    reflect(session, analysis, on_final=notifier)
    if analysis.status in TERMINAL_STATES:
        raise ApiError(
            409, "conflict", f"analysis {analysis_id} is already {analysis.status}",
            {"status": analysis.status},
        )  # fmt: skip
    _revoke(queue, analysis)
    analysis.status = "cancelled"
    analysis.message = "cancelled on request"
    session.commit()
    return analysis


@router.delete(
    "/{analysis_id}", status_code=204, summary="Delete an analysis and its files",
    responses=errors(404),
)  # fmt: skip
def delete_analysis(
    analysis_id: str, club: CurrentClub, session: SessionDep, storage: StorageDep,
    queue: QueueDep,
) -> Response:  # fmt: skip
    analysis = _get(session, club, analysis_id)
    if analysis.status not in TERMINAL_STATES:
        _revoke(queue, analysis)
    work_dir = analysis.work_dir
    session.delete(analysis)
    session.commit()
    Storage.remove(work_dir)
    return Response(status_code=204)


@router.get(
    "/{analysis_id}/events",
    summary="Server-sent events of progress until done, failed or cancelled",
    description=(
        "`event: progress` with the analysis JSON whenever status, stage, progress or message "
        "changes; a final `event: end`. Comment lines keep idle connections alive."
    ),
    responses={200: {"content": {"text/event-stream": {}}}} | errors(404),
)
async def analysis_events(
    analysis_id: str,
    request: Request,
    club: CurrentClub,
    session: SessionDep,
    settings: SettingsDep,
    notifier: NotifierDep,
) -> StreamingResponse:
    _get(session, club, analysis_id)
    sessions = request.app.state.sessionmaker
    club_id = club.id

    def snapshot() -> dict | None:
        with sessions() as s:
            a = crud.get_analysis(s, club_id=club_id, analysis_id=analysis_id)
            if a is None:
                return None
            reflect(s, a, on_final=notifier)
            return _public(a).model_dump(mode="json")

    async def stream() -> AsyncIterator[str]:
        last_key = None
        sent_at = time.monotonic()
        deadline = sent_at + settings.sse_max_s
        n = 0
        while time.monotonic() < deadline:
            data = await run_in_threadpool(snapshot)
            if data is None:
                yield 'event: end\ndata: {"status": "deleted"}\n\n'
                return
            key = (data["status"], data["stage"], data["progress"], data["message"])
            if key != last_key:
                n += 1
                last_key = key
                sent_at = time.monotonic()
                yield f"id: {n}\nevent: progress\ndata: {json.dumps(data)}\n\n"
            if data["status"] in TERMINAL_STATES:
                yield f"event: end\ndata: {json.dumps({'status': data['status']})}\n\n"
                return
            if await request.is_disconnected():
                return
            if time.monotonic() - sent_at > 15:
                sent_at = time.monotonic()
                yield ": keep-alive\n\n"
            await asyncio.sleep(settings.sse_poll_s)

    return StreamingResponse(
        stream(),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )
