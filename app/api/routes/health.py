import hmac

from fastapi import APIRouter, Header
from fastapi.responses import PlainTextResponse
from sqlalchemy import text
from sqlalchemy.exc import SQLAlchemyError

from app.api.deps import SessionDep, SettingsDep
from app.api.errors import ApiError, json_errors
from app.schemas import HealthPublic

router = APIRouter(tags=["health"])


@router.get("/health", response_model=HealthPublic, summary="Liveness and database check")
def health(session: SessionDep) -> HealthPublic:
    try:
        session.execute(text("SELECT 1"))
        database = "ok"
    except SQLAlchemyError:
        database = "error"
    return HealthPublic(version="1", database=database)


@router.get(
    "/metrics",
    response_class=PlainTextResponse,
    summary="Worker metrics in Prometheus text format (analyses, stage durations, failures)",
    description=(
        "For the operator's scraper, not for clubs: counts span every club. Off unless "
        "`COACH_METRICS_TOKEN` is set; then send `Authorization: Bearer <that token>`."
    ),
    responses=json_errors(401, 404),
)
def metrics(settings: SettingsDep, authorization: str | None = Header(None)) -> str:
    if not settings.metrics_token:
        raise ApiError(404, "not_found", "metrics are off: set COACH_METRICS_TOKEN to scrape them")
    sent = (authorization or "").removeprefix("Bearer ").strip()
    if not hmac.compare_digest(sent.encode(), settings.metrics_token.encode()):
        raise ApiError(
            401, "unauthorized", "send the metrics token as Authorization: Bearer <token>",
            headers={"WWW-Authenticate": "Bearer"},
        )  # fmt: skip
    # Workers write their counters as files under the data dir (worker.metrics), so the API
    # reads them without a connection to any worker; every worker machine shares that dir.
    from worker.metrics import render_prometheus

    return render_prometheus(settings.data_dir / "metrics")
