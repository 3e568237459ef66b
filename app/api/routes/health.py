from fastapi import APIRouter
from fastapi.responses import PlainTextResponse
from sqlalchemy import text
from sqlalchemy.exc import SQLAlchemyError

from app.api.deps import SessionDep, SettingsDep
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
)
def metrics(settings: SettingsDep) -> str:
    # Workers write their counters as files under the data dir (worker.metrics), so the API
    # reads them without a connection to any worker; every worker machine shares that dir.
    from worker.metrics import render_prometheus

    return render_prometheus(settings.data_dir / "metrics")
