"""The HTML pages. Data comes from the API (:mod:`app.api.routes`, fetched by the
page scripts) or, for the dashboard and the printable report, is rendered here."""

from __future__ import annotations

import re
from datetime import UTC, datetime, time, timedelta
from pathlib import Path
from typing import Annotated, Any
from urllib.parse import quote

from fastapi import APIRouter, Query, Request
from fastapi.responses import HTMLResponse, RedirectResponse
from fastapi.templating import Jinja2Templates

from app import crud
from app.api import access
from app.api.deps import NotifierDep, SessionDep, principal_of
from app.api.errors import ApiError
from app.api.params import DbId
from app.api.routes.comments import comment_rows
from app.core import invites, media, sessions
from app.core.reflect import reflect
from app.core.summary import page_summary
from app.models import ANALYSIS_STATES, User
from app.web_surface import BONE_LABELS, BONE_NAMES, ONE_CAMERA_NOTE

TEMPLATES = Jinja2Templates(directory=Path(__file__).resolve().parents[1] / "templates")
TEMPLATES.env.globals["one_camera_note"] = ONE_CAMERA_NOTE
# One table of bone words for every page's script (common.js: coach.boneLabel).
TEMPLATES.env.globals["bone_words"] = {"ids": list(BONE_NAMES), "labels": list(BONE_LABELS)}
router = APIRouter(include_in_schema=False)


def page_user(request: Request, session) -> User | None:
    return sessions.current_user(request, session)


#: A path on this site: a slash, then no second slash or backslash (``//evil``, ``/\\evil``
#: leave the site), and only URL characters, so no tab or newline that a browser would drop
#: (``/%09/evil`` becomes ``//evil``).
_LOCAL_PATH = re.compile(r"/(?![/\\])[A-Za-z0-9\-._~!$&'()*+,;=:@%/?#]*")


def local_path(target: str) -> str:
    """``target`` if it is a path on this site, else ``/`` (no open redirect after sign-in)."""
    return target if _LOCAL_PATH.fullmatch(target) and "\\" not in target else "/"


def _sign_in(request: Request) -> RedirectResponse:
    target = request.url.path + (f"?{request.url.query}" if request.url.query else "")
    return RedirectResponse(f"/login?next={quote(target)}", status_code=303)


def _render(request: Request, name: str, user: User | None, status: int = 200, **ctx: Any):
    return TEMPLATES.TemplateResponse(
        request, name, {"user": user, "page": name.removesuffix(".html")} | ctx,
        status_code=status,
    )  # fmt: skip


def error_page(request: Request, status: int, message: str):
    """What a browser shows for an unknown address or a refused method (not raw JSON)."""
    title = {404: "Not found", 405: "Not possible here"}.get(status, "Something went wrong")
    text = "There is no page at this address." if status == 404 else message
    return _render(request, "message.html", None, status, title=title, message=text)


def _forbidden(request: Request, user: User, message: str):
    return _render(request, "message.html", user, 403, title="Not allowed", message=message)


@router.get("/favicon.ico")
def favicon() -> RedirectResponse:
    """Browsers ask for /favicon.ico before reading the page's icon link."""
    return RedirectResponse("/static/favicon.svg", status_code=301)


@router.get("/", response_class=HTMLResponse)
def home(request: Request, session: SessionDep):
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    return RedirectResponse("/dashboard" if user.role == "coach" else "/analyses", status_code=303)


@router.get("/analyses", response_class=HTMLResponse)
def my_analyses(
    request: Request,
    session: SessionDep,
    notifier: NotifierDep,
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
):
    """A performer's own attempts, newest first (a coach has the dashboard)."""
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    if user.role == "coach":
        return RedirectResponse("/dashboard", status_code=303)
    limit = 50
    items, total = crud.list_analyses(
        session, club_id=user.club_id, performer_id=user.id, limit=limit, offset=offset
    )
    for a in items:
        reflect(session, a, on_final=notifier)
    return _render(
        request, "analyses.html", user, items=items, total=total, offset=offset, limit=limit
    )


@router.get("/login", response_class=HTMLResponse)
def login(request: Request, session: SessionDep, next: str = "/"):
    return _render(request, "login.html", page_user(request, session), next=local_path(next))


@router.get("/join/{token}", response_class=HTMLResponse)
def join_page(request: Request, token: str, session: SessionDep):
    """A performer's invite link: set a name, email and password, and be signed in."""
    try:
        invite = invites.find_invite(session, token)
    except invites.InviteError as exc:
        status = 404 if exc.reason == "unknown" else 410
        return _render(request, "message.html", page_user(request, session), status,
                       title="Invite link not usable", message=str(exc))  # fmt: skip
    club = crud.get_club(session, invite.club_id)
    return _render(
        request, "join.html", None, invite=invite, club=club, token=token,
        min_password=invites.MIN_PASSWORD_LEN,
    )  # fmt: skip


def _performers(session, user: User) -> list[User]:
    """Whom a coach may pick as the person in a video (a performer picks nobody)."""
    if user.role != "coach":
        return []
    return crud.list_performers(session, club_id=user.club_id, limit=1000, offset=0)[0]


@router.get("/upload", response_class=HTMLResponse)
def upload(request: Request, session: SessionDep):
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    performers = _performers(session, user)
    return _render(
        request, "upload.html", user, performers=performers,
        max_video_bytes=request.app.state.settings.max_video_bytes,
    )  # fmt: skip


@router.get("/captures", response_class=HTMLResponse)
def captures_page(request: Request, session: SessionDep):
    """Reference-free 3D capture: the upload form and the user's captures."""
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    performers = _performers(session, user)
    return _render(request, "captures.html", user, performers=performers, capture_id="")


