"""ASGI middleware: body limits, cross-origin protection for cookie sessions, security headers."""

from __future__ import annotations

from starlette.datastructures import Headers
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.api import errors
from app.core.config import Settings

API_PREFIX = "/api/v1"
#: Body limit for requests that carry no file (JSON, forms).
SMALL_BODY_BYTES = 1024 * 1024
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")


class _BodyTooLarge(Exception):
    pass


async def _send_response(send: Send, response) -> None:
    await send(
        {
            "type": "http.response.start",
            "status": response.status_code,
            "headers": [(k.encode(), v.encode()) for k, v in response.headers.items()],
        }
    )
    await send({"type": "http.response.body", "body": response.body})


class BodyLimitMiddleware:
    """Refuses request bodies over a per-route limit with 413, before they are parsed.

    Checks Content-Length up front and counts the bytes of bodies sent without it (chunked),
    so a client cannot make the multipart parser spool an unbounded upload. Whatever the app
    answered to a body cut short (the form parser says 400) is replaced by the 413.
    """

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        extra = settings.multipart_overhead_bytes
        self.limits = {
            f"{API_PREFIX}/analyses": settings.max_video_bytes + extra,
            f"{API_PREFIX}/references": settings.max_bvh_bytes + settings.max_domain_bytes + extra,
            f"{API_PREFIX}/references/takes": settings.max_reference_takes
            * (settings.max_bvh_bytes + extra),
        }

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] in SAFE_METHODS:
            await self.app(scope, receive, send)
            return
        limit = self.limits.get(scope["path"].rstrip("/"), SMALL_BODY_BYTES)
        declared = Headers(scope=scope).get("content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            await self._refuse(send, limit)
            return
        received, too_large, started = 0, False, False

        async def counting_receive() -> Message:
            nonlocal received, too_large
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > limit:
                    too_large = True
                    raise _BodyTooLarge
            return message

        async def tracking_send(message: Message) -> None:
            nonlocal started
            if too_large:  # the app's answer to a body we cut short: ours replaces it
                return
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counting_receive, tracking_send)
        except _BodyTooLarge:
            pass
        if too_large and not started:
            await self._refuse(send, limit)

    @staticmethod
    async def _refuse(send: Send, limit: int) -> None:
        await _send_response(send, errors.error_response(
            413, "too_large", f"the request body is larger than the limit of {limit} bytes",
            {"limit_bytes": limit},
        ))  # fmt: skip


class CrossOriginGuard:
    """Refuses state changes that a browser sends from another origin (CSRF).

    Browsers say where a request comes from: ``Sec-Fetch-Site`` (all current ones) or else
    ``Origin``. A change is allowed when it comes from this origin (or a configured CORS
    origin), when it carries its own credentials (an API key or a bearer token: a page on
    another site cannot add those without CORS), or when no browser header is present (not a
    browser, so no ambient cookie to abuse). SameSite=Lax alone let a sibling subdomain post.
    """

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        self.allowed = {o.rstrip("/") for o in settings.cors_origins}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] not in SAFE_METHODS:
            headers = Headers(scope=scope)
            if not self._allowed(headers, scope):
                await _send_response(send, errors.error_response(
                    403, "cross_origin",
                    "cross-origin request refused: send it from this site, or with an API key",
                ))  # fmt: skip
                return
        # A websocket (the 3D view's) carries the session cookie like a state change: one
        # opened by a page of another site, even a sibling subdomain, is refused (4403)
        # before the app sees it.
        if scope["type"] == "websocket" and not self._allowed(Headers(scope=scope), scope):
            await receive()  # websocket.connect
            await send({"type": "websocket.close", "code": 4403, "reason": "cross-origin"})
            return
        await self.app(scope, receive, send)

    def _allowed(self, headers: Headers, scope: Scope) -> bool:
        if "x-api-key" in headers or "authorization" in headers:
            return True
        origin = headers.get("origin")
        if origin and origin in self.allowed:
            return True
        site = headers.get("sec-fetch-site")
        if site is not None:
            return site in ("same-origin", "none")
        if origin is None:
            return True
        scheme = scope.get("scheme", "http")
        scheme = {"ws": "http", "wss": "https"}.get(scheme, scheme)  # a websocket's page
        return origin == f"{scheme}://{headers.get('host', '')}"


#: Pages load only their own scripts and styles; the 3D view is a frame of this origin too
#: (web.viewer.proxy relays it).
CSP = (
    b"default-src 'self'; script-src 'self'; style-src 'self'; "
    b"img-src 'self' data: blob:; media-src 'self' blob:; connect-src 'self'; "
    b"frame-src 'self'; frame-ancestors 'self'; "
    b"object-src 'none'; base-uri 'self'; form-action 'self'"
)


class SecurityHeadersMiddleware:
    """Headers every response carries; API data is never cached, pages get a CSP, and HSTS
    is sent where cookies are https-only (outside development)."""

    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        self.hsts = not settings.is_development

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        path: str = scope["path"]
        extra = [
            (b"x-content-type-options", b"nosniff"),
            (b"referrer-policy", b"same-origin"),
            (b"x-frame-options", b"SAMEORIGIN"),
            (b"permissions-policy", b"camera=(), microphone=(), geolocation=(), payment=()"),
        ]
        if self.hsts:
            extra.append((b"strict-transport-security", b"max-age=31536000; includeSubDomains"))
        if not path.startswith(f"{API_PREFIX}/docs"):  # Swagger UI runs inline scripts
            extra.append((b"content-security-policy", CSP))

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                names = {k.lower() for k, _ in headers}
                if path.startswith(API_PREFIX) and b"cache-control" not in names:
                    headers.append((b"cache-control", b"no-store"))
                # A response with a policy of its own keeps it (the framed 3D view's page,
                # web.viewer.proxy): two policies would both apply, the stricter winning.
                own = b"content-security-policy" in names
                message["headers"] = headers + [
                    h for h in extra if not (own and h[0] == b"content-security-policy")
                ]
            await send(message)

        await self.app(scope, receive, send_with_headers)
