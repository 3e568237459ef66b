from fastapi import APIRouter

from app import crud
from app.api.deps import CurrentClub, PageDep, SessionDep
from app.api.errors import ApiError, errors
from app.schemas import PerformerCreate, UserPublic

router = APIRouter(prefix="/performers", tags=["performers"], responses=errors(401, 429))


@router.post(
    "", status_code=201, response_model=UserPublic, summary="Add a performer to the club",
    responses=errors(409, 422),
)  # fmt: skip
def create_performer(body: PerformerCreate, club: CurrentClub, session: SessionDep):
    if crud.get_user_by_email(session, club_id=club.id, email=body.email) is not None:
        raise ApiError(
            409, "conflict", f"a user with email {body.email} already exists in this club",
            {"email": body.email},
        )  # fmt: skip
    return crud.create_user(
        session,
        club_id=club.id,
        role="performer",
        email=body.email,
        display_name=body.display_name,
        password=body.password,
    )


@router.get("", response_model=list[UserPublic], summary="The club's performers")
def list_performers(club: CurrentClub, session: SessionDep, page: PageDep):
    return crud.list_performers(session, club_id=club.id, limit=page.limit, offset=page.offset)
