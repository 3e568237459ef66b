"""A coach's "reviewed" mark on an analysis (issue 21, item 1).

The dashboard lists every analysis of the club with its headline error and whether a coach
has reviewed it; these two routes set and clear the mark. ``GET /analyses?reviewed=false``
is the coach's to-review list.
"""

from fastapi import APIRouter

from app.api.access import analysis_for
from app.api.deps import CurrentCoach, SessionDep
from app.api.errors import errors
from app.models import utcnow
from app.schemas import AnalysisPublic

router = APIRouter(prefix="/analyses", tags=["analyses"], responses=errors(401, 429))


@router.put(
    "/{analysis_id}/reviewed", response_model=AnalysisPublic,
    summary="Mark an analysis reviewed (coach)", responses=errors(403, 404),
)  # fmt: skip
def mark_reviewed(analysis_id: str, who: CurrentCoach, session: SessionDep):
    """Idempotent: marking it again keeps the first mark's time and coach."""
    analysis = analysis_for(session, who, analysis_id)
    if analysis.reviewed_at is None:
        analysis.reviewed_at = utcnow()
        analysis.reviewed_by_id = who.user.id if who.user is not None else None
        session.commit()
    return analysis


@router.delete(
    "/{analysis_id}/reviewed", response_model=AnalysisPublic,
    summary="Put an analysis back on the to-review list (coach)", responses=errors(403, 404),
)  # fmt: skip
def clear_reviewed(analysis_id: str, who: CurrentCoach, session: SessionDep):
    analysis = analysis_for(session, who, analysis_id)
    analysis.reviewed_at = None
    analysis.reviewed_by_id = None
    session.commit()
    return analysis
