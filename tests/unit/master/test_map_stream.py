"""The map's stream over a master service without a broker: snapshot, batched changes, the
traffic seam and the fallback to a snapshot for a reader that fell behind."""

from __future__ import annotations

import asyncio
from collections.abc import Mapping
from typing import Any

import orjson
import pytest

from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.graph_file import GraphZone
from vda5050.models import ActionStatus, AgvPosition, Connection, ConnectionState, Visualization
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master.config import MasterConfig
from vda_master.live import LiveView
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.service import MasterService
from vda_master.testing import RecordingPublisher, demo_graph, make_factsheet, plan_state, zone
from vda_master.web.stream import MapStream

AGV = AgvId("acme", "robot_0")
KEY = "acme/robot_0"


def _topic(kind: Topic) -> str:
    return build_topic("uagv", 2, AGV, kind)


def _at_node_7() -> bytes:
    position = AgvPosition(x=0.0, y=0.0, theta=0.0, map_id="demo", position_initialized=True)
    return encode(make_state(last_node_id="7", agv_position=position))


def _service() -> tuple[MasterService, FakeClock]:
    clock = FakeClock()
    service = MasterService(MasterConfig(), demo_graph(), RecordingPublisher(), clock)
    online = Connection.model_validate({**HEADER, "connection_state": ConnectionState.ONLINE})
    service.ingest(_topic(Topic.CONNECTION), encode(online))
    service.ingest(_topic(Topic.FACTSHEET), encode(make_factsheet()))
    service.ingest(_topic(Topic.STATE), _at_node_7())
    return service, clock


def _visualization(x: float, y: float) -> bytes:
    position = AgvPosition(x=x, y=y, theta=1.0, map_id="demo", position_initialized=True)
    return encode(Visualization.model_validate({**HEADER, "agv_position": position}))


def _event(raw: bytes | None) -> tuple[str, dict[str, object]]:
    assert raw is not None
    head, data = raw.decode().strip().split("\n")
    loaded: dict[str, object] = orjson.loads(data.removeprefix("data: "))
    return head.removeprefix("event: "), loaded


def _one(body: dict[str, object], key: str) -> dict[str, Any]:
    listed = body[key]
    assert isinstance(listed, list)
    assert len(listed) == 1
    item: dict[str, Any] = listed[0]
    return item


def _vehicles(body: dict[str, object]) -> dict[str, dict[str, object]]:
    listed = body.get("vehicles", [])
    assert isinstance(listed, list)
    return {v["id"]: v for v in listed}


def test_the_master_subscribes_to_visualization() -> None:
    """Visualization is subscribed besides state, connection and factsheet."""
    service, _ = _service()
    assert Topic.VISUALIZATION in {kind for _, kind in service.subscriptions()}


def test_snapshot_holds_graph_vehicles_orders_and_traffic() -> None:
    """The first event draws everything: stations with their type, the vehicle where its
    state puts it, its battery, the recent orders and traffic control's snapshot."""
    service, _ = _service()
    service.create_order(OrderRequest(Target(destination="10"), AGV))
    name, body = _event(MapStream(service).snapshot())
    assert name == "snapshot"
    graph = body["graph"]
    assert isinstance(graph, dict)
    stations = {n["id"]: n["stationType"] for n in graph["nodes"] if n["stationType"]}
    assert stations["11"] == "pick"
    assert len(graph["edges"]) == len(service.graph.edges)
    vehicle = _vehicles(body)[KEY]
    assert vehicle["connection"] == "ONLINE"
    assert (vehicle["x"], vehicle["y"]) == (0.0, 0.0)  # node 7
    assert vehicle["battery"] == 80.0
    assert vehicle["activeOrderId"] is not None
    orders = body["orders"]
    assert isinstance(orders, list)
    assert [o["status"] for o in orders] == ["SENT"]
    traffic = body["traffic"]
    assert isinstance(traffic, dict)
    assert traffic["enabled"] is True
    assert traffic == service.traffic_snapshot()


