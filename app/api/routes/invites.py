"""Invite links: a coach creates one for a new performer, who joins with it."""

from __future__ import annotations

from datetime import timedelta

from fastapi import APIRouter, Request, Response

from app.api.deps import CREATED, CurrentCoach, SessionDep, SettingsDep
from app.api.errors import ApiError, errors
from app.core import invites, sessions
from app.schemas import InviteCreate, InvitePublic, JoinBody, JoinedPublic

router = APIRouter(tags=["invites"])

_INVITE_STATUS = {"unknown": 404, "used": 410, "expired": 410, "invalid": 422}


@router.post(
    "/invites", status_code=201, response_model=InvitePublic,
    summary="A single-use link for a new performer (the token is in this answer only)",
    description="201 with the link's path (the join page) as its `Location`.",
    responses=CREATED | errors(401, 403, 429),
)  # fmt: skip
def create_invite(
    body: InviteCreate, request: Request, response: Response, who: CurrentCoach,
    session: SessionDep,
):  # fmt: skip
    invite, token = invites.create_invite(
        session, club_id=who.club.id, created_by=who.user.id if who.user else None,
        display_name=body.display_name, ttl=timedelta(days=body.days),
    )  # fmt: skip
    response.headers["Location"] = f"/join/{token}"
    return InvitePublic(
        url=str(request.base_url).rstrip("/") + f"/join/{token}",
        path=f"/join/{token}",
        display_name=invite.display_name,
        expires_at=invite.expires_at,
    )


@router.post(
    "/join/{token}", response_model=JoinedPublic,
    summary="Redeem an invite: create the performer and sign them in",
    responses=errors(404, 410, 422),
)  # fmt: skip
def join(
    token: str, body: JoinBody, request: Request, session: SessionDep, settings: SettingsDep
):
    try:
        user = invites.redeem_invite(
            session, token, display_name=body.display_name, email=body.email,
            password=body.password,
        )  # fmt: skip
    except invites.InviteError as exc:
        raise ApiError(_INVITE_STATUS[exc.reason], f"invite_{exc.reason}", str(exc)) from None
    sessions.start(request, session, user, settings.session_max_age_s)
    return JoinedPublic(id=user.id, display_name=user.display_name, url="/upload")
