"""Comments pinned to an analysis, a frame or a segment: the coach and the performer talk."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request, Response
from sqlalchemy import select

from app.api.access import analysis_for
from app.api.deps import CREATED, CurrentPrincipal, PageDep, SessionDep, location
from app.api.errors import ApiError, errors, not_found
from app.api.params import DbId
from app.models import Analysis, Comment
from app.schemas import CommentCreate, CommentPublic, CommentsPublic

router = APIRouter(
    prefix="/analyses/{analysis_id}/comments", tags=["comments"], responses=errors(401, 404, 429)
)


def comment_public(c: Comment) -> dict[str, Any]:
    return {
        "id": c.id,
        "body": c.body,
        "frame": c.frame,
        "segment": c.segment,
        "drawing": c.drawing,
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


@router.get(
    "", response_model=CommentsPublic,
    summary="The analysis' comments, pinned ones first by frame, then the rest in order",
)  # fmt: skip
def list_comments(analysis_id: str, who: CurrentPrincipal, session: SessionDep, page: PageDep):
    a = analysis_for(session, who, analysis_id)
    rows = comment_rows(session, a)
    items = [comment_public(c) for c in rows[page.offset : page.offset + page.limit]]
    return CommentsPublic(items=items, total=len(rows), limit=page.limit, offset=page.offset)


def _comment_of(session, analysis: Analysis, comment_id: int) -> Comment:
    c = session.get(Comment, comment_id)
    if c is None or c.analysis_id != analysis.id:
        raise not_found("comment", comment_id)
    return c


@router.post(
    "", status_code=201, response_model=CommentPublic,
    summary="Comment, on a frame or a segment if given (signed-in users)",
    description="201 with the comment's `Location`.",
    responses=CREATED | errors(403, 422),
)  # fmt: skip
def create_comment(
    analysis_id: str, body: CommentCreate, who: CurrentPrincipal, session: SessionDep,
    request: Request, response: Response,
):  # fmt: skip
    a = analysis_for(session, who, analysis_id)
    user = who.require_user()
    if body.drawing is not None and body.frame is None:
        raise ApiError(422, "invalid_comment", "a drawing is drawn over a frame: give `frame`")
    c = Comment(
        club_id=a.club_id, analysis_id=a.id, author_id=user.id, frame=body.frame,
        segment=body.segment, body=body.body.strip(),
        drawing=None if body.drawing is None else [[list(p) for p in s] for s in body.drawing],
    )  # fmt: skip
    session.add(c)
    session.commit()
    response.headers["Location"] = location(
        request, "read_comment", analysis_id=a.id, comment_id=c.id
    )
    return comment_public(c)


@router.get("/{comment_id}", response_model=CommentPublic, summary="One comment")
def read_comment(analysis_id: str, comment_id: DbId, who: CurrentPrincipal, session: SessionDep):
    a = analysis_for(session, who, analysis_id)
    return comment_public(_comment_of(session, a, comment_id))


@router.delete(
    "/{comment_id}", status_code=204, summary="Delete a comment (its author, or a coach)",
    responses=errors(403),
)  # fmt: skip
def delete_comment(
    analysis_id: str, comment_id: DbId, who: CurrentPrincipal, session: SessionDep
) -> Response:
    a = analysis_for(session, who, analysis_id)
    c = _comment_of(session, a, comment_id)
    if not who.is_coach and (who.user is None or c.author_id != who.user.id):
        raise ApiError(403, "forbidden", "you can delete only your own comments")
    session.delete(c)
    session.commit()
    return Response(status_code=204)
