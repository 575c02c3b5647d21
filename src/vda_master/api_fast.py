"""A short way for ``POST /orders`` past FastAPI's per-request machinery (issue 12).

FastAPI's exception, body-limit and exit-stack layers, its routing, dependency solving and
response handling cost about 200 µs of a ``POST /orders`` on this project's machines: 1138
against 932 µs of master CPU per order in ``benchmarks/post_orders.py --compare-fastapi``
(docs/performance.md, lever 47). :class:`FastOrderPost` answers the common case itself: a JSON
body that parses and validates as the route's own model, sent with a key that may act. It
validates with the same model and hands the request to the same function as the FastAPI
route, so the answer is the route's answer.

Everything else goes on to FastAPI unchanged, with the body it has read: another content type,
a body that does not parse or validate, a missing or insufficient key. Every error answer
about the request itself therefore stays FastAPI's own (and :mod:`vda_master.api_errors`'s);
the fast path renders only the refusals the handler raises (404, 409, 422 from master control,
503 from the store), with the same function as the application's exception handlers.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Final, Generic, TypeVar

import orjson
from pydantic import BaseModel, ValidationError
from starlette.datastructures import Headers
from starlette.requests import Request
from starlette.responses import Response
from starlette.types import ASGIApp, Receive, Scope, Send

from vda_master.api_errors import replay

_JSON: Final = "application/json"

M = TypeVar("M", bound=BaseModel)


@dataclass(frozen=True, slots=True)
class ShortRoute(Generic[M]):
    """What the short way needs of its route: the path, the body model, whether a request may
    use it, the handler, and how the handler's refusals are answered (None: not a refusal)."""

    path: str
    model: type[M]
    authorized: Callable[[Request], bool]
    handle: Callable[[M], Awaitable[Response]]
    refusal: Callable[[Exception], Response | None]


class FastOrderPost(Generic[M]):
    """ASGI middleware: ``POST route.path`` with a valid body goes to ``route.handle``
    directly, when ``route.authorized`` lets the request act; anything else goes on to
    ``app``."""

    def __init__(self, app: ASGIApp, *, route: ShortRoute[M]) -> None:
        self.app = app
        self.route = route

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        route = self.route
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] != route.path:
            await self.app(scope, receive, send)
            return
        content_type = Headers(scope=scope).get("content-type", "")
        if content_type.split(";", 1)[0].strip().lower() != _JSON or not route.authorized(
            Request(scope)
        ):
            await self.app(scope, receive, send)
            return
        body = await _read_body(receive)
        if body is None:
            return  # the client went away before its body was in
        request = self._parsed(body)
        if request is None:
            await self.app(scope, replay(body, receive), send)
            return
        try:
            response = await route.handle(request)
        except Exception as exc:
            refused = route.refusal(exc)
            if refused is None:
                raise  # as FastAPI would: ServerErrorMiddleware answers 500 and logs it
            response = refused
        await response(scope, receive, send)

    def _parsed(self, body: bytes) -> M | None:
        """The body as the route's model, or None when FastAPI should say what is wrong."""
        try:
            return self.route.model.model_validate(orjson.loads(body))
        except (orjson.JSONDecodeError, ValidationError):
            return None


async def _read_body(receive: Receive) -> bytes | None:
    """The whole request body, or None if the client disconnected first."""
    chunks: list[bytes] = []
    while True:
        message = await receive()
        if message["type"] != "http.request":
            return None
        chunks.append(message.get("body", b""))
        if not message.get("more_body", False):
            return b"".join(chunks)
