"""Browser sign-in: a server-side session (app.core.sessions) behind a signed cookie."""

from fastapi import APIRouter, Request, Response

from app import crud
from app.api.deps import CurrentUser, SessionDep, SettingsDep
from app.api.errors import ApiError, errors, rate_limited
from app.core import security, sessions
from app.core.ratelimit import SignInThrottle
from app.schemas import LoginRequest, PasswordChange, UserPublic

router = APIRouter(prefix="/session", tags=["session"])


def _throttle(request: Request) -> SignInThrottle:
    return request.app.state.signin_throttle


def _client_ip(request: Request) -> str:
    return request.client.host if request.client else "unknown"


@router.post(
    "", response_model=UserPublic, summary="Sign in (sets the session cookie)",
    description=(
        "Failed attempts are throttled per account and per client address: after a few, "
        "each further failure doubles a lock-out, answered with 429 and `Retry-After`."
    ),
    responses=errors(401, 422, 429),
)  # fmt: skip
def sign_in(body: LoginRequest, request: Request, session: SessionDep, settings: SettingsDep):
    throttle = _throttle(request)
    keys = throttle.keys(body.email, _client_ip(request))
    wait = throttle.wait(keys)
    if wait > 0:
        raise rate_limited(wait, "too many failed sign-ins")
    user = crud.authenticate(session, email=body.email, password=body.password)
    if user is None:
        throttle.failed(keys)
        raise ApiError(401, "unauthorized", "wrong email or password")
    throttle.succeeded(body.email)
    sessions.start(request, session, user, settings.session_max_age_s)
    return user


@router.get("", response_model=UserPublic, summary="The signed-in user", responses=errors(401))
def whoami(user: CurrentUser):
    return user


@router.delete("", status_code=204, summary="Sign out (the cookie stops working everywhere)")
def sign_out(request: Request, session: SessionDep) -> Response:
    sessions.end(request, session)
    return Response(status_code=204)


@router.put(
    "/password", status_code=204, summary="Change your password",
    description="Signs you out on every other browser; this one gets a new session.",
    responses=errors(401, 422),
)  # fmt: skip
def change_password(
    body: PasswordChange, request: Request, user: CurrentUser, session: SessionDep,
    settings: SettingsDep,
) -> Response:  # fmt: skip
    if not security.verify_password(body.current_password, user.password_hash):
        raise ApiError(401, "unauthorized", "the current password is wrong")
    user.password_hash = security.hash_password(body.new_password)
    session.commit()
    sessions.revoke_all(session, user.id)
    sessions.start(request, session, user, settings.session_max_age_s)
    return Response(status_code=204)
