from fastapi import APIRouter

from app import crud
from app.api.deps import CoachClub, SessionDep, SettingsDep
from app.api.errors import errors, invalid
from app.core import webhooks
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
        "The webhook URL must be http or https and its host must resolve to public addresses "
        "only (no private, loopback, link-local, multicast or reserved ones; checked again "
        "before each delivery, which connects to the address checked); otherwise 422. "
        "Setting a webhook URL for the first time (or `rotate_webhook_secret`) returns the "
        "signing secret once.\n\n"
        "Each delivery is a POST of JSON `{delivery_id, event, analysis}` with the headers "
        "`X-Coach-Delivery` (the delivery id, the same for every retry of one event), "
        "`X-Coach-Timestamp` (unix seconds when this attempt was sent) and "
        "`X-Coach-Signature: sha256=<hex HMAC-SHA256 with the secret of "
        '"<X-Coach-Timestamp>.<body>">`. A receiver recomputes the signature, refuses '
        "timestamps more than 5 minutes from its clock and drops delivery ids it has seen "
        "(`app.core.security.verify_webhook` does the first two). Redirects are not "
        "followed; a 2xx answer ends the delivery, 5xx, 408, 429 and network errors are "
        "retried with backoff.\n\n"
        "This URL is the club's default endpoint and receives every event; more endpoints, "
        "each with its own secret and the events it wants, live at `/api/v1/webhooks`."
    ),
    responses=errors(422),
)
def update_club(
    club: CoachClub, body: ClubUpdate, session: SessionDep, settings: SettingsDep
) -> ClubUpdated:
    if body.webhook_url:
        try:
            webhooks.destination(body.webhook_url, allow_private=settings.webhook_allow_private)
        except webhooks.WebhookUrlError as exc:
            raise invalid("body.webhook_url", str(exc), "webhook_url_refused") from None
    secret = crud.update_club(
        session,
        club,
        name=body.name,
        webhook_url=body.webhook_url,
        rotate=body.rotate_webhook_secret,
    )
    return ClubUpdated.model_validate(club).model_copy(update={"webhook_secret": secret})
