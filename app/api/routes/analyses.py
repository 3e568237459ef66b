import asyncio
import hashlib
import json
import logging
import tempfile
import time
import uuid
from collections.abc import AsyncIterator
from pathlib import Path
from typing import IO, Annotated, Any

from fastapi import APIRouter, File, Form, Header, Query, Request, Response, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse, JSONResponse, PlainTextResponse, StreamingResponse
from sqlalchemy.exc import IntegrityError
from starlette.background import BackgroundTask

from app import crud
from app.api.access import analysis_for, done_analysis, reference_for, result_of
from app.api.deps import (
    CREATED,
    CurrentPrincipal,
    NotifierDep,
    PageDep,
    Principal,
    QueueDep,
    SessionDep,
    SettingsDep,
    StorageDep,
    location,
)
from app.api.errors import ApiError, errors, not_found
from app.api.params import MAX_ID, DbIdForm, DbIdQuery, Instant
from app.core import media, summary, validation
from app.core.config import Settings
from app.core.queue import JobQueue, PublishFailed, QueueUnavailable, analysis_job
from app.core.reflect import reflect
from app.core.storage import Storage, UploadTooLarge
from app.models import TERMINAL_STATES, Analysis
from app.schemas import (
    AnalysesPublic,
    AnalysisPublic,
    AnalysisState,
    SegmentsPublic,
)
from worker.contract import AnalysisFolder, AnalysisJob
from worker.engine_surface import ONE_CAMERA_NOTE, InvalidInput, Result

log = logging.getLogger("app.analyses")

router = APIRouter(prefix="/analyses", tags=["analyses"], responses=errors(401, 429))

IdempotencyKey = Annotated[
    str | None,
    Header(
        alias="Idempotency-Key",
        min_length=1,
        max_length=255,
        description=(
            "Retrying an upload with the same key returns the same analysis (200); the key "
            "used again for a different upload (another video, reference or performer) is a "
            "409."
        ),
    ),
]


def _public(analysis: Analysis) -> AnalysisPublic:
    return AnalysisPublic.model_validate(analysis)


@router.post(
    "",
    status_code=201,
    response_model=AnalysisPublic,
    summary="Upload a performer's video and start its analysis",
    description=(
        "The video is streamed to disk, size-limited and decoded (first frames) before it is "
        "accepted. 201 for a new analysis, with its `Location`; 200 with the existing one when "
        "the Idempotency-Key was already used by this club for the same upload (the same "
        "video, reference and performer); 409 `idempotency_conflict` when it was used for a "
        "different one."
    ),
    responses={200: {"model": AnalysisPublic, "description": "Idempotent replay"}}
    | CREATED
    | errors(404, 409, 413, 422, 503),
)
async def create_analysis(
    request: Request,
    response: Response,
    who: CurrentPrincipal,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    queue: QueueDep,
    video: Annotated[UploadFile, File(description="The performer's video.")],
    reference_id: DbIdForm,
    performer_id: Annotated[
        int | None,
        Form(ge=1, le=MAX_ID, description="Whom the video shows (a performer: themselves)."),
    ] = None,
    idempotency_key: IdempotencyKey = None,
):
    club = who.club
    performer_id = performer_shown(who, performer_id)
    fingerprint = None
    if idempotency_key is not None:
        video_sha256 = await run_in_threadpool(_sha256_of, video.file)
        fingerprint = _fingerprint(reference_id, performer_id, video_sha256)
        existing = crud.get_analysis_by_idempotency_key(
            session, club_id=club.id, key=idempotency_key
        )
        if existing is not None:
            response.status_code = 200
            return _replay(existing, idempotency_key, fingerprint)
    reference = reference_for(session, who, reference_id)
    if crud.get_performer(session, club_id=club.id, user_id=performer_id) is None:
        raise not_found("performer", performer_id)

    analysis_id = str(uuid.uuid4())
    suffix = Storage.video_suffix(video.filename)
    tmp = storage.new_tmp_dir()
    work_dir = storage.analysis_dir(analysis_id)
    try:
        upload = tmp / f"video{suffix}"
        info = await receive_video(video, upload, storage, settings)
        video_path = storage.move(upload, AnalysisFolder(work_dir).video(suffix))
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
            idempotency_fingerprint=fingerprint,
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
            return _replay(existing, idempotency_key or "", fingerprint)
        job = analysis_job(analysis, reference, settings.engine_preset)
        await enqueue(session, queue, analysis, job)
        response.headers["Location"] = location(request, "read_analysis", analysis_id=analysis.id)
        return analysis
    except BaseException:
        session.rollback()
        if crud.get_analysis(session, club_id=club.id, analysis_id=analysis_id) is None:
            Storage.remove(work_dir)
        raise
    finally:
        Storage.remove(tmp)