@router.get("/captures/{capture_id}", response_class=HTMLResponse)
def capture_page(request: Request, capture_id: str, session: SessionDep):
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    try:
        c = access.capture_for(session, principal_of(session, user), capture_id)
    except ApiError:
        return _render(request, "message.html", user, 404, title="Not found",
                       message="There is no such capture in your club.")  # fmt: skip
    return _render(request, "captures.html", user, performers=[], capture_id=c.id)


@router.get("/analyses/{analysis_id}", response_class=HTMLResponse)
def analysis_page(request: Request, analysis_id: str, session: SessionDep, notifier: NotifierDep):
    return _analysis(request, analysis_id, session, notifier, review=False)


@router.get("/analyses/{analysis_id}/review", response_class=HTMLResponse)
def review_page(request: Request, analysis_id: str, session: SessionDep, notifier: NotifierDep):
    return _analysis(request, analysis_id, session, notifier, review=True)


def _analysis(request, analysis_id, session, notifier, *, review: bool):
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    if review and user.role != "coach":
        return _forbidden(request, user, "Only coaches review analyses.")
    try:
        a = access.analysis_for(session, principal_of(session, user), analysis_id)
    except ApiError:
        return _render(request, "message.html", user, 404, title="Not found",
                       message="There is no such analysis in your club.")  # fmt: skip
    reflect(session, a, on_final=notifier)
    return _render(request, "analysis.html", user, analysis=a, review=review)


@router.get("/analyses/{analysis_id}/report", response_class=HTMLResponse)
def report_page(request: Request, analysis_id: str, session: SessionDep, notifier: NotifierDep):
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    try:
        a = access.done_analysis(session, principal_of(session, user), analysis_id, notifier)
        result = access.result_of(a)
    except ApiError as exc:
        return _render(request, "message.html", user, exc.status_code, title="No report",
                       message=exc.message)  # fmt: skip
    segments = page_summary(a, result)["segments"]
    frames = result.frames
    comments = comment_rows(session, a)
    stills = media.report_stills(a.video_path, a.work_dir, result)  # sync route: a threadpool
    return _render(
        request, "report.html", user, analysis=a, result=result.doc, frames=frames,
        segments=segments, comments=comments,
        plot=media.error_plot_svg(result), fps=result.video.fps, stills=stills,
        mean_error=(sum(f.posture_error_deg for f in frames) / len(frames)) if frames else 0.0,
    )  # fmt: skip


def _date(s: str | None, *, end: bool) -> datetime | None:
    if not s:
        return None
    try:
        d = datetime.strptime(s, "%Y-%m-%d").date()
    except ValueError:
        return None
    t = datetime.combine(d, time.min, tzinfo=UTC)
    return t + timedelta(days=1) if end else t


@router.get("/dashboard", response_class=HTMLResponse)
def dashboard(
    request: Request,
    session: SessionDep,
    notifier: NotifierDep,
    performer: Annotated[str, Query(max_length=12)] = "",
    reference: Annotated[str, Query(max_length=12)] = "",
    status: Annotated[str, Query(max_length=16)] = "",
    since: Annotated[str, Query(max_length=10)] = "",
    until: Annotated[str, Query(max_length=10)] = "",
    review: Annotated[str, Query(max_length=10)] = "",
    offset: Annotated[int, Query(ge=0, le=1_000_000)] = 0,
):
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    if user.role != "coach":
        return RedirectResponse("/upload", status_code=303)
    limit = 50
    items, total = crud.list_analyses(
        session, club_id=user.club_id, limit=limit, offset=offset,
        performer_id=int(performer) if performer.isdigit() else None,
        reference_id=int(reference) if reference.isdigit() else None,
        # "to review" means finished and not yet reviewed
        status=status if status in ANALYSIS_STATES else ("done" if review == "to_review" else None),
        created_after=_date(since, end=False), created_before=_date(until, end=True),
        reviewed={"to_review": False, "reviewed": True}.get(review),
    )  # fmt: skip
    for a in items:
        reflect(session, a, on_final=notifier)
    performers = crud.list_performers(session, club_id=user.club_id, limit=1000, offset=0)[0]
    references = crud.list_references(session, club_id=user.club_id, limit=1000, offset=0)[0]
    query = {"performer": performer, "reference": reference, "status": status,
             "since": since, "until": until, "review": review}  # fmt: skip
    return _render(
        request, "dashboard.html", user, items=items, total=total, offset=offset, limit=limit,
        performers=performers, references=references, states=ANALYSIS_STATES, query=query,
    )  # fmt: skip


@router.get("/performers/{performer_id}/compare", response_class=HTMLResponse)
def compare_page(
    request: Request,
    performer_id: DbId,
    session: SessionDep,
    a: Annotated[str, Query(max_length=36)] = "",
    b: Annotated[str, Query(max_length=36)] = "",
):
    """A performer's analyses over time (mean error, trend) and two of them side by side."""
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    try:
        performer = access.performer_for(session, principal_of(session, user), performer_id)
    except ApiError:
        return _render(request, "message.html", user, 404, title="Not found",
                       message="There is no such performer in your club.")  # fmt: skip
    return _render(request, "compare.html", user, performer=performer, a=a, b=b)


@router.get("/references", response_class=HTMLResponse)
def references_page(request: Request, session: SessionDep):
    user = page_user(request, session)
    if user is None:
        return _sign_in(request)
    if user.role != "coach":
        return _forbidden(request, user, "Only coaches manage references.")
    return _render(request, "references.html", user, bones=BONE_NAMES)
