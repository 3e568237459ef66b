"""Reference-free captures (issue 23): a performer's 3D motion from one video, no expert
needed. Upload, follow, answer the questions the video leaves open, download as BVH or CSV,
or put it in the club's reference library."""

import shutil
import uuid
from datetime import datetime
from typing import Annotated, Literal

from fastapi import APIRouter, File, Form, Query, Request, Response, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import FileResponse

from app import crud
from app.api.access import capture_for
from app.api.deps import (
    CREATED,
    CurrentCoach,
    CurrentPrincipal,
    PageDep,
    QueueDep,
    SessionDep,
    SettingsDep,
    StorageDep,
    location,
)
from app.api.errors import ApiError, errors, not_found
from app.api.params import MAX_ID
from app.api.routes.analyses import performer_shown, receive_video
from app.api.routes.references import add_reference
from app.core import media, validation
from app.core.queue import QueueUnavailable
from app.core.storage import Storage
from app.models import TERMINAL_STATES, Capture
from app.schemas import (
    CaptureAnswers,
    CapturePublic,
    CaptureQuestion,
    CapturesPublic,
    CaptureToReference,
    ReferencePublic,
)
from worker.contract import CaptureFolder, CaptureJob
from worker.engine_surface import InvalidInput

router = APIRouter(prefix="/captures", tags=["captures"], responses=errors(401, 429))

_SIGN = {"towards": -1, "yes": -1, "away": 1, "no": 1}


def reflect_capture(session, capture: Capture) -> Capture:
    """Copy the worker's status.json into the row when it was written after the row last
    changed (a capture queued again with answers stays "queued" until a worker takes it)."""
    status = Storage.read_json(CaptureFolder(capture.work_dir).status) or {}
    state = status.get("state")
    if state in ("queued", "running", "done", "failed") and _newer(status, capture):
        new = (
            state,
            float(status.get("progress") or 0.0),
            str(status.get("message") or ""),
            status.get("error"),
        )
        if new != (capture.status, capture.progress, capture.message, capture.error):
            capture.status, capture.progress, capture.message, capture.error = new
            session.commit()
    return capture


def public(capture: Capture) -> CapturePublic:
    """The row, and its summary once done."""
    out = CapturePublic.model_validate(capture)
    summary = Storage.read_json(CaptureFolder(capture.work_dir).summary)
    if out.status == "done" and summary:
        out.frames, out.fps = summary.get("frames"), summary.get("fps")
        out.questions = [CaptureQuestion.model_validate(q) for q in summary.get("questions") or ()]
    return out


def _newer(status: dict, capture: Capture) -> bool:
    """Whether the worker's status.json is news for the row: always, but for a row queued
    (again, with answers) after the file was written, which stays "queued" until a worker
    takes it."""
    try:
        written = datetime.fromisoformat(status["updated"])
    except (KeyError, TypeError, ValueError):
        return False
    return capture.status != "queued" or written >= capture.updated_at


async def _queue(session, queue, capture: Capture) -> None:
    job = CaptureJob(
        capture_id=capture.id,
        video_path=capture.video_path,
        work_dir=capture.work_dir,
        height_m=capture.height_m,
        answers=dict(capture.answers or {}),
    )
    try:
        capture.task_id = await run_in_threadpool(queue.enqueue_capture, job)
    except QueueUnavailable as exc:
        raise ApiError(503, "queue_unavailable", str(exc)) from None
    session.commit()


