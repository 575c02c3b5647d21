"""A master service journaling into SQLite in one process, driven by hand-made states (the
tests of the store and of zones changed at run time)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import httpx

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import ActionState, ActionStatus, Connection, ConnectionState
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.api import create_app
from vda_master.config import MasterConfig
from vda_master.graph import Graph
from vda_master.journal import Journal
from vda_master.service import MasterService
from vda_master.store import Store, StoreWriter, WriteBatch, open_store
from vda_master.testing import RecordingPublisher, line_graph, plan_state

AGV = AgvId("acme", "robot_0")
SETTINGS = {"release_window_nodes": 3, "traffic_control": False, "confirm_timeout_s": 5.0}


class GatedStore:
    """A store whose writes wait until ``open`` is set (a slow or stuck database)."""

    def __init__(self, store: Store) -> None:
        self.store = store
        self.open = asyncio.Event()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.store, name)

    async def write(self, batch: WriteBatch) -> None:
        await self.open.wait()
        await self.store.write(batch)


@asynccontextmanager
async def journaled(
    data_dir: Path,
    *,
    gate: bool = False,
    clock: FakeClock | None = None,
    graph: Graph | None = None,
    **settings: object,
) -> AsyncIterator[tuple[MasterService, RecordingPublisher, Store, StoreWriter]]:
    """A master service on line graph n0…n11 (or ``graph``) journaling into SQLite in
    ``data_dir`` (its map files there too), with robot_0 ONLINE on n0; the writer is closed
    (everything written) on exit."""
    publisher = RecordingPublisher()
    service = MasterService(
        MasterConfig.model_validate({**SETTINGS, "data_dir": str(data_dir), **settings}),
        graph or line_graph(12),
        publisher,
        clock or FakeClock(),
    )
    async with open_store(None, data_dir) as sql:
        store: Store = GatedStore(sql) if gate else sql
        writer = StoreWriter(store)
        flushing = asyncio.create_task(writer.flush_loop())
        service.attach_journal(Journal(store, writer, service.clock))
        try:
            yield service, publisher, store, writer
        finally:
            if isinstance(store, GatedStore):
                store.open.set()
            await writer.close()
            await flushing


@asynccontextmanager
async def in_process_api(service: MasterService) -> AsyncIterator[httpx.AsyncClient]:
    """An HTTP client of ``service``'s API, called in process."""
    transport = httpx.ASGITransport(app=create_app(service))
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as client:
        yield client


def report(service: MasterService, **state: Any) -> None:
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(make_state(**state)))


def reconnect(service: MasterService) -> None:
    """robot_0's connection says ONLINE."""
    connected = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    service.ingest(build_topic("uagv", 2, AGV, Topic.CONNECTION), encode(connected))


def online(service: MasterService, node: str = "n0") -> None:
    """robot_0 ONLINE, standing on ``node``."""
    reconnect(service)
    report(service, last_node_id=node)


def drive(service: MasterService, order_id: str, passed: int, **fields: Any) -> None:
    """The vehicle confirms the latest update and reports node ``passed`` as its last."""
    track = service.tracks[order_id]
    state = plan_state(
        track.plan,
        update_id=track.update_id,
        passed=passed,
        released_end=track.released_end,
        **fields,
    )
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(state))


def cancel_ids(publisher: RecordingPublisher) -> list[str]:
    return [
        a["actionId"]
        for m in publisher.messages(Topic.INSTANT_ACTIONS)
        for a in m["actions"]
        if a["actionType"] == "cancelOrder"
    ]


def stop_after_cancel(service: MasterService, order_id: str, cancel: str, passed: int) -> None:
    """robot_0 stopped at node ``passed`` of the order: the cancel ``cancel`` FINISHED, its node
    and edge states empty (§6.6.3)."""
    track = service.tracks[order_id]
    state = plan_state(
        track.plan, update_id=track.update_id, passed=passed, released_end=track.released_end
    )
    finished = ActionState(action_id=cancel, action_status=ActionStatus.FINISHED)
    stopped = state.model_copy(
        update={
            "node_states": [],
            "edge_states": [],
            "action_states": [*state.action_states, finished],
        }
    )
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(stopped))
