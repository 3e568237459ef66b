"""The 3D view through the app's own origin: viser's page and websocket, relayed.

Each analysis' viser server listens on a loopback port (:mod:`web.live`); browsers never see
it. The page frames ``/analyses/{id}/3d/{tab}/``, where ``tab`` is a random token of that
browser tab. This module relays the page (and any file it asks for) over HTTP and the viser
websocket, which the client opens at the page's own path without its last slash. So the view
works wherever the app does: behind a reverse proxy, over HTTPS, on any host name, with the
app's own sign-in checked on every connection.

Each websocket relayed is one viser client: the relay tells :mod:`web.live` which tab it
belongs to, so that the tab's video moves its own 3D view and nobody else's (issue 21 item 2).
A relay (rather than, say, a second public port) is written here because no maintained ASGI
package proxies websockets; ``websockets`` (viser's own dependency) is the client side.
"""

from __future__ import annotations

import asyncio
import logging
import re

import httpx
import websockets
from fastapi import APIRouter, Request, Response, WebSocket
from starlette.websockets import WebSocketDisconnect

from app.api.access import analysis_for
from app.api.deps import principal_of
from app.api.errors import ApiError
from app.core import sessions
from web.live import get_viewers

log = logging.getLogger("web.viewer.proxy")
router = APIRouter(include_in_schema=False)

#: A browser tab's token: what :func:`viewer_path` and the page's script make.
TAB_PATTERN = r"^[0-9a-f]{16,64}$"
#: What the framed viser page may do: its client is one inline module (zstd-packed, unpacked
#: by WebAssembly) with inline styles, and talks to its websocket on this origin.
VIEWER_CSP = (
    "default-src 'self'; script-src 'self' 'unsafe-inline' 'wasm-unsafe-eval' blob:; "
    "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; font-src 'self' data:; "
    "connect-src 'self' data: blob:; worker-src 'self' blob:; frame-ancestors 'self'; "
    "object-src 'none'; base-uri 'self'"
)


def viewer_path(analysis_id: str) -> str:
    """Where the page frames an analysis' 3D view (a tab token and ``/`` follow)."""
    return f"/analyses/{analysis_id}/3d/"


def _port_for(request: Request | WebSocket, analysis_id: str, tab: str) -> int:
    """The analysis' viser port, if the caller is signed in, may see it, and its viewer runs."""
    if not re.match(TAB_PATTERN, tab):
        raise ApiError(404, "not_found", "no 3D view here")
    db = request.app.state.sessionmaker()
    try:
        user = sessions.current_user(request, db)  # type: ignore[arg-type]
        if user is None:
            raise ApiError(401, "unauthorized", "sign in to see this 3D view")
        analysis_for(db, principal_of(db, user), analysis_id)
    finally:
        db.close()
    port = get_viewers().port_of(analysis_id)
    if port is None:
        raise ApiError(409, "not_ready", "the 3D view is not started; reload the page")
    return port


@router.get("/analyses/{analysis_id}/3d/{tab}/{path:path}")
async def viewer_file(analysis_id: str, tab: str, path: str, request: Request) -> Response:
    """Viser's page (``path`` empty) or a file it asks for, from the analysis' server."""
    port = _port_for(request, analysis_id, tab)
    async with httpx.AsyncClient(timeout=10.0) as client:
        r = await client.get(f"http://127.0.0.1:{port}/{path}")
    headers = {k: v for k, v in r.headers.items() if k.lower() in ("content-type", "cache-control")}
    headers["content-security-policy"] = VIEWER_CSP
    return Response(r.content, r.status_code, headers=headers)


@router.websocket("/analyses/{analysis_id}/3d/{tab}")
async def viewer_socket(websocket: WebSocket, analysis_id: str, tab: str) -> None:
    """Relay one viser client's websocket, both ways, until either side closes."""
    try:
        port = _port_for(websocket, analysis_id, tab)
    except ApiError as exc:
        await websocket.close(code=4000 + exc.status_code, reason=exc.message[:120])
        return
    viewers = get_viewers()
    protocols = list(websocket.scope.get("subprotocols") or [])
    # One upstream connection at a time per viewer: viser numbers its clients in the order
    # their connections arrive, which is how this tab learns its client id.
    async with viewers.connect_lock(analysis_id):
        client_id = viewers.next_client_id(analysis_id)
        try:
            upstream = await websockets.connect(
                f"ws://127.0.0.1:{port}/", subprotocols=protocols or None, max_size=None,
                open_timeout=10,
            )  # fmt: skip
        except (OSError, websockets.WebSocketException) as exc:
            log.warning("viewer.relay_failed analysis=%s error=%s", analysis_id, exc)
            await websocket.close(code=1011)
            return
    viewers.bind_tab(analysis_id, tab, client_id)
    await websocket.accept(subprotocol=upstream.subprotocol)
    async with upstream:
        down = asyncio.create_task(_downstream(upstream, websocket))
        try:
            await _upstream(websocket, upstream)
        finally:
            down.cancel()


async def _upstream(websocket: WebSocket, upstream) -> None:
    """Browser -> viser."""
    try:
        while True:
            m = await websocket.receive()
            if m["type"] == "websocket.disconnect":
                return
            if m.get("bytes") is not None:
                await upstream.send(m["bytes"])
            elif m.get("text") is not None:
                await upstream.send(m["text"])
    except (WebSocketDisconnect, websockets.ConnectionClosed):
        return


async def _downstream(upstream, websocket: WebSocket) -> None:
    """Viser -> browser; closes the browser's side when viser closes."""
    try:
        async for m in upstream:
            if isinstance(m, bytes):
                await websocket.send_bytes(m)
            else:
                await websocket.send_text(m)
    except (WebSocketDisconnect, websockets.ConnectionClosed, RuntimeError):
        pass
    try:
        await websocket.close()
    except RuntimeError:
        pass