@router.post(
    "",
    status_code=201,
    response_model=CapturePublic,
    summary="Upload a video and capture its 3D motion (no reference needed)",
    description=(
        "The video is checked as for an analysis (size, length, decodable). The capture runs "
        "in a worker: the learned pose model's 2D pose, each bone's depth from its "
        "foreshortening, depth signs from continuity, joint limits and the model's depth "
        "hint. Where the video leaves a sign open, the done capture lists `questions`; "
        "answer them with `POST /captures/{id}/answers`. 201 with its `Location`."
    ),
    responses=CREATED | errors(404, 413, 422, 503),
)
async def create_capture(
    request: Request,
    response: Response,
    who: CurrentPrincipal,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    queue: QueueDep,
    video: Annotated[UploadFile, File(description="The performer's video, whole body in view.")],
    performer_id: Annotated[
        int | None,
        Form(ge=1, le=MAX_ID, description="Whom the video shows (a performer: themselves)."),
    ] = None,
    height_m: Annotated[float, Form(ge=0.5, le=2.5, description="Performer's height, m.")] = 1.75,
    name: Annotated[str | None, Form(min_length=1, max_length=200)] = None,
):
    performer = performer_shown(who, performer_id)
    if crud.get_performer(session, club_id=who.club.id, user_id=performer) is None:
        raise not_found("performer", performer)
    capture_id = str(uuid.uuid4())
    suffix = Storage.video_suffix(video.filename)
    tmp = storage.new_tmp_dir()
    work_dir = storage.capture_dir(capture_id)
    try:
        upload = tmp / f"video{suffix}"
        info = await receive_video(video, upload, storage, settings)
        path = Storage.move(upload, CaptureFolder(work_dir).video(suffix))
        label = name or (video.filename or "capture").rsplit("/", 1)[-1][:200]
        capture = Capture(
            id=capture_id,
            club_id=who.club.id,
            performer_id=performer,
            name=label,
            video_path=str(path),
            work_dir=str(work_dir),
            height_m=height_m,
            status="queued",
            message=f"queued ({info['frames']} frames at {info['fps']:.1f} fps)",
        )
        session.add(capture)
        session.commit()
        await _queue(session, queue, capture)
    except BaseException:
        session.rollback()
        row = session.get(Capture, capture_id)
        if row is not None:
            session.delete(row)
            session.commit()
        Storage.remove(work_dir)
        raise
    finally:
        Storage.remove(tmp)
    response.headers["Location"] = location(request, "read_capture", capture_id=capture_id)
    return public(capture)


@router.get("", response_model=CapturesPublic, summary="The club's captures (a performer's own)")
def list_captures(who: CurrentPrincipal, session: SessionDep, page: PageDep):
    rows, total = crud.list_captures(
        session,
        club_id=who.club.id,
        limit=page.limit,
        offset=page.offset,
        performer_id=who.own_performer_id,
    )
    return CapturesPublic(
        items=[public(reflect_capture(session, c)) for c in rows],
        total=total,
        limit=page.limit,
        offset=page.offset,
    )


@router.get(
    "/{capture_id}",
    response_model=CapturePublic,
    summary="A capture: status, then questions",
    responses=errors(404),
)
def read_capture(capture_id: str, who: CurrentPrincipal, session: SessionDep):
    return public(reflect_capture(session, capture_for(session, who, capture_id)))


def _done(session, who, capture_id: str) -> Capture:
    capture = reflect_capture(session, capture_for(session, who, capture_id))
    if capture.status != "done":
        raise ApiError(409, "not_ready", f"capture {capture_id} is not done")
    return capture


@router.get(
    "/{capture_id}/motion.bvh",
    summary="The captured motion as BVH (root motion, one frame per video frame)",
    responses={200: {"content": {"text/plain": {}}}} | errors(404, 409),
)
def capture_bvh(
    capture_id: str,
    who: CurrentPrincipal,
    session: SessionDep,
    skeleton: Annotated[Literal["cmu", "coach"], Query(description="Joint names.")] = "cmu",
):
    folder = CaptureFolder(_done(session, who, capture_id).work_dir)
    path = folder.bvh if skeleton == "cmu" else folder.bvh_coach
    return FileResponse(path, media_type="text/plain", filename=f"capture-{capture_id[:8]}.bvh")


