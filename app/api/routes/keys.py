from fastapi import APIRouter, Request, Response

from app import crud
from app.api.deps import CREATED, CoachClub, PageDep, SessionDep, location
from app.api.errors import errors, not_found
from app.api.params import DbId
from app.schemas import ApiKeyCreate, ApiKeyCreated, ApiKeyPublic, ApiKeysPublic

router = APIRouter(prefix="/keys", tags=["keys"], responses=errors(401, 429))


@router.post(
    "",
    status_code=201,
    response_model=ApiKeyCreated,
    summary="Create another API key for the club (the key is shown once)",
    description="201 with the key's `Location`. Send it as `X-API-Key: <key>` or "
    "`Authorization: Bearer <key>`.",
    responses=CREATED | errors(422),
)
def create_key(
    club: CoachClub,
    session: SessionDep,
    request: Request,
    response: Response,
    body: ApiKeyCreate | None = None,
):
    row, key = crud.create_api_key(session, club_id=club.id, name=(body.name if body else ""))
    response.headers["Location"] = location(request, "read_key", key_id=row.id)
    return ApiKeyCreated(**ApiKeyPublic.model_validate(row).model_dump(), key=key)


@router.get("", response_model=ApiKeysPublic, summary="The club's keys (prefixes only)")
def list_keys(club: CoachClub, session: SessionDep, page: PageDep):
    items, total = crud.list_api_keys(
        session, club_id=club.id, limit=page.limit, offset=page.offset
    )
    return ApiKeysPublic(items=items, total=total, limit=page.limit, offset=page.offset)


@router.get(
    "/{key_id}", response_model=ApiKeyPublic, summary="One key (its prefix only)",
    responses=errors(404),
)  # fmt: skip
def read_key(key_id: DbId, club: CoachClub, session: SessionDep):
    row = crud.get_api_key(session, club_id=club.id, key_id=key_id)
    if row is None:
        raise not_found("API key", key_id)
    return row


@router.delete("/{key_id}", status_code=204, summary="Revoke a key", responses=errors(404))
def revoke_key(key_id: DbId, club: CoachClub, session: SessionDep) -> Response:
    row = crud.get_api_key(session, club_id=club.id, key_id=key_id)
    if row is None:
        raise not_found("API key", key_id)
    crud.revoke_api_key(session, row)
    return Response(status_code=204)
