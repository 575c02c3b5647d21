"""Error answers of the HTTP API: every 4xx names what is wrong in words a user understands.

Every answer other than 2xx is ``{"detail": "<what is wrong>"}`` (:class:`ErrorBody`):

- 401: no API key, or an unknown one (when keys are configured, :mod:`vda_master.api_auth`);
- 403: a viewer key on an operation that acts;
- 404: an unknown vehicle, node, edge or order;
- 405: the path exists but not with this method; ``Allow`` lists every method it has;
- 409: the vehicle cannot take it *now* (busy, offline, not in AUTOMATIC, ...);
- 413: the request body is larger than the configured limit;
- 415: the request body is not declared as JSON (``content-type: application/json``);
- 422: the request itself is wrong (malformed JSON with line and column, a missing or unknown
  field by name, a route that is not continuous), or the vehicle can never serve it (an action
  or field its factsheet does not offer).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

from fastapi import Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.routing import BaseRoute, Match, Route
from starlette.types import ASGIApp, Message, Receive, Scope, Send

_JSON_TYPES: Final = ("application/json",)
_BODY_METHODS: Final = frozenset({"POST", "PUT", "PATCH"})


class ErrorBody(BaseModel):
    """What every 4xx answer carries."""

    detail: str


def error_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries documenting the error body of each status."""
    meaning = {
        401: "missing or unknown API key",
        403: "the API key may only read",
        404: "unknown vehicle, node, edge or order",
        409: "the vehicle cannot take this now (the detail says why)",
        413: "request body too large",
        415: "request body is not JSON (content-type)",
        422: "invalid request, or one the vehicle can never serve (the detail says what)",
        503: "the order store does not answer now (the detail says why); try again",
    }
    return {status: {"model": ErrorBody, "description": meaning[status]} for status in statuses}


def error(status: int, detail: str) -> JSONResponse:
    """An error answer with ``detail``."""
    return JSONResponse({"detail": detail}, status_code=status)


async def invalid_request(request: Request, exc: RequestValidationError) -> JSONResponse:
    """422/415 with a message for the first thing wrong with the request."""
    errors = list(exc.errors())
    if request.method in _BODY_METHODS and any(_about_body(e) for e in errors):
        problem = await _body_problem(request, errors)
        if problem is not None:
            return error(*problem)
    return error(422, describe_errors(errors))


async def http_error(request: Request, exc: HTTPException) -> Response:
    """FastAPI's answer to an HTTP error, except for two: a body that is not UTF-8 is a 422
    that says so, as other malformed JSON is (FastAPI answers a bare 400); a 405 names the
    method and lists in ``Allow`` every method of the path (FastAPI keeps one route per method,
    and Starlette's 405 lists only the methods of the first route whose path matched; RFC 9110
    §15.5.6 asks for all of them)."""
    if isinstance(exc.__cause__, UnicodeDecodeError):  # FastAPI's 400 "error parsing the body"
        return error(422, _not_utf8(exc.__cause__))
    if exc.status_code != 405:  # noqa: PLR2004 - HTTP status
        return await http_exception_handler(request, exc)
    allowed = _allowed_methods(request.app.router.routes, request.scope)
    response = error(
        405, f"{request.method} is not allowed on {request.url.path}: use {' or '.join(allowed)}"
    )
    response.headers["Allow"] = ", ".join(allowed)
    return response


def _allowed_methods(routes: Sequence[BaseRoute], scope: Scope) -> list[str]:
    """Every method some route of ``routes`` takes on the path of ``scope``, sorted."""
    methods: set[str] = set()
    for route in routes:
        if isinstance(route, Route) and route.methods:
            match, _ = route.matches(scope)
            if match is not Match.NONE:
                methods |= route.methods
    return sorted(methods)


def describe_errors(errors: Sequence[Mapping[str, Any]]) -> str:
    """One sentence per validation error, naming the field in the request's own spelling."""
    return "; ".join(_describe(e) for e in errors) or "invalid request"


def _about_body(error_: Mapping[str, Any]) -> bool:
    loc = error_.get("loc", ())
    return bool(loc) and loc[0] == "body"


