"""The 3D view's JSON routes (``/api/v1/analyses/{id}/viewer...``), mounted by :mod:`web.routes`.

They belong to the viewer (viser servers in this process, :mod:`web.live`), so they live here
and join the API through the web package's declared mount; access is the API's own
(:mod:`app.api.access`).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Request, Response
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, Field

from app.api.access import analysis_for, done_analysis, result_of
from app.api.deps import CurrentPrincipal, NotifierDep, SessionDep
from app.api.errors import ApiError
from app.core import media
from app.core.reflect import reflect
from web.live import NothingToShowYet, ViewerUnavailable, get_viewers
from web.viewer.proxy import TAB_PATTERN, viewer_path

router = APIRouter(prefix="/api/v1/analyses/{analysis_id}/viewer", include_in_schema=False)


@router.post("")
async def start_viewer(
    analysis_id: str, request: Request, who: CurrentPrincipal, session: SessionDep,
    notifier: NotifierDep,
):  # fmt: skip
    """The finished analysis' 3D view: where the page frames it (a tab token and "/" follow,
    :mod:`web.viewer.proxy`)."""
    a = done_analysis(session, who, analysis_id, notifier)
    result = result_of(a)
    bvh = a.reference.bvh_path

    def load():
        return media.reference_joints(bvh), result

    try:
        await run_in_threadpool(get_viewers().ensure, a.id, load)
    except ViewerUnavailable as exc:
        raise ApiError(503, "viewer_unavailable", str(exc)) from None
    return {"url": viewer_path(a.id)}


@router.post("/live")
async def start_live_viewer(
    analysis_id: str, request: Request, who: CurrentPrincipal, session: SessionDep,
    notifier: NotifierDep,
):  # fmt: skip
    """The 3D view of a running analysis, filled in from its folder as stages finish.

    409 ``not_ready`` until stage 2's output exists (the page asks again); once the analysis
    is done the same server shows the finished scene (``phase`` "done").
    """
    a = analysis_for(session, who, analysis_id)
    reflect(session, a, on_final=notifier)
    if a.status in ("failed", "cancelled") or not a.work_dir:
        raise ApiError(409, "not_ready", f"the analysis is {a.status}", {"status": a.status})
    try:
        _, state = await run_in_threadpool(get_viewers().ensure_running, a.id, a.work_dir)
    except NothingToShowYet as exc:
        raise ApiError(409, "not_ready", str(exc), {"status": a.status}) from None
    except ViewerUnavailable as exc:
        raise ApiError(503, "viewer_unavailable", str(exc)) from None
    return {"url": viewer_path(a.id), **state}


class FrameBody(BaseModel):
    frame: int = Field(ge=0, le=1_000_000)
    #: The browser tab whose 3D view moves (the token in its frame's address).
    tab: str = Field(pattern=TAB_PATTERN)


@router.post("/frame", status_code=204)
async def viewer_frame(
    analysis_id: str, body: Annotated[FrameBody, Body()], who: CurrentPrincipal,
    session: SessionDep,
):  # fmt: skip
    a = analysis_for(session, who, analysis_id)
    await run_in_threadpool(get_viewers().set_frame, a.id, body.frame, body.tab)
    return Response(status_code=204)
