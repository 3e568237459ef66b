"""Analyse another repetition of a video that holds several (issue 20, item 7).

The engine finds every repetition of the reference in a video and analyses the first; the
result lists them all (``summary.repetitions``). This route starts a new analysis of the same
video, the same reference and performer, limited to the repetition the user picked.
"""

from pathlib import Path as FilePath

from fastapi import APIRouter, Path, Request, Response

from app.api.access import done_analysis, reference_for, result_of
from app.api.deps import (
    CREATED,
    CurrentPrincipal,
    NotifierDep,
    QueueDep,
    SessionDep,
    SettingsDep,
    StorageDep,
    location,
)
from app.api.errors import ApiError, errors
from app.api.routes.analyses import enqueue
from app.core.queue import analysis_job
from app.core.storage import Storage
from app.models import Analysis
from app.schemas import AnalysisPublic
from worker.contract import AnalysisFolder

router = APIRouter(prefix="/analyses", tags=["analyses"], responses=errors(401, 429))


@router.post(
    "/{analysis_id}/repetitions/{number}",
    status_code=201,
    response_model=AnalysisPublic,
    summary="Analyse another repetition of the same video",
    description=(
        "When a done analysis found several repetitions of the reference in its video "
        "(`summary.repetitions` of its result, numbered from 1 in that order), this starts a "
        "new analysis of repetition `number` alone: the same video, reference and performer. "
        "201 with the new analysis' `Location`; 404 for a repetition the result does not list; "
        "409 while the analysis is not done."
    ),
    responses=CREATED | errors(404, 409, 503),
)
async def analyse_repetition(
    request: Request,
    response: Response,
    who: CurrentPrincipal,
    session: SessionDep,
    settings: SettingsDep,
    storage: StorageDep,
    queue: QueueDep,
    notifier: NotifierDep,
    analysis_id: str,
    number: int = Path(ge=1, le=1000, description="The repetition, from 1."),
):
    source = done_analysis(session, who, analysis_id, notifier)
    reps = result_of(source).summary.repetitions
    if number > len(reps):
        raise ApiError(
            404, "not_found",
            f"analysis {analysis_id} lists {len(reps)} repetitions, not {number}",
            {"repetitions": len(reps)},
        )  # fmt: skip
    rep = reps[number - 1]
    reference = reference_for(session, who, source.reference_id)
    new = Analysis(club_id=source.club_id, performer_id=source.performer_id,
                   reference_id=source.reference_id, video_path="", work_dir="",
                   status="queued", frames_start=rep.start, frames_end=rep.end,
                   message=f"queued (repetition {number} of {len(reps)}: "
                           f"{rep.start_s:.1f}-{rep.end_s:.1f} s)")  # fmt: skip
    session.add(new)
    session.flush()  # the id names the folder
    work_dir = storage.analysis_dir(new.id)
    try:
        src = FilePath(source.video_path)
        new.work_dir = str(work_dir)
        new.video_path = str(Storage.share(src, AnalysisFolder(work_dir).video(src.suffix)))
        session.commit()
        await enqueue(session, queue, new, analysis_job(new, reference, settings.engine_preset))
    except BaseException:
        session.rollback()
        Storage.remove(work_dir)
        raise
    response.headers["Location"] = location(request, "read_analysis", analysis_id=new.id)
    return new
