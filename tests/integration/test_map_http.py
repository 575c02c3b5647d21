"""The map over the master's real HTTP server: page, assets, and a live stream that a stopping
master ends instead of waiting for the browser to leave."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Annotated

import httpx
import orjson
import pytest
from fastapi import Depends, FastAPI, Header, HTTPException

from tests.integration.master_helpers import running_master
from vda5050.broker import BrokerAddress
from vda5050.clock import FakeClock
from vda_master.config import MasterConfig
from vda_master.runtime import MasterProcess
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, demo_graph
from vda_master.web import add_map
from vda_master.web.routes import STATIC

pytestmark = pytest.mark.integration


async def test_page_and_assets_are_served_from_the_package(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """/ and /map serve the page, which loads only /map-assets/ files that exist."""
    async with running_master(embedded_broker, unique_interface_name) as master:
        base = f"http://127.0.0.1:{master.api_port}"
        async with httpx.AsyncClient(base_url=base) as client:
            root, alias = await client.get("/"), await client.get("/map")
            script = await client.get("/map-assets/js/main.js")
            missing = await client.get("/map-assets/js/nothing.js")
    assert root.status_code == alias.status_code == 200
    assert root.text == alias.text
    assert 'src="/map-assets/js/main.js"' in root.text
    assert script.headers["content-type"].startswith(("text/javascript", "application/javascript"))
    assert missing.status_code == 404
    modules = {p.name for p in (STATIC / "js").glob("*.js")}
    assert {"main.js", "status.js", "stream.js", "api.js"} <= modules


async def test_event_stream_starts_with_a_snapshot_and_ends_when_the_master_stops(
    embedded_broker: BrokerAddress, unique_interface_name: str, tmp_path: Path
) -> None:
    """A client of /events gets the snapshot at once, its traffic part what GET /traffic
    answers; stopping the master closes the stream and the master exits promptly although the
    client never left."""
    config = MasterConfig.model_validate(
        {
            "broker_url": embedded_broker.url,
            "interface_name": unique_interface_name,
            "client_id": f"{unique_interface_name}-master",
            "api_port": 0,
            "data_dir": str(tmp_path),
        }
    )
    master = MasterProcess(config, graph=demo_graph())
    stop = asyncio.Event()
    async with asyncio.timeout(15), asyncio.TaskGroup() as group:
        running = group.create_task(master.run(stop))
        await master.session.wait_connected()
        while master.api_port is None:
            await asyncio.sleep(0.01)
        url = f"http://127.0.0.1:{master.api_port}/events"
        async with httpx.AsyncClient(timeout=5) as client, client.stream("GET", url) as response:
            assert response.headers["content-type"].startswith("text/event-stream")
            lines = response.aiter_lines()
            assert await anext(lines) == "event: snapshot"
            snapshot = orjson.loads((await anext(lines)).removeprefix("data: "))
            assert len(snapshot["graph"]["nodes"]) == len(master.graph.nodes)
            traffic = (await client.get(f"http://127.0.0.1:{master.api_port}/traffic")).json()
            assert snapshot["traffic"] == traffic
            assert traffic["enabled"] is True
            stop.set()
            rest = [line async for line in lines]
        await running
    assert rest == [""]


async def test_stream_dependencies_guard_the_stream_but_not_the_page() -> None:
    """With a key check given to add_map, /events answers 401 without the key; the page and
    its assets (no data in them) stay open."""

    async def needs_key(x_api_key: Annotated[str | None, Header()] = None) -> None:
        if x_api_key != "s3cret":
            raise HTTPException(401, "missing or wrong API key")

    service = MasterService(MasterConfig(), demo_graph(), RecordingPublisher(), FakeClock())
    app = FastAPI()
    add_map(app, service, stream_dependencies=[Depends(needs_key)])
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        refused = await client.get("/events")
        page = await client.get("/map")
        style = await client.get("/map-assets/map.css")
    assert refused.status_code == 401
    assert refused.json() == {"detail": "missing or wrong API key"}
    assert page.status_code == style.status_code == 200
