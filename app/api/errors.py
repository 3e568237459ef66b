"""The API's one error shape: ``{"error": {"code", "message", "details"}}``.

Routes and dependencies raise :class:`ApiError`; FastAPI's own errors (validation, 404 of
unknown paths, 405) are rewritten into the same shape by the handlers installed here.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from app.schemas import ErrorResponse

#: OS error numbers quoted by libraries ("[Errno 1094995529] Invalid data ...").
_ERRNO = re.compile(r"\[Errno -?\d+\]\s*")


class ApiError(Exception):
    def __init__(
        self,
        status_code: int,
        code: str,
        message: str,
        details: dict[str, Any] | None = None,
        headers: dict[str, str] | None = None,
    ) -> None:
        super().__init__(message)
        self.status_code = status_code
        self.code = code
        self.message = message
        self.details = details or {}
        self.headers = headers


def not_found(what: str, ident: object) -> ApiError:
    return ApiError(404, "not_found", f"{what} {ident} does not exist", {"id": str(ident)})


def rate_limited(wait_s: float, why: str) -> ApiError:
    """A 429 telling when to come back (``Retry-After``, whole seconds)."""
    retry = max(1, math.ceil(wait_s))
    return ApiError(
        429, "rate_limited", f"{why}; try again in {retry} s", {"retry_after_s": retry},
        headers={"Retry-After": str(retry)},
    )  # fmt: skip


def error_response(
    status_code: int,
    code: str,
    message: str,
    details: dict[str, Any] | None = None,
    headers: dict[str, str] | None = None,
) -> JSONResponse:
    # Libraries' OS error numbers ("[Errno 1094995529] Invalid data ...") mean nothing to a
    # client; whatever route wrapped such a message, they go here.
    message = _ERRNO.sub("", message)
    body = {"error": {"code": code, "message": message, "details": details or {}}}
    return JSONResponse(jsonable_encoder(body), status_code=status_code, headers=headers)


#: For route decorators: ``responses=errors(401, 404)`` documents the error shape in OpenAPI.
def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    return {c: {"model": ErrorResponse, "description": HTTPStatus(c).phrase} for c in codes}


def json_errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """:func:`errors` for a route whose success is not JSON (FastAPI would document its
    errors in the route's media type)."""
    schema = {"$ref": "#/components/schemas/ErrorResponse"}
    return {
        c: {
            "description": HTTPStatus(c).phrase,
            "content": {"application/json": {"schema": schema}},
        }
        for c in codes
    }


async def _api_error(_request: Request, exc: ApiError) -> JSONResponse:
    return error_response(exc.status_code, exc.code, exc.message, exc.details, exc.headers)


def _allowed_methods(request: Request) -> str:
    """Every method some route serves at this path. Starlette's 405 names only those of the
    first route it tried, and FastAPI makes one route per method."""
    return ", ".join(sorted(_methods_at(request.app.router.routes, request.scope)))


def _methods_at(routes: Iterable[Any], scope: dict) -> set[str]:
    methods: set[str] = set()
    for route in routes:
        # FastAPI >= 0.16x keeps an included router whole: its routes are its candidates.
        candidates = getattr(route, "effective_candidates", None)
        if callable(candidates):
            methods |= _methods_at(candidates(), scope)
            continue
        match, _ = route.matches(scope)
        if match != Match.NONE:
            served = getattr(route, "methods", None)
            if served is None:
                served = getattr(getattr(route, "original_route", None), "methods", None)
            methods |= set(served or ())
    return methods


async def _http_error(request: Request, exc: StarletteHTTPException) -> Response:
    headers = dict(getattr(exc, "headers", None) or {})
    if exc.status_code == 400:  # a body that could not be parsed: like any invalid request
        problem = {"loc": "body", "message": "the request body could not be read", "type": "body"}
        return error_response(
            422, "invalid_request", "body: the request body could not be read",
            {"errors": [problem]},
        )  # fmt: skip
    if exc.status_code == 405:
        headers["Allow"] = _allowed_methods(request)
    code = {404: "not_found", 405: "method_not_allowed"}.get(
        exc.status_code, HTTPStatus(exc.status_code).phrase.lower().replace(" ", "_")
    )
    message = exc.detail if isinstance(exc.detail, str) else HTTPStatus(exc.status_code).phrase
    # A person's browser gets a page; the API (and anything not asking for HTML) gets JSON.
    # The page comes from a mounted package (web), which sets app.state.html_error.
    from app.api.middleware import API_PREFIX  # (middleware imports this module)

    page = getattr(request.app.state, "html_error", None)
    wants_html = "text/html" in request.headers.get("accept", "")
    if page is not None and wants_html and not request.url.path.startswith(API_PREFIX):
        return page(request, exc.status_code, message)
    return error_response(exc.status_code, code, message, headers=headers or None)


#: Parts of a pydantic error location that name its schema, not the request: union members
#: ("function-wrap[wrap_val()]", "literal['']"), wrappers ("lax-or-strict", "json-or-python").
_SCHEMA_TAG = re.compile(
    r"[^A-Za-z0-9_.-]|^(function-(wrap|after|before|plain)|lax-or-strict|json-or-python"
    r"|tagged-union|nullable|default|chain|is-instance|constrained-[a-z]+)$"
)
#: Prefixes pydantic puts before the message of a validator's exception.
_MESSAGE_PREFIXES = ("Value error, ", "Assertion failed, ")


def plain_message(message: str) -> str:
    """A validator's message as a person reads it, without pydantic's prefix."""
    for prefix in _MESSAGE_PREFIXES:
        message = message.removeprefix(prefix)
    return message


def _problem(e: dict[str, Any]) -> dict[str, str]:
    """One validation error as ``{"loc": "body.webhook_url", "message", "type"}``."""
    loc = [str(p) for p in e.get("loc", ()) if isinstance(p, int) or not _SCHEMA_TAG.search(p)]
    kind = e.get("type", "")
    message = plain_message(e.get("msg", ""))
    if kind == "json_invalid":  # its loc ends with a character position, not a field
        loc = loc[:1]
        why = (e.get("ctx") or {}).get("error")
        message = f"the body is not valid JSON ({why})" if why else "the body is not valid JSON"
    return {"loc": ".".join(loc), "message": message, "type": kind}


def invalid(loc: str, message: str, kind: str = "value_error", **details: Any) -> ApiError:
    """A 422 in the shape of a validation error, for checks a route makes itself.

    ``loc`` is where the value came from and its name: ``"body.webhook_url"``.
    """
    problem = {"loc": loc, "message": message, "type": kind}
    where = loc.split(".", 1)[-1]
    return ApiError(422, "invalid_request", f"{where}: {message}", {"errors": [problem], **details})


async def _validation_error(_request: Request, exc: RequestValidationError) -> JSONResponse:
    problems: list[dict[str, str]] = []
    for p in map(_problem, exc.errors()):
        if all(p["loc"] != q["loc"] for q in problems):  # one per field (not per union member)
            problems.append(p)
    first = problems[0] if problems else {"loc": "", "message": "invalid request"}
    where = first["loc"].split(".", 1)[-1]
    return error_response(
        422,
        "invalid_request",
        f"{where}: {first['message']}" if where else first["message"],
        {"errors": problems},
    )


def install(app: FastAPI) -> None:
    app.add_exception_handler(ApiError, _api_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
