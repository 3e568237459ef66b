"""Browser sign-in: a signed session cookie (Starlette SessionMiddleware) for the web pages."""

from fastapi import APIRouter, Request, Response

from app import crud
from app.api.deps import CurrentUser, SessionDep
from app.api.errors import ApiError, errors
from app.schemas import LoginRequest, UserPublic

router = APIRouter(prefix="/session", tags=["session"])


@router.post("", response_model=UserPublic, summary="Sign in (sets the session cookie)",
             responses=errors(401, 422))  # fmt: skip
def sign_in(body: LoginRequest, request: Request, session: SessionDep):
    user = crud.authenticate(session, email=body.email, password=body.password)
    if user is None:
        raise ApiError(401, "unauthorized", "wrong email or password")
    request.session.clear()
    request.session["user_id"] = user.id
    request.session["club_id"] = user.club_id
    return user


@router.get("", response_model=UserPublic, summary="The signed-in user", responses=errors(401))
def whoami(user: CurrentUser):
    return user


@router.delete("", status_code=204, summary="Sign out")
def sign_out(request: Request) -> Response:
    request.session.clear()
    return Response(status_code=204)
