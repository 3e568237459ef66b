"""Comments pinned to an analysis, a frame or a segment: the coach and the performer talk."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Response
from sqlalchemy import select

from app.api.access import analysis_for
from app.api.deps import CurrentPrincipal, SessionDep
from app.api.errors import ApiError, errors, not_found
from app.models import Analysis, Comment
from app.schemas import CommentCreate, CommentPublic

router = APIRouter(
    prefix="/analyses/{analysis_id}/comments", tags=["comments"], responses=errors(401, 404, 429)
)


def comment_public(c: Comment) -> dict[str, Any]:
    return {
        "id": c.id,
        "body": c.body,
        "frame": c.frame,
        "segment": c.segment,
        "author": c.author.display_name if c.author else "(removed)",
        "author_id": c.author_id,
        "created_at": c.created_at.isoformat(),
    }


def comment_rows(session, analysis: Analysis) -> list[Comment]:
    """The analysis' comments, pinned ones first by frame, then the rest in order."""
    q = select(Comment).where(
        Comment.club_id == analysis.club_id, Comment.analysis_id == analysis.id
    )
    return list(session.scalars(q.order_by(Comment.frame.is_(None), Comment.frame, Comment.id)))


@router.get("", response_model=list[CommentPublic], summary="The analysis' comments")
def list_comments(analysis_id: str, who: CurrentPrincipal, session: SessionDep):
    a = analysis_for(session, who, analysis_id)
    return [comment_public(c) for c in comment_rows(session, a)]


@router.post(
    "", status_code=201, response_model=CommentPublic,
    summary="Comment, on a frame or a segment if given (signed-in users)",
    responses=errors(403, 422),
)  # fmt: skip
def create_comment(
    analysis_id: str, body: CommentCreate, who: CurrentPrincipal, session: SessionDep
):
    a = analysis_for(session, who, analysis_id)
    user = who.require_user()
    c = Comment(
        club_id=a.club_id, analysis_id=a.id, author_id=user.id, frame=body.frame,
        segment=body.segment, body=body.body.strip(),
    )  # fmt: skip
    session.add(c)
    session.commit()
    return comment_public(c)


@router.delete(
    "/{comment_id}", status_code=204, summary="Delete a comment (its author, or a coach)",
    responses=errors(403),
)  # fmt: skip
def delete_comment(
    analysis_id: str, comment_id: int, who: CurrentPrincipal, session: SessionDep
) -> Response:
    a = analysis_for(session, who, analysis_id)
    c = session.get(Comment, comment_id)
    if c is None or c.analysis_id != a.id:
        raise not_found("comment", comment_id)
    if not who.is_coach and (who.user is None or c.author_id != who.user.id):
        raise ApiError(403, "forbidden", "you can delete only your own comments")
    session.delete(c)
    session.commit()
    return Response(status_code=204)
