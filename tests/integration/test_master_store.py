"""Master control on a real store (issue 10), in one process: write-ahead before the first
publish, the journal of changes and history, a restart that resumes tracking and releasing with
continuing headerIds, and orders that left memory still answered by the API."""

from __future__ import annotations

import asyncio
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import httpx
import pytest
from structlog.testing import capture_logs

from tests.integration.service_on_store import (
    AGV,
    GatedStore,
    cancel_ids,
    drive,
    journaled,
    online,
    reconnect,
    report,
    stop_after_cancel,
)
from vda5050.clock import FakeClock
from vda5050.codec import encode
from vda5050.models import ActionStatus, Connection
from vda5050.testing import HEADER, make_state
from vda5050.topics import AgvId, Topic, build_topic
from vda_master import journal as journal_module
from vda_master import persistence
from vda_master.api import create_app
from vda_master.dispatcher import OrderStatus
from vda_master.graph import Graph, build_graph
from vda_master.journal import Journal
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.service import MasterService
from vda_master.store import Store, WriteBatch
from vda_master.testing import (
    demo_graph,
    demo_graph_with_zones,
    line_graph,
    zone,
)

pytestmark = pytest.mark.integration


async def test_a_new_order_is_committed_before_its_first_message(tmp_path: Path) -> None:
    async with journaled(tmp_path, gate=True) as (service, publisher, store, writer):
        online(service)
        track = service.create_order(OrderRequest(Target(destination="n11"), AGV))
        await asyncio.sleep(0.2)
        assert publisher.orders() == []  # held: the store has not committed it yet
        assert isinstance(store, GatedStore)
        store.open.set()
        await service.committed(track.order_id)
        (order,) = publisher.orders()
        assert order["orderId"] == track.order_id
        await writer.flush()
        record = await store.get_order(track.order_id)
        assert record is not None
        assert (record.status, record.sent_update_id, record.released_end) == ("SENT", 0, 3)
        assert record.request == {
            "manufacturer": "acme",
            "serialNumber": "robot_0",
            "destination": "n11",
            "destinationActions": [],
        }
        events = await store.order_events(track.order_id)
        assert [e.event for e in events] == ["created", "published"]
        assert events[1].details == {"headerId": 0, "orderUpdateId": 0, "baseEnd": "n3"}
        (counter,) = await store.load_header_counters()
        assert (counter.topic, counter.header_id) == ("order", 0)


async def test_a_batch_is_committed_in_one_write_before_its_messages(tmp_path: Path) -> None:
    """POST /orders/batch answers once every created order is written ahead; until then none
    of its orders is sent, and the store takes them in one write (one transaction)."""
    async with journaled(tmp_path, gate=True) as (service, publisher, store, writer):
        online(service)
        other = AgvId("acme", "robot_1")
        for kind, message in (
            (Topic.CONNECTION, Connection.model_validate({**HEADER, "connection_state": "ONLINE"})),
            (Topic.STATE, make_state(last_node_id="n11")),
        ):
            stamped = message.model_copy(update={"serial_number": "robot_1"})
            service.ingest(build_topic("uagv", 2, other, kind), encode(stamped))
        assert isinstance(store, GatedStore)
        store.open.set()
        await writer.flush()  # the registry's writes, before the count starts
        store.open.clear()
        writes: list[WriteBatch] = []
        original = store.write

        async def counted(batch: WriteBatch) -> None:
            writes.append(batch)
            await original(batch)

        store.write = counted  # type: ignore[method-assign]
        body = {
            "orders": [
                {"manufacturer": "acme", "serialNumber": "robot_0", "destination": "n5"},
                {"manufacturer": "acme", "serialNumber": "robot_1", "destination": "n6"},
                {"manufacturer": "acme", "serialNumber": "robot_1", "destination": "n7"},
            ]
        }
        transport = httpx.ASGITransport(app=create_app(service))
        async with httpx.AsyncClient(transport=transport, base_url="http://m") as client:
            answer = asyncio.create_task(client.post("/orders/batch", json=body))
            await asyncio.sleep(0.2)
            assert not answer.done()
            assert publisher.orders() == []  # held until the store has committed them
            store.open.set()
            response = await answer
        assert [r["status"] for r in response.json()["results"]] == [201, 201, 409]
        sent = [o["orderId"] for o in publisher.orders()]
        assert sent == [r["orderId"] for r in response.json()["results"][:2]]
        assert len(writes) == 1
        assert {record.order_id for record in writes[0].orders} == set(sent)


