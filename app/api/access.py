"""Rows a caller may see: every lookup of the API goes through here, scoped by its principal.

A club's rows are visible to its API keys and coaches; a performer sees their own analyses and
themselves only. Anything else is answered 404, so ids of other clubs or performers leak
nothing.
"""

from __future__ import annotations

import uuid
from typing import Any

from sqlalchemy.orm import Session

from app import crud
from app.api.deps import Principal
from app.api.errors import ApiError, not_found
from app.core.reflect import Notifier, reflect
from app.core.storage import Storage
from app.models import Analysis, Capture, Reference, User
from worker.engine_surface import InvalidInput, Result


def _own_row(session: Session, who: Principal, kind: str, row_id: str, get) -> Any:
    """The club's row ``row_id`` (a uuid) from ``get``, if ``who`` may see it (a performer
    only their own); 404 otherwise."""
    try:
        uuid.UUID(row_id)
    except ValueError:
        raise not_found(kind, row_id) from None
    row = get(session, club_id=who.club.id, **{f"{kind}_id": row_id})
    own = who.own_performer_id
    if row is None or (own is not None and row.performer_id != own):
        raise not_found(kind, row_id)
    return row


def analysis_for(session: Session, who: Principal, analysis_id: str) -> Analysis:
    """The analysis, if ``who`` may see it; 404 otherwise."""
    return _own_row(session, who, "analysis", analysis_id, crud.get_analysis)


def capture_for(session: Session, who: Principal, capture_id: str) -> Capture:
    """The capture, if ``who`` may see it; 404 otherwise."""
    return _own_row(session, who, "capture", capture_id, crud.get_capture)


def reference_for(session: Session, who: Principal, reference_id: int) -> Reference:
    ref = crud.get_reference(session, club_id=who.club.id, reference_id=reference_id)
    if ref is None:
        raise not_found("reference", reference_id)
    return ref


def performer_for(session: Session, who: Principal, performer_id: int) -> User:
    """A performer of the club whom ``who`` may see: a coach any, a performer only
    themselves."""
    p = crud.get_performer(session, club_id=who.club.id, user_id=performer_id)
    own = who.own_performer_id
    if p is None or (own is not None and p.id != own):
        raise not_found("performer", performer_id)
    return p


def done_analysis(
    session: Session, who: Principal, analysis_id: str, notifier: Notifier | None
) -> Analysis:
    """The analysis once it is done (its folder reflected first); 409 before."""
    analysis = analysis_for(session, who, analysis_id)
    reflect(session, analysis, on_final=notifier)
    if analysis.status != "done" or not analysis.result_path:
        raise ApiError(
            409, "not_ready", f"analysis {analysis_id} is {analysis.status}, not done",
            {"status": analysis.status, "progress": analysis.progress},
        )  # fmt: skip
    return analysis


def result_of(analysis: Analysis) -> Result:
    """The done analysis' result (typed); 409 while its file cannot be read, 500
    ``bad_result`` when it is malformed."""
    doc = Storage.read_json(analysis.result_path) if analysis.result_path else None
    if doc is None:
        raise ApiError(409, "not_ready", "the result file cannot be read yet")
    try:
        return Result.from_dict(doc)
    except InvalidInput as exc:
        raise ApiError(500, "bad_result", f"the result is malformed ({exc})") from None