def _sha256_of(f: IO[bytes]) -> str:
    """The hex sha256 of the spooled upload, which is then rewound for its copy."""
    digest = hashlib.sha256()
    f.seek(0)
    while chunk := f.read(1024 * 1024):
        digest.update(chunk)
    f.seek(0)
    return digest.hexdigest()


def _fingerprint(reference_id: int, performer_id: int, video_sha256: str) -> str:
    """What makes two uploads under one Idempotency-Key the same request."""
    fields = json.dumps([reference_id, performer_id, video_sha256])
    return hashlib.sha256(fields.encode()).hexdigest()


def _replay(existing: Analysis, key: str, fingerprint: str | None) -> Analysis:
    """The analysis made by an earlier upload with this key; 409 when that upload differed.

    Rows made before fingerprints were kept have none and are taken as the same.
    """
    if existing.idempotency_fingerprint not in (None, fingerprint):
        raise ApiError(
            409, "idempotency_conflict",
            "this Idempotency-Key was already used for a different upload (another video, "
            "reference or performer); use a new key for a new upload",
            {"analysis_id": existing.id},
        )  # fmt: skip
    return existing


async def receive_video(
    video: UploadFile, upload: Path, storage: Storage, settings: Settings
) -> dict[str, Any]:
    """Stream the upload to ``upload`` within the size limit and probe it: 413 when too
    large, 422 when it is not a video the engine can read."""
    try:
        await storage.receive(video, upload, settings.max_video_bytes)
    except UploadTooLarge as exc:
        raise ApiError(
            413, "too_large", f"the video is larger than the limit of {exc.limit} bytes",
            {"limit_bytes": exc.limit},
        ) from None  # fmt: skip
    try:
        return await run_in_threadpool(validation.probe_video, upload, settings)
    except InvalidInput as exc:
        raise ApiError(422, "invalid_video", str(exc)) from None


async def enqueue(session, queue: JobQueue, analysis: Analysis, job: AnalysisJob) -> None:
    """Queue the analysis' job. The committed row is the record: a broker that does not take
    the job now gets it from recovery later (app.core.recovery); only a deployment without
    the worker package removes the row (503)."""
    try:
        analysis.task_id = await run_in_threadpool(queue.enqueue, job)
    except PublishFailed as exc:
        log.warning("analysis.publish_deferred analysis=%s error=%s", analysis.id, exc)
        return
    except QueueUnavailable as exc:
        session.delete(analysis)
        session.commit()
        raise ApiError(503, "queue_unavailable", str(exc)) from None
    session.commit()
    log.info("analysis.queued analysis=%s task=%s", analysis.id, analysis.task_id)


def performer_shown(who: Principal, performer_id: int | None) -> int:
    """Whom an upload shows: a performer uploads for themselves; a coach and an API key
    name the performer."""
    if who.own_performer_id is not None:
        return who.own_performer_id
    if performer_id is None or (who.user is not None and performer_id == who.user.id):
        raise ApiError(422, "invalid_request", "choose the performer this video shows")
    return performer_id


