"""``register(app)``: the browser pages, their JSON endpoints and static files.

Pages (session-cookie sign-in, ``POST /api/v1/session``):

    /login                       sign in
    /upload                      pick a reference, upload a video, watch its progress
    /analyses/{id}               progress, then results (video + skeleton, 3D view, timeline)
    /analyses/{id}/review        coach review: segment table and pinned comments
    /analyses/{id}/report        printable report
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
    from web.pages import api, html

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
    app.include_router(api.router)
    app.include_router(html.router)
