from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response

from app import crud
from app.api.access import analysis_for, done_analysis, performer_for, result_of
from app.api.deps import (
    CREATED,
    CoachClub,
    CurrentPrincipal,
    NotifierDep,
    PageDep,
    SessionDep,
    location,
)
from app.api.errors import ApiError, errors
from app.api.params import DbId
from app.core import compare
from app.core.reflect import reflect
from app.core.summary import segment_names
from app.models import Analysis, User
from app.schemas import PerformerCreate, UserPublic, UsersPublic

router = APIRouter(prefix="/performers", tags=["performers"], responses=errors(401, 429))


@router.post(
    "", status_code=201, response_model=UserPublic, summary="Add a performer to the club",
    description="201 with the performer's `Location`.", responses=CREATED | errors(409, 422),
)  # fmt: skip
def create_performer(
    body: PerformerCreate, club: CoachClub, session: SessionDep, request: Request,
    response: Response,
):  # fmt: skip
    if crud.get_user_by_email(session, club_id=club.id, email=body.email) is not None:
        raise ApiError(
            409, "conflict", f"a user with email {body.email} already exists in this club",
            {"email": body.email},
        )  # fmt: skip
    user = crud.create_user(
        session,
        club_id=club.id,
        role="performer",
        email=body.email,
        display_name=body.display_name,
        password=body.password,
    )
    response.headers["Location"] = location(request, "read_performer", performer_id=user.id)
    return user


@router.get("", response_model=UsersPublic, summary="The club's performers")
def list_performers(club: CoachClub, session: SessionDep, page: PageDep):
    items, total = crud.list_performers(
        session, club_id=club.id, limit=page.limit, offset=page.offset
    )
    return UsersPublic(items=items, total=total, limit=page.limit, offset=page.offset)


@router.get(
    "/{performer_id}", response_model=UserPublic, summary="One performer",
    responses=errors(404),
)  # fmt: skip
def read_performer(performer_id: DbId, who: CurrentPrincipal, session: SessionDep):
    return performer_for(session, who, performer_id)


def _history(session, performer: User, notifier) -> list[dict[str, Any]]:
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


@router.get(
    "/{performer_id}/history", summary="A performer's analyses over time, with their errors",
    responses=errors(404),
)  # fmt: skip
def performer_history(
    performer_id: DbId, who: CurrentPrincipal, session: SessionDep, notifier: NotifierDep
) -> dict[str, Any]:
    p = performer_for(session, who, performer_id)
    return {
        "performer": {"id": p.id, "display_name": p.display_name},
        "analyses": _history(session, p, notifier),
    }


def _attempt(a: Analysis) -> dict[str, Any]:
    return {
        "id": a.id, "created_at": a.created_at.isoformat(), "url": f"/analyses/{a.id}",
        "video": f"/api/v1/analyses/{a.id}/video.mp4",
    }  # fmt: skip


@router.get(
    "/{performer_id}/compare",
    summary="Two of a performer's attempts against one reference, segment by segment",
    responses=errors(404, 409, 422),
)
def compare_attempts(
    performer_id: DbId,
    who: CurrentPrincipal,
    session: SessionDep,
    notifier: NotifierDep,
    a: Annotated[str, Query(max_length=36)],
    b: Annotated[str, Query(max_length=36)],
) -> dict[str, Any]:
    """Per-segment error and tempo with the change from A to B, and both error curves over
    the reference's frames."""
    p = performer_for(session, who, performer_id)
    first, second = analysis_for(session, who, a), analysis_for(session, who, b)
    if first.performer_id != p.id or second.performer_id != p.id:
        raise ApiError(422, "invalid_request", "both analyses must be this performer's")
    if first.reference_id != second.reference_id:
        raise ApiError(422, "invalid_request", "the two analyses use different references")
    ra = result_of(done_analysis(session, who, a, notifier))
    rb = result_of(done_analysis(session, who, b, notifier))
    n = max(len(ra.segments), len(rb.segments))
    data = compare.compare_results(ra, rb, segment_names(first.reference, n))
    return {
        "performer": {"id": p.id, "display_name": p.display_name},
        "reference": {"id": first.reference_id, "name": first.reference.name},
        "a": _attempt(first), "b": _attempt(second), **data,
    }  # fmt: skip