@router.get(
    "", response_model=AnalysesPublic,
    summary="The club's analyses (a performer's own), newest first",
)  # fmt: skip
def list_analyses(
    who: CurrentPrincipal,
    session: SessionDep,
    page: PageDep,
    notifier: NotifierDep,
    performer_id: DbIdQuery = None,
    reference_id: DbIdQuery = None,
    status: Annotated[AnalysisState | None, Query()] = None,
    created_after: Annotated[
        Instant | None,
        Query(description="Created at or after this ISO 8601 date-time (no zone: UTC)."),
    ] = None,
    created_before: Annotated[
        Instant | None,
        Query(description="Created before this ISO 8601 date-time (no zone: UTC)."),
    ] = None,
    reviewed: Annotated[
        bool | None, Query(description="Only those a coach has (true) or has not (false) reviewed.")
    ] = None,
):
    own = who.own_performer_id
    if own is not None and performer_id not in (None, own):
        return AnalysesPublic(items=[], total=0, limit=page.limit, offset=page.offset)
    items, total = crud.list_analyses(
        session,
        club_id=who.club.id,
        limit=page.limit,
        offset=page.offset,
        performer_id=own or performer_id,
        reference_id=reference_id,
        status=status,
        created_after=created_after,
        created_before=created_before,
        reviewed=reviewed,
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
def read_analysis(
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep
):
    analysis = analysis_for(session, who, analysis_id)
    reflect(session, analysis, on_final=notifier)
    return analysis


@router.get(
    "/{analysis_id}/result",
    summary="The result JSON (DESIGN.md) once the analysis is done",
    description=ONE_CAMERA_NOTE,
    responses={200: {"content": {"application/json": {}}}} | errors(404, 409),
)
def read_result(
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep,
    candidates: Annotated[bool, Query(
        description="false leaves out every frame's `candidates` (three quarters of the "
        "document); `selected` then indexes nothing and is left out too."
    )] = True,
):  # fmt: skip
    analysis = done_analysis(session, who, analysis_id, notifier)
    if candidates:
        return FileResponse(analysis.result_path, media_type="application/json")
    doc = json.loads(Path(analysis.result_path).read_text())
    for frame in doc.get("frames", []):
        frame.pop("candidates", None)
        frame.pop("selected", None)
    return JSONResponse(doc)


@router.get(
    "/{analysis_id}/provisional",
    summary="The first segments' results while the analysis still runs",
    description="Stage 4 on the whole segments whose frames are done, written while stage 3 "
    "works on the rest: the `/summary` of those segments, plus `provisional` (`frames` and "
    "`segments` covered, of `video_frames` and `reference_segments`). The final result may "
    "move the last covered boundary by a frame or two. 409 `not_ready` until a first "
    "segment is done, `done` once the final result is there (read `/summary`). "
    + ONE_CAMERA_NOTE,
    responses=errors(404, 409),
)
def read_provisional(
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep
) -> dict[str, Any]:
    analysis = analysis_for(session, who, analysis_id)
    reflect(session, analysis, on_final=notifier)
    if analysis.status == "done":
        raise ApiError(409, "done", "the final result is ready: read /summary")
    doc = Storage.read_json(AnalysisFolder(analysis.work_dir).provisional)
    if doc is None or analysis.status != "running":
        raise ApiError(
            409, "not_ready", "no whole segment has been analysed yet",
            {"status": analysis.status, "progress": analysis.progress},
        )  # fmt: skip
    try:
        result = Result.from_dict(doc)
    except InvalidInput as exc:
        raise ApiError(500, "bad_result", f"the provisional result is malformed ({exc})") from None
    return summary.page_summary(analysis, result) | {"provisional": doc["provisional"]}


@router.get(
    "/{analysis_id}/segments",
    response_model=SegmentsPublic,
    summary="Per-segment summary: timing against the reference and the worst bone",
    description=ONE_CAMERA_NOTE,
    responses=errors(404, 409),
)
def read_segments(
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep
):
    analysis = done_analysis(session, who, analysis_id, notifier)
    segments = summary.segments_or_error(result_of(analysis))
    return SegmentsPublic(analysis_id=analysis.id, segments=segments)


@router.get(
    "/{analysis_id}/angles",
    summary="Each joint's bend in every frame: the performer's and the expert's",
    description="`bends` (label, joint index), `performer` and `expert` as (frames, bends) "
    "degrees, 0 for a straight joint; the expert's at the matched moment. " + ONE_CAMERA_NOTE,
    responses=errors(404, 409),
)
def read_angles(
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep
) -> dict[str, Any]:
    analysis = done_analysis(session, who, analysis_id, notifier)
    ref = media.reference_joints(analysis.reference.bvh_path)
    return summary.bend_angles(result_of(analysis), ref)


@router.get(
    "/{analysis_id}/summary",
    summary="What the result page shows: named segments with tempo, score and worst bones",
    description=ONE_CAMERA_NOTE,
    responses=errors(404, 409),
)
def read_summary(
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep
) -> dict[str, Any]:
    analysis = done_analysis(session, who, analysis_id, notifier)
    return summary.page_summary(analysis, result_of(analysis))


@router.get(
    "/{analysis_id}/thumbnail.jpg", summary="A small picture of the video's first analysed frame",
    responses={200: {"content": {"image/jpeg": {}}}} | errors(404, 422),
)  # fmt: skip
async def read_thumbnail(analysis_id: str, who: CurrentPrincipal, session: SessionDep):
    a = analysis_for(session, who, analysis_id)
    try:
        path = await run_in_threadpool(
            media.video_thumbnail, a.video_path, a.work_dir, a.frames_start or 0
        )
    except Exception as exc:  # a broken upload: the list shows no picture, not a 500
        log.warning("analysis.thumbnail_failed analysis=%s error=%s", a.id, exc)
        raise ApiError(422, "invalid_video", "no picture can be made of this video") from None
    return FileResponse(path, media_type="image/jpeg")


@router.get(
    "/{analysis_id}/video.mp4", summary="The performer's video, converted to play in browsers",
    responses={200: {"content": {"video/mp4": {}}}} | errors(404, 422),
)  # fmt: skip
async def read_video(analysis_id: str, who: CurrentPrincipal, session: SessionDep):
    a = analysis_for(session, who, analysis_id)
    try:
        path = await run_in_threadpool(media.playable_video, a.video_path, a.work_dir)
    except Exception as exc:  # a broken upload: say so instead of a 500 page
        # The library's message names server paths and error numbers: logged, not sent.
        log.warning("analysis.video_unplayable analysis=%s error=%s", a.id, exc)
        raise ApiError(
            422, "invalid_video", "the video cannot be converted to play in a browser"
        ) from None
    return FileResponse(path, media_type="video/mp4")


@router.get(
    "/{analysis_id}/export.csv", summary="Per-frame errors and joint angles as CSV",
    responses={200: {"content": {"text/csv": {}}}} | errors(404, 409),
)  # fmt: skip
def export_csv(analysis_id: str, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep):
    a = done_analysis(session, who, analysis_id, notifier)
    return PlainTextResponse(
        media.result_csv(result_of(a)), media_type="text/csv",
        headers={"Content-Disposition": f'attachment; filename="analysis-{a.id[:8]}.csv"'},
    )  # fmt: skip


@router.get(
    "/{analysis_id}/export.bvh", summary="The performer's motion as BVH",
    responses={200: {"content": {"application/octet-stream": {}}}} | errors(404, 409),
)  # fmt: skip
async def export_bvh(
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep
):
    a = done_analysis(session, who, analysis_id, notifier)
    result = result_of(a)
    tmp = Path(tempfile.mkdtemp(prefix="coach-bvh-"))
    path = await run_in_threadpool(media.result_bvh, result, tmp / "performer.bvh")
    return FileResponse(
        path, media_type="application/octet-stream", filename=f"performer-{a.id[:8]}.bvh",
        background=BackgroundTask(Storage.remove, tmp),
    )  # fmt: skip


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
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, queue: QueueDep,
    notifier: NotifierDep,
):  # fmt: skip
    analysis = analysis_for(session, who, analysis_id)
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
    notifier(analysis)  # the club hears of it like of done and failed ones
    return analysis


@router.delete(
    "/{analysis_id}", status_code=204,
    summary="Delete an analysis and its files (a coach any, a performer their own)",
    responses=errors(404),
)  # fmt: skip
def delete_analysis(
    analysis_id: str, who: CurrentPrincipal, session: SessionDep, storage: StorageDep,
    queue: QueueDep,
) -> Response:  # fmt: skip
    analysis = analysis_for(session, who, analysis_id)
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
    who: CurrentPrincipal,
    session: SessionDep,
    settings: SettingsDep,
    notifier: NotifierDep,
) -> StreamingResponse:
    analysis_for(session, who, analysis_id)
    sessions = request.app.state.sessionmaker
    club_id = who.club.id

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
