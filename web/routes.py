"""``register(app)``: the browser pages, the 3D view's routes and static files.

Every other JSON route the pages call is the API's (``/api/v1``, :mod:`app.api.routes`), which
accepts the session cookie as well as an API key.

Pages (session-cookie sign-in, ``POST /api/v1/session``):

    /login                       sign in
    /upload                      pick a reference, upload a video, watch its progress
    /analyses/{id}               progress, then results (video + skeleton, 3D view, timeline)
    /analyses/{id}/review        coach review: segment table and pinned comments
    /analyses/{id}/report        printable report
    /analyses/{id}/3d/{tab}/     the 3D view (viser, relayed with its websocket; one per tab)
    /dashboard                   coach: the club's analyses with filters
    /references                  coach: upload BVH, preview, segment names, weights, tolerances
    /performers/{id}/compare     a performer's attempts over time; two of them side by side
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

STATIC_DIR = Path(__file__).resolve().parent / "static"


def register(app: FastAPI) -> None:
    """The web package's mount (declared in pyproject.toml, entry point ``coach.mounts``)."""
    from web.pages import html
    from web.viewer import proxy
    from web.viewer import routes as viewer

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    app.include_router(viewer.router)
    app.include_router(proxy.router)  # before the pages: /analyses/{id}/3d/... is the 3D view
    app.include_router(html.router)
    app.state.html_error = html.error_page  # browsers get pages for 404/405 (app.api.errors)