async def _body_problem(
    request: Request, errors: Sequence[Mapping[str, Any]]
) -> tuple[int, str] | None:
    """What is wrong with the body as a whole (type, JSON syntax, emptiness, shape), if that is
    the problem rather than one of its fields."""
    media_type = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    if media_type not in _JSON_TYPES and not media_type.endswith("+json"):
        got = f"got {media_type!r}" if media_type else "the header is missing"
        return 415, f"request body must be JSON: send 'content-type: application/json' ({got})"
    body = await request.body()
    if not body.strip():
        return 422, "request body is empty: send a JSON object"
    if any(e.get("type") == "json_invalid" for e in errors):
        try:
            json.loads(body)
        except json.JSONDecodeError as exc:
            where = f"at line {exc.lineno} column {exc.colno}"
            return 422, f"request body is not valid JSON: {exc.msg} {where}"
        except UnicodeDecodeError as exc:
            return 422, _not_utf8(exc)
    shape = [e for e in errors if tuple(e.get("loc", ())) == ("body",)]
    if shape and shape[0].get("type") in {"model_attributes_type", "dict_type", "model_type"}:
        kind = type(shape[0].get("input")).__name__
        named = {"list": "an array", "str": "a string", "int": "a number", "float": "a number"}
        return 422, f"request body must be a JSON object, not {named.get(kind, kind)}"
    return None


def _not_utf8(exc: UnicodeDecodeError) -> str:
    byte = exc.object[exc.start : exc.start + 1].hex()
    return f"request body is not valid JSON: it is not UTF-8 text (byte 0x{byte} at {exc.start})"


def _describe(error_: Mapping[str, Any]) -> str:
    loc = [str(part) for part in error_.get("loc", ())]
    message = str(error_.get("msg", "invalid")).removeprefix("Value error, ")
    if loc and loc[0] in {"query", "path", "header"}:
        return f"{loc[0]} parameter {'.'.join(loc[1:])!r}: {message}"
    where = ".".join(loc[1:] if loc and loc[0] == "body" else loc)
    kind = error_.get("type")
    if kind == "missing":
        return f"missing field {where!r}" if where else "missing request body"
    if kind == "extra_forbidden":
        return f"unknown field {where!r}"
    return f"field {where!r}: {message}" if where else message


@dataclass(frozen=True, slots=True)
class UploadLimit:
    """A larger body limit for ``PUT`` requests under ``prefix`` (map files), named after its
    master setting."""

    prefix: str
    max_bytes: int
    setting: str


class BodyLimitMiddleware:
    """413 with ``{"detail": ...}`` for a request body over ``max_bytes`` (``upload``'s limit
    for an upload it covers): by its Content-Length before anything is read, or, for a body
    without one, once more than the limit streamed in (such a body is read here first and
    handed on whole). The loop never parses more than the limit of one request."""

    def __init__(self, app: ASGIApp, max_bytes: int, upload: UploadLimit | None = None) -> None:
        self.app = app
        self.max_bytes = max_bytes
        self.upload = upload

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit, setting = self.max_bytes, "max_body_bytes"
        upload = self.upload
        if (
            upload is not None
            and scope["method"] == "PUT"
            and scope["path"].startswith(upload.prefix)
        ):
            limit, setting = upload.max_bytes, upload.setting
        declared = Headers(scope=scope).get("content-length")
        if declared is not None:
            if declared.isdigit() and int(declared) > limit:
                await _refuse(limit, setting, scope, receive, send)
                return
            await self.app(scope, receive, send)
            return
        chunks: list[bytes] = []
        size, more = 0, True
        while more:
            message = await receive()
            if message["type"] != "http.request":
                return  # the client went away
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > limit:
                await _refuse(limit, setting, scope, receive, send)
                return
            chunks.append(chunk)
            more = message.get("more_body", False)
        await self.app(scope, replay(b"".join(chunks), receive), send)


async def _refuse(limit: int, setting: str, scope: Scope, receive: Receive, send: Send) -> None:
    detail = f"request body is larger than the limit of {limit} bytes (master setting {setting})"
    await error(413, detail)(scope, receive, send)


def replay(body: bytes, receive: Receive) -> Receive:
    """``receive`` with ``body``, already read, delivered first."""
    delivered = False

    async def replayed() -> Message:
        nonlocal delivered
        if delivered:
            return await receive()
        delivered = True
        return {"type": "http.request", "body": body, "more_body": False}

    return replayed
