"""One router per resource, collected into the v1 API router."""

from fastapi import APIRouter

from app.api.routes import (
    analyses,
    captures,
    club,
    comments,
    framing,
    health,
    invites,
    keys,
    performers,
    references,
    repetitions,
    reviews,
    session,
    webhooks,
)

api_router = APIRouter()
api_router.include_router(health.router)
api_router.include_router(club.router)
api_router.include_router(keys.router)
api_router.include_router(webhooks.router)
api_router.include_router(performers.router)
api_router.include_router(references.router)
api_router.include_router(analyses.router)
api_router.include_router(repetitions.router)
api_router.include_router(reviews.router)
api_router.include_router(captures.router)
api_router.include_router(framing.router)
api_router.include_router(comments.router)
api_router.include_router(invites.router)
api_router.include_router(session.router)
