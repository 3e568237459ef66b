from fastapi import APIRouter

from app import crud
from app.api.deps import CoachClub, SessionDep
from app.api.errors import errors
from app.schemas import ClubPublic, ClubUpdate, ClubUpdated

router = APIRouter(prefix="/club", tags=["club"], responses=errors(401, 429))


@router.get("", response_model=ClubPublic, summary="The caller's club")
def read_club(club: CoachClub) -> ClubPublic:
    return ClubPublic.model_validate(club)


@router.patch(
    "",
    response_model=ClubUpdated,
    summary="Rename the club or set its completion webhook",
    description=(
        "Setting a webhook URL for the first time (or `rotate_webhook_secret`) returns the "
        "signing secret once. Each delivery is a POST of JSON with "
        "`X-Coach-Signature: sha256=<hex HMAC-SHA256 of the body with the secret>`."
    ),
    responses=errors(422),
)
def update_club(club: CoachClub, body: ClubUpdate, session: SessionDep) -> ClubUpdated:
    secret = crud.update_club(
        session,
        club,
        name=body.name,
        webhook_url=None if body.webhook_url is None else str(body.webhook_url),
        rotate=body.rotate_webhook_secret,
    )
    return ClubUpdated.model_validate(club).model_copy(update={"webhook_secret": secret})