def test_a_visualization_sends_only_the_pose_with_its_receive_stamp() -> None:
    """A visualization changes the pose alone; the change carries when it was received."""
    service, clock = _service()
    stream = MapStream(service)
    reader = service.live.subscribe()
    clock.advance(1.0)
    service.ingest(_topic(Topic.VISUALIZATION), _visualization(3.0, 4.0))
    name, body = _event(stream.changes(service.live.drain(reader)))
    assert name == "changes"
    pose = _one(body, "poses")
    assert (pose["id"], pose["x"], pose["y"], pose["theta"]) == (KEY, 3.0, 4.0, 1.0)
    assert pose["rx"] > 0
    assert "vehicles" not in body


def test_a_vehicle_the_master_forgets_is_sent_as_removed_and_its_pose_dropped() -> None:
    """A silent vehicle the master forgets (forget_after_s) is listed under ``removed`` in
    the next change, its pose is no longer kept, and a later snapshot does not hold it."""
    service, clock = _service()
    stream = MapStream(service)
    reader = service.live.subscribe()
    service.ingest(_topic(Topic.VISUALIZATION), _visualization(3.0, 4.0))
    service.live.drain(reader)
    assert AGV in service.live.poses
    clock.advance(service.config.forget_after_s + 10.0)
    service.tick()
    assert service.fleet.get(AGV) is None
    name, body = _event(stream.changes(service.live.drain(reader)))
    assert name == "changes"
    assert body["removed"] == [KEY]
    assert "vehicles" not in body
    assert "poses" not in body
    assert AGV not in service.live.poses
    assert AGV not in service.live.received
    _, snapshot = _event(stream.snapshot())
    assert snapshot["vehicles"] == []


def test_the_newer_of_visualization_and_state_gives_the_position() -> None:
    """A state after the visualization wins with its agvPosition, and the other way round."""
    service, clock = _service()
    stream = MapStream(service)
    clock.advance(1.0)
    service.ingest(_topic(Topic.VISUALIZATION), _visualization(3.0, 4.0))
    assert _vehicles(_event(stream.snapshot())[1])[KEY]["x"] == 3.0
    clock.advance(1.0)
    service.ingest(_topic(Topic.STATE), _at_node_7())
    assert _vehicles(_event(stream.snapshot())[1])[KEY]["x"] == 0.0


def test_unknown_vehicles_visualization_is_ignored() -> None:
    """A pose of a vehicle the fleet view does not hold is not kept (bounded by the fleet)."""
    service, _ = _service()
    stranger = build_topic("uagv", 2, AgvId("acme", "ghost"), Topic.VISUALIZATION)
    service.ingest(stranger, _visualization(1.0, 1.0))
    assert AgvId("acme", "ghost") not in service.live.poses


def test_order_changes_are_sent_with_their_status() -> None:
    """Creating an order puts it into the next changes event."""
    service, _ = _service()
    stream = MapStream(service)
    reader = service.live.subscribe()
    track = service.create_order(OrderRequest(Target(destination="10"), AGV))
    _, body = _event(stream.changes(service.live.drain(reader)))
    order = _one(body, "orders")
    assert (order["orderId"], order["vehicle"], order["status"]) == (track.order_id, KEY, "SENT")


