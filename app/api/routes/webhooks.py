"""More webhook receivers per club, each with its own events and signing secret.

The club's own ``webhook_url`` (``PATCH /club``) stays its default endpoint and receives
every event; these endpoints receive the events they name. Deliveries are the same for all
(``app.core.reflect.Notifier``).
"""

from fastapi import APIRouter, Request, Response

from app import crud
from app.api.deps import CREATED, CoachClub, PageDep, SessionDep, SettingsDep, location
from app.api.errors import ApiError, errors, invalid, not_found
from app.api.params import DbId
from app.core import webhooks
from app.core.config import Settings
from app.models import WebhookEndpoint
from app.schemas import (
    WebhookEndpointCreate,
    WebhookEndpointCreated,
    WebhookEndpointPublic,
    WebhookEndpointsPublic,
    WebhookEndpointUpdate,
    WebhookEndpointUpdated,
)

#: Endpoints a club may have: each final analysis is one delivery per endpoint.
MAX_ENDPOINTS = 20

URL_RULES = (
    "The URL must be http or https and its host must resolve to public addresses only (no "
    "private, loopback, link-local, multicast or reserved ones; checked again before each "
    "delivery); otherwise 422."
)

router = APIRouter(prefix="/webhooks", tags=["webhooks"], responses=errors(401, 429))


def _check_url(url: str, settings: Settings) -> None:
    """422 unless ``url`` may receive webhooks now (app.core.webhooks)."""
    try:
        webhooks.destination(url, allow_private=settings.webhook_allow_private)
    except webhooks.WebhookUrlError as exc:
        raise invalid("body.url", str(exc), "webhook_url_refused") from None


def _endpoint(session: SessionDep, club: CoachClub, webhook_id: int) -> WebhookEndpoint:
    row = crud.get_webhook_endpoint(session, club_id=club.id, endpoint_id=webhook_id)
    if row is None:
        raise not_found("Webhook endpoint", webhook_id)
    return row


@router.post(
    "",
    status_code=201,
    response_model=WebhookEndpointCreated,
    summary="Add a webhook endpoint (its signing secret is shown once)",
    description=(
        f"201 with the endpoint's `Location`. {URL_RULES} `events` defaults to every event. "
        "Deliveries are signed with the endpoint's own secret, in the format `PATCH /club` "
        f"describes. At most {MAX_ENDPOINTS} endpoints per club (409)."
    ),
    responses=CREATED | errors(409, 422),
)
def create_webhook(
    club: CoachClub,
    session: SessionDep,
    settings: SettingsDep,
    request: Request,
    response: Response,
    body: WebhookEndpointCreate,
) -> WebhookEndpointCreated:
    _check_url(body.url, settings)
    if crud.count_webhook_endpoints(session, club_id=club.id) >= MAX_ENDPOINTS:
        raise ApiError(
            409, "limit_reached", f"a club has at most {MAX_ENDPOINTS} webhook endpoints",
            {"max_endpoints": MAX_ENDPOINTS},
        )  # fmt: skip
    row = crud.create_webhook_endpoint(
        session, club_id=club.id, url=body.url, events=list(body.events),
        description=body.description,
    )  # fmt: skip
    response.headers["Location"] = location(request, "read_webhook", webhook_id=row.id)
    return WebhookEndpointCreated.model_validate(row)


@router.get("", response_model=WebhookEndpointsPublic, summary="The club's webhook endpoints")
def list_webhooks(club: CoachClub, session: SessionDep, page: PageDep) -> WebhookEndpointsPublic:
    items, total = crud.list_webhook_endpoints(
        session, club_id=club.id, limit=page.limit, offset=page.offset
    )
    return WebhookEndpointsPublic(
        items=[WebhookEndpointPublic.model_validate(i) for i in items],
        total=total, limit=page.limit, offset=page.offset,
    )  # fmt: skip


@router.get(
    "/{webhook_id}", response_model=WebhookEndpointPublic,
    summary="One webhook endpoint (without its secret)", responses=errors(404),
)  # fmt: skip
def read_webhook(webhook_id: DbId, club: CoachClub, session: SessionDep) -> WebhookEndpointPublic:
    return WebhookEndpointPublic.model_validate(_endpoint(session, club, webhook_id))


@router.patch(
    "/{webhook_id}",
    response_model=WebhookEndpointUpdated,
    summary="Change a webhook endpoint, pause it or rotate its secret",
    description=(
        f"Fields left out stay as they are. {URL_RULES} `rotate_secret: true` returns the new "
        "secret once (`secret`); the old one signs nothing more. `enabled: false` pauses "
        "deliveries (`disabled_at` is set), `true` resumes them."
    ),
    responses=errors(404, 422),
)
def update_webhook(
    webhook_id: DbId,
    club: CoachClub,
    session: SessionDep,
    settings: SettingsDep,
    body: WebhookEndpointUpdate,
) -> WebhookEndpointUpdated:
    row = _endpoint(session, club, webhook_id)
    if body.url is not None:
        _check_url(body.url, settings)
    secret = crud.update_webhook_endpoint(
        session, row, url=body.url, events=body.events, description=body.description,
        enabled=body.enabled, rotate=body.rotate_secret,
    )  # fmt: skip
    public = WebhookEndpointPublic.model_validate(row).model_dump()
    return WebhookEndpointUpdated(**public, secret=secret)


@router.delete(
    "/{webhook_id}", status_code=204, summary="Remove a webhook endpoint", responses=errors(404)
)
def delete_webhook(webhook_id: DbId, club: CoachClub, session: SessionDep) -> Response:
    crud.delete_webhook_endpoint(session, _endpoint(session, club, webhook_id))
    return Response(status_code=204)
