"""HTTP routes of the map: the page, its assets and the event stream."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Final

from fastapi import FastAPI, params
from fastapi.responses import HTMLResponse, StreamingResponse
from fastapi.staticfiles import StaticFiles

from vda_master.service import MasterService
from vda_master.web.stream import MapStream

STATIC: Final = Path(__file__).parent / "static"
ASSETS: Final = "/map-assets"
#: Headers of the event stream: never cached, never buffered by a proxy.
_STREAM_HEADERS: Final = {"Cache-Control": "no-cache", "X-Accel-Buffering": "no"}


def add_map(
    app: FastAPI, service: MasterService, *, stream_dependencies: Sequence[params.Depends] = ()
) -> None:
    """Mount the page (``/``, ``/map``), its assets and ``/events`` on ``app``.

    The page and its assets hold no data and stay open; ``stream_dependencies`` guard the
    stream (e.g. the API-key check of the read routes): the page sends the key with it.
    """
    page = (STATIC / "index.html").read_text(encoding="utf-8")
    app.mount(ASSETS, StaticFiles(directory=STATIC), name="map-assets")

    @app.get("/", include_in_schema=False)
    @app.get("/map", include_in_schema=False)
    async def map_page() -> HTMLResponse:
        return HTMLResponse(page, headers={"Cache-Control": "no-cache"})

    @app.get(
        "/events",
        dependencies=list(stream_dependencies),
        response_class=StreamingResponse,
        summary="Live map stream (Server-Sent Events)",
        description="A `snapshot` event (graph, vehicles, recent orders, traffic), then "
        "`changes` events with what changed, at most every 50 ms (docs/web.md).",
    )
    async def events() -> StreamingResponse:
        stream = MapStream(service)
        return StreamingResponse(
            stream.events(), media_type="text/event-stream", headers=_STREAM_HEADERS
        )
