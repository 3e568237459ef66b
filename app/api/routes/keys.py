from fastapi import APIRouter, Response

from app import crud
from app.api.deps import CoachClub, SessionDep
from app.api.errors import errors, not_found
from app.schemas import ApiKeyCreate, ApiKeyCreated, ApiKeyPublic

router = APIRouter(prefix="/keys", tags=["keys"], responses=errors(401, 429))


@router.post(
    "",
    status_code=201,
    response_model=ApiKeyCreated,
    summary="Create another API key for the club (the key is shown once)",
    responses=errors(422),
)
def create_key(club: CoachClub, session: SessionDep, body: ApiKeyCreate | None = None):
    row, key = crud.create_api_key(session, club_id=club.id, name=(body.name if body else ""))
    return ApiKeyCreated(**ApiKeyPublic.model_validate(row).model_dump(), key=key)


@router.get("", response_model=list[ApiKeyPublic], summary="The club's keys (prefixes only)")
def list_keys(club: CoachClub, session: SessionDep):
    return crud.list_api_keys(session, club_id=club.id)


@router.delete("/{key_id}", status_code=204, summary="Revoke a key", responses=errors(404))
def revoke_key(key_id: int, club: CoachClub, session: SessionDep) -> Response:
    row = crud.get_api_key(session, club_id=club.id, key_id=key_id)
    if row is None:
        raise not_found("API key", key_id)
    crud.revoke_api_key(session, row)
    return Response(status_code=204)