def test_traffic_is_sent_when_notified_and_only_when_it_changed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The traffic seam: a notified snapshot goes out once; an unchanged one is not resent."""
    service, _ = _service()
    stream = MapStream(service)
    stream.snapshot()
    reader = service.live.subscribe()
    snapshot: Mapping[str, object] = {"vehicles": [{"serialNumber": "robot_0", "waitingFor": []}]}
    monkeypatch.setattr(service, "traffic_snapshot", lambda: snapshot)
    service.live.traffic_changed()
    _, body = _event(stream.changes(service.live.drain(reader)))
    assert body["traffic"] == snapshot
    service.live.traffic_changed()
    assert stream.changes(service.live.drain(reader)) is None


async def test_events_batch_a_burst_into_one_event_and_end_when_the_master_stops() -> None:
    """Fifty poses within one flush window arrive as one event; close() ends the stream."""
    service, clock = _service()
    events = MapStream(service, flush_s=0.05).events()
    name, _ = _event(await anext(events))
    assert name == "snapshot"
    for step in range(50):
        clock.advance(0.01)
        service.ingest(_topic(Topic.VISUALIZATION), _visualization(float(step), 0.0))
    name, body = _event(await anext(events))
    assert name == "changes"
    pose = _one(body, "poses")
    assert pose["x"] == 49.0
    service.live.close()
    async with asyncio.timeout(2):
        assert [e async for e in events] == []
    assert service.live.readers == 0


async def test_a_reader_that_fell_behind_gets_a_fresh_snapshot() -> None:
    """Past the pending limit the next event is a snapshot, not an ever-growing diff."""
    service, _ = _service()
    service.live = LiveView(max_pending=5)
    events = MapStream(service, flush_s=0.0).events()
    await anext(events)
    for index in range(20):
        service.live.order_changed(f"o{index}")
    name, _ = _event(await anext(events))
    assert name == "snapshot"
    await events.aclose()


async def test_a_change_of_zones_sends_every_reader_a_snapshot_with_the_new_graph() -> None:
    """The page redraws the graph from a snapshot: a zone added through the API is drawn at
    once, its closed edges apart."""
    service, _ = _service()
    events = MapStream(service, flush_s=0.0).events()
    name, first = _event(await anext(events))
    assert "zones" not in first["graph"]  # type: ignore[operator]
    spill = zone("spill", "BLOCKED", [[13.0, -1.5], [17.0, -1.5], [17.0, 1.5], [13.0, 1.5]])
    await service.add_zone(GraphZone.model_validate(spill))
    name, body = _event(await anext(events))
    assert name == "snapshot"
    graph = body["graph"]
    assert isinstance(graph, dict)
    assert [z["zoneId"] for z in graph["zones"]] == ["spill"]
    assert {e[0] for e in graph["blockedEdges"]} == {"11", "21", "45"}
    await events.aclose()


def test_queued_orders_are_listed_and_sent_when_they_wait_and_when_they_go() -> None:
    """An order waiting for the busy vehicle is in the snapshot and in a changes event
    (QUEUED, no vehicle named); once the vehicle is free it comes again as the vehicle's."""
    service, _ = _service()
    running = service.create_order(OrderRequest(Target(destination="10"), AGV))
    stream = MapStream(service)
    reader = service.live.subscribe()
    service.live.drain(reader)
    assert isinstance(service.clock, FakeClock)
    service.clock.advance(1.0)  # newer: listed first
    waiting = service.place_order(OrderRequest(Target(destination="12"), queue=True))
    _, body = _event(stream.changes(service.live.drain(reader)))
    order = _one(body, "orders")
    assert (order["orderId"], order["vehicle"], order["status"]) == (
        waiting.order_id,
        None,
        "QUEUED",
    )
    assert "it runs order" in str(order["reason"])
    _, snapshot = _event(stream.snapshot())
    listed = snapshot["orders"]
    assert isinstance(listed, list)
    assert [(o["orderId"], o["status"]) for o in listed] == [
        (waiting.order_id, "QUEUED"),
        (running.order_id, "SENT"),
    ]
    plan = running.plan
    finished = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
    done = plan_state(plan, passed=plan.last_index, actions=finished)
    service.ingest(build_topic("uagv", 2, AGV, Topic.STATE), encode(done))
    _, body = _event(stream.changes(service.live.drain(reader)))
    orders = body["orders"]
    assert isinstance(orders, list)
    served = next(o for o in orders if o["orderId"] == waiting.order_id)
    assert (served["vehicle"], served["status"], served["active"]) == (KEY, "SENT", True)