async def test_a_store_that_does_not_answer_delays_the_order_but_does_not_stop_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(journal_module, "WRITE_AHEAD_TIMEOUT_S", 0.2)
    async with journaled(tmp_path, gate=True) as (service, publisher, store, writer):
        online(service)
        with capture_logs() as logs:
            track = service.create_order(OrderRequest(Target(destination="n5"), AGV))
            await service.committed(track.order_id)
        assert len(publisher.orders()) == 1
        (failed,) = [e for e in logs if e["event"] == "order.write_ahead_failed"]
        assert "did not commit within 0.2 s" in failed["reason"]
        assert isinstance(store, GatedStore)
        store.open.set()  # the database answers again: the queued record is written
        await writer.flush()
        assert await store.get_order(track.order_id) is not None


async def test_restart_resumes_tracking_releasing_and_header_ids(tmp_path: Path) -> None:
    """Run 1 releases an 11-edge route to node 5 while the vehicle passes node 2, then stops.
    Run 2 loads it, the vehicle's first state reconciles it, the base grows again with the next
    orderUpdateId and headerIds increasing past run 1 (R15), and the order finishes with one
    history."""
    async with journaled(tmp_path) as (service, publisher, _, _):
        online(service)
        order_id = service.create_order(OrderRequest(Target(destination="n11"), AGV)).order_id
        await service.committed(order_id)
        drive(service, order_id, passed=0)
        drive(service, order_id, passed=2)  # the window slides: update 1, base to n5
        first_run = publisher.orders()
        assert [o["orderUpdateId"] for o in first_run] == [0, 1]
        assert service.tracks[order_id].released_end == 5

    async with journaled(tmp_path) as (service, publisher, store, writer):
        with capture_logs() as logs:
            (resumed,) = await service.resume_from(store)
        assert resumed.order_id == order_id
        recovered = [e for e in logs if e["event"] == "order.recovered"]
        assert recovered[0]["order_update_id"] == 1
        assert service.availability_of(AGV) == f"it runs order {order_id!r}"
        reconnect(service)
        with capture_logs() as logs:
            drive(service, order_id, passed=3)  # first state after the restart
        (settled,) = [e for e in logs if e["event"] == "order.reconciled"]
        assert settled["outcome"] == "running"
        (update,) = publisher.orders()
        assert update["orderUpdateId"] == 2
        # on after the stored counter with a gap: a crash may have lost the last few counters
        assert update["headerId"] == first_run[-1]["headerId"] + persistence.RESTART_HEADER_GAP + 1
        assert update["nodes"][0]["nodeId"] == "n5"  # stitched at the decision point
        for passed in range(4, 12):
            drive(service, order_id, passed=passed)
        finished = dict.fromkeys(service.tracks[order_id].plan.action_ids(), ActionStatus.FINISHED)
        drive(service, order_id, passed=11, actions=finished)
        assert service.tracks[order_id].status is OrderStatus.FINISHED
        await writer.flush()
        history = await store.order_events(order_id)
        events = [e.event for e in history]
        record = await store.get_order(order_id)
    assert record is not None
    assert record.status == "FINISHED"
    assert events[:2] == ["created", "published"]
    assert {"recovered", "reconciled", "accepted"} <= set(events)
    assert events[-1] == "status_changed"
    assert events.count("node_passed") == 12  # n0 … n11, each once across both runs
    assert events.count("published") == len(first_run) + len(publisher.orders())