@router.get(
    "/{capture_id}/video.mp4",
    summary="The captured video, converted to play in browsers",
    responses={200: {"content": {"video/mp4": {}}}} | errors(404, 422),
)
async def capture_video(capture_id: str, who: CurrentPrincipal, session: SessionDep):
    c = capture_for(session, who, capture_id)
    try:
        path = await run_in_threadpool(media.playable_video, c.video_path, c.work_dir)
    except Exception:  # a broken upload: say so instead of a 500 page
        raise ApiError(
            422, "invalid_video", "the video cannot be converted to play in a browser"
        ) from None
    return FileResponse(path, media_type="video/mp4")


@router.get(
    "/{capture_id}/angles.csv",
    summary="Joint positions and angles per frame",
    responses={200: {"content": {"text/csv": {}}}} | errors(404, 409),
)
def capture_csv(capture_id: str, who: CurrentPrincipal, session: SessionDep):
    folder = CaptureFolder(_done(session, who, capture_id).work_dir)
    return FileResponse(folder.csv, media_type="text/csv", filename=f"capture-{capture_id[:8]}.csv")


@router.post(
    "/{capture_id}/answers",
    response_model=CapturePublic,
    status_code=202,
    summary="Answer the capture's questions; it runs again with them",
    description=(
        "`answers` maps question ids (from `questions`) to `towards` or `away` (`yes` or "
        "`no` for the facing question). Answers add to earlier ones. 202: the capture is "
        "queued again; 409 while it runs; 422 for an id it did not ask."
    ),
    responses=errors(404, 409, 422, 503),
)
async def answer_capture(
    capture_id: str,
    body: CaptureAnswers,
    who: CurrentPrincipal,
    session: SessionDep,
    queue: QueueDep,
):
    capture = _done(session, who, capture_id)
    asked = {q.id for q in public(capture).questions}
    unknown = sorted(set(body.answers) - asked)
    if unknown:
        raise ApiError(
            422,
            "invalid_request",
            f"the capture did not ask {', '.join(unknown)}",
            {"asked": sorted(asked)},
        )
    capture.answers = dict(capture.answers or {}) | {k: _SIGN[v] for k, v in body.answers.items()}
    capture.status, capture.progress, capture.message = "queued", 0.0, "queued with your answers"
    session.commit()
    await _queue(session, queue, capture)
    return public(capture)


@router.post(
    "/{capture_id}/reference",
    status_code=201,
    response_model=ReferencePublic,
    summary="Use the capture as a reference in the club's library",
    responses=CREATED | errors(403, 404, 409, 422),
)
async def capture_to_reference(
    request: Request,
    response: Response,
    capture_id: str,
    body: CaptureToReference,
    who: CurrentCoach,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
):
    capture = _done(session, who, capture_id)
    tmp = storage.new_tmp_dir()
    try:
        bvh = tmp / "reference.bvh"
        shutil.copyfile(CaptureFolder(capture.work_dir).bvh, bvh)
        try:
            derived = await run_in_threadpool(validation.inspect_reference, bvh, None, settings)
        except InvalidInput as exc:
            raise ApiError(422, "invalid_reference", str(exc)) from None
        ref = add_reference(session, who, storage, body.name or capture.name, bvh, None, derived)
        capture.reference_id = ref.id
        session.commit()
    finally:
        Storage.remove(tmp)
    response.headers["Location"] = location(request, "read_reference", reference_id=ref.id)
    return ref


@router.delete(
    "/{capture_id}",
    status_code=204,
    summary="Delete a capture and its files",
    responses=errors(404, 409),
)
def delete_capture(capture_id: str, who: CurrentPrincipal, session: SessionDep) -> Response:
    capture = reflect_capture(session, capture_for(session, who, capture_id))
    if capture.status not in TERMINAL_STATES:
        raise ApiError(409, "running", "the capture is still running; delete it once it ends")
    work_dir = capture.work_dir
    session.delete(capture)
    session.commit()
    Storage.remove(work_dir)
    return Response(status_code=204)