async def test_orders_that_left_memory_are_answered_from_the_store(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(persistence, "KEPT_ENDED", 1)
    async with journaled(tmp_path) as (service, _, _, writer):
        online(service)
        ids = []
        for destination, node in (("n2", 2), ("n0", 0), ("n1", 1)):
            order_id = service.create_order(
                OrderRequest(Target(destination=destination), AGV)
            ).order_id
            await service.committed(order_id)
            plan = service.tracks[order_id].plan
            done = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
            drive(service, order_id, passed=plan.last_index, actions=done)
            assert service.tracks[order_id].status is OrderStatus.FINISHED
            assert service.fleet.get(AGV) is not None
            report(service, last_node_id=f"n{node}")
            ids.append(order_id)
        assert ids[0] not in service.tracks  # only the newest ended order stays in memory
        await writer.flush()
        transport = httpx.ASGITransport(app=create_app(service))
        async with httpx.AsyncClient(transport=transport, base_url="http://m") as client:
            one = await client.get(f"/orders/{ids[0]}")
            listed = await client.get("/orders", params={"limit": 10})
            history = await client.get(f"/orders/{ids[0]}/events")
            missing = await client.get("/orders/nope/events")
    assert one.status_code == 200, one.text
    assert (one.json()["status"], one.json()["nodeIds"]) == ("FINISHED", ["n0", "n1", "n2"])
    assert [o["orderId"] for o in listed.json()] == ids[::-1]
    events = history.json()
    assert events[0]["event"] == "created"
    assert events[0]["destination"] == "n2"
    assert {"time", "event"} <= set(events[-1])
    assert events[-1]["status"] == "FINISHED"
    assert missing.status_code == 404


class CountingStore(GatedStore):
    """A store that counts the listings read from it (its writes are not gated)."""

    def __init__(self, store: Store) -> None:
        super().__init__(store)
        self.open.set()
        self.listings = 0

    async def list_orders(self, **filters: Any) -> Any:
        self.listings += 1
        return await self.store.list_orders(**filters)


async def test_a_listing_reads_the_store_only_for_orders_that_memory_lacks(
    tmp_path: Path,
) -> None:
    """GET /orders of a master whose store holds nothing that memory lacks is answered from
    memory (the traffic benchmark lists up to 1000 orders 20 times a second: reading them back
    from the database each time cost the master a third of a core); after a restart the
    earlier run's orders are listed from the store."""
    order_ids = []
    for run in range(2):
        clock = FakeClock(datetime(2026, 1, 1 + run, tzinfo=UTC))
        async with journaled(tmp_path, clock=clock) as (service, _, sql, _writer):
            store = CountingStore(sql)
            assert isinstance(service.journal, Journal)
            service.journal.store = store
            await service.resume_from(store)
            started = store.listings
            online(service)
            order_id = service.create_order(OrderRequest(Target(destination="n2"), AGV)).order_id
            await service.committed(order_id)
            order_ids.append(order_id)
            transport = httpx.ASGITransport(app=create_app(service))
            async with httpx.AsyncClient(transport=transport, base_url="http://m") as client:
                listed = (await client.get("/orders", params={"limit": 1000})).json()
            if run == 0:
                assert store.listings == started  # memory holds every order there is
            else:
                assert store.listings == started + 1
            assert [o["orderId"] for o in listed] == order_ids[::-1]
            plan = service.tracks[order_id].plan
            done = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
            drive(service, order_id, passed=plan.last_index, actions=done)
            report(service, last_node_id="n0")  # back where it started, for the next run


def _line_closed_at(node: int) -> Graph:
    """Line graph n0…n11 (2 m apart) with a BLOCKED zone, ``spill``, round node ``node``."""
    line = line_graph(12)
    x = 2.0 * node
    raw = {
        "mapId": line.map_id,
        "nodes": [n.model_dump(by_alias=True, exclude_none=True) for n in line.nodes.values()],
        "edges": [e.model_dump(by_alias=True, exclude_none=True) for e in line.edges.values()],
        "zones": [zone("spill", "BLOCKED", [[x - 0.5, -1.0], [x + 0.5, -1.0], [x, 1.0]])],
    }
    return build_graph(raw)


async def _resumed(service: MasterService, store: Store) -> None:
    """The one open order of the run before loaded, robot_0 ONLINE again."""
    (_recovered,) = await service.resume_from(store)
    reconnect(service)


@pytest.mark.parametrize("traffic_control", [False, True])
async def test_an_order_whose_way_a_new_zone_closes_is_stopped_and_fails_saying_why(
    tmp_path: Path, traffic_control: bool
) -> None:
    """Run 1 sends robot_0 from n0 to n11 and releases up to n5; before run 2 a BLOCKED zone
    closes node 8, the only way on. The recovered order never releases the closed edge: master
    control cancels it on the vehicle (which stops at its next node) and, although master
    control restarts once more before the vehicle confirms the cancel, the order ends FAILED
    naming the zone, with and without traffic control (which once failed the recovery on the
    edge it no longer knew)."""
    async with journaled(tmp_path) as (service, _, _, _):
        online(service)
        order_id = service.create_order(OrderRequest(Target(destination="n11"), AGV)).order_id
        await service.committed(order_id)
        drive(service, order_id, passed=2)
        assert service.tracks[order_id].released_end == 5

    closed = _line_closed_at(8)
    async with journaled(tmp_path, graph=closed, traffic_control=traffic_control) as (
        service,
        publisher,
        store,
        _,
    ):
        await _resumed(service, store)
        drive(service, order_id, passed=3)
        (cancel,) = cancel_ids(publisher)
        assert all("e7" not in [e["edgeId"] for e in o["edges"]] for o in publisher.orders())
        assert service.tracks[order_id].reason == ""  # still RUNNING: the cancel is under way

    async with journaled(tmp_path, graph=closed, traffic_control=traffic_control) as (
        service,
        _,
        store,
        _,
    ):
        await _resumed(service, store)
        assert service.tracks[order_id].released_end == 5
        stop_after_cancel(service, order_id, cancel, passed=5)
        ended = service.tracks[order_id]
    assert ended.status is OrderStatus.FAILED
    assert "edge 'e7' enters BLOCKED zone 'spill'" in ended.reason
    assert "no other way leads to 'n11'" in ended.reason


async def test_an_order_whose_unreleased_way_a_new_zone_closes_goes_round_it(
    tmp_path: Path,
) -> None:
    """On the demo warehouse, robot_0 is sent from node 7 along aisle A to node 3; before run 2
    a BLOCKED zone closes node 10 on that way, beyond what was released. The recovered order is
    re-routed from the end of its base (kept as it was, R66) round by aisle B, and its next
    update carries the new way."""
    demo = demo_graph()
    async with journaled(tmp_path, graph=demo, release_window_nodes=1) as (service, _, _, _):
        online(service, node="7")
        track = service.create_order(OrderRequest(Target(destination="3"), AGV))
        assert [n.node_id for n in track.plan.nodes] == ["7", "1", "2", "10", "3"]
        order_id = track.order_id
        await service.committed(order_id)
        released = service.tracks[order_id].released_end
        assert released < 2  # the closed edge 2 -> 10 is not released yet

    zoned = demo_graph_with_zones(
        zone("works", "BLOCKED", [[13.0, -1.5], [17.0, -1.5], [17.0, 1.5], [13.0, 1.5]])
    )
    async with journaled(tmp_path, graph=zoned, release_window_nodes=1) as (
        service,
        publisher,
        store,
        _,
    ):
        await _resumed(service, store)
        drive(service, order_id, passed=0)
        track = service.tracks[order_id]
        nodes = [n.node_id for n in track.plan.nodes]
        assert nodes[: released + 1] == ["7", "1", "2", "10", "3"][: released + 1]
        assert "10" not in nodes[released + 1 :]
        assert nodes[-1] == "3"
        assert cancel_ids(publisher) == []
        await service.committed(order_id)  # a new plan is written ahead of its messages
        drive(service, order_id, passed=released)  # at the base's end: the window slides on
        (update,) = publisher.orders()
        assert update["nodes"][0]["nodeId"] == nodes[released]  # stitched at the base's end
        assert "10" not in [n["nodeId"] for n in update["nodes"]]
