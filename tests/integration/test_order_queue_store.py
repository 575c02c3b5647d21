"""Queued orders (docs/master.md, *Queued orders*) through the HTTP API on a real store: the 202
comes once the order is committed, the order is listed, read, cancelled and batched as QUEUED,
and it survives a restart of master control to be sent when its vehicle comes free."""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
import pytest

from tests.integration.service_on_store import GatedStore, drive, journaled, online
from vda5050.models import ActionStatus
from vda_master.api import create_app
from vda_master.api_models import OrderInfo, OrderQueued
from vda_master.dispatcher import OrderStatus
from vda_master.queue_rules import NEVER_SENT
from vda_master.service import MasterService

pytestmark = pytest.mark.integration

FOR_ROBOT_0 = {"manufacturer": "acme", "serialNumber": "robot_0"}


def _client(service: MasterService) -> httpx.AsyncClient:
    transport = httpx.ASGITransport(app=create_app(service))
    return httpx.AsyncClient(transport=transport, base_url="http://m")


def _finish(service: MasterService, order_id: str) -> None:
    """The vehicle drives the order node by node (the base grows as it goes) to its end."""
    plan = service.tracks[order_id].plan
    for passed in range(plan.last_index):
        drive(service, order_id, passed=passed)
    done = dict.fromkeys(plan.action_ids(), ActionStatus.FINISHED)
    drive(service, order_id, passed=plan.last_index, actions=done)


async def test_a_queued_order_is_answered_202_once_committed_and_read_listed_and_cancelled(
    tmp_path: Path,
) -> None:
    async with journaled(tmp_path, gate=True) as (service, publisher, store, writer):
        online(service)
        assert isinstance(store, GatedStore)
        store.open.set()
        async with _client(service) as client:
            running = await client.post("/orders", json={**FOR_ROBOT_0, "destination": "n5"})
            assert running.status_code == 201, running.text
            refused = await client.post("/orders", json={"destination": "n7"})
            assert refused.status_code == 409  # without queue: as ever
            never = {"destination": "n7", "queue": True, "queueTimeoutS": 0}
            wrong = await client.post("/orders", json=never)
            assert wrong.status_code == 422, wrong.text
            assert "queueTimeoutS" in wrong.text
            store.open.clear()
            asked = asyncio.create_task(
                client.post("/orders", json={"destination": "n7", "queue": True, "priority": 3})
            )
            await asyncio.sleep(0.2)
            assert not asked.done()  # held until the store has it
            store.open.set()
            queued = await asked
            assert queued.status_code == 202, queued.text
            body = OrderQueued.model_validate(queued.json())
            assert (body.status, body.priority, body.queue_position) == (OrderStatus.QUEUED, 3, 1)
            assert body.manufacturer is None
            assert "it runs order" in body.reason
            record = await store.get_order(body.order_id)
            assert record is not None
            assert record.status == "QUEUED"

            one = await client.get(f"/orders/{body.order_id}")
            listed = await client.get("/orders", params={"status": "QUEUED"})
            health = await client.get("/health")
            view = OrderInfo.model_validate(one.json())
            assert (view.status, view.queue_position, view.node_ids) == (OrderStatus.QUEUED, 1, [])
            assert [o["orderId"] for o in listed.json()] == [body.order_id]
            assert health.json()["queuedOrders"] == 1

            batch = await client.post(
                "/orders/batch",
                json={"orders": [{"destination": "n8", "queue": True}, {"destination": "n9"}]},
            )
            results = batch.json()["results"]
            assert [r["status"] for r in results] == [202, 409]
            assert results[0]["queuePosition"] == 2

            cancelled = await client.delete(f"/orders/{body.order_id}")
            assert cancelled.status_code == 202
            assert cancelled.json()["status"] == "CANCELLED"
            assert cancelled.json()["reason"] == NEVER_SENT + "cancelled while queued"
            again = await client.delete(f"/orders/{body.order_id}")
            assert again.status_code == 409
            await writer.flush()
            history = await client.get(f"/orders/{body.order_id}/events")
        assert [e["event"] for e in history.json()] == ["queued", "status_changed"]
        assert [o["orderId"] for o in publisher.orders()] == [running.json()["orderId"]]


async def test_queued_orders_wait_again_after_a_restart_and_go_when_the_vehicle_is_free(
    tmp_path: Path,
) -> None:
    async with journaled(tmp_path) as (service, _, _, _):
        online(service)
        async with _client(service) as client:
            running = await client.post("/orders", json={**FOR_ROBOT_0, "destination": "n5"})
            low = await client.post("/orders", json={"destination": "n3", "queue": True})
            high = await client.post(
                "/orders", json={**FOR_ROBOT_0, "destination": "n9", "queue": True, "priority": 1}
            )
        assert [r.status_code for r in (running, low, high)] == [201, 202, 202]
        running_id = running.json()["orderId"]

    async with journaled(tmp_path) as (service, publisher, store, writer):
        (resumed,) = await service.resume_from(store)
        assert resumed.order_id == running_id
        assert [service.position(o.json()["orderId"]) for o in (low, high)] == [2, 1]
        online(service)
        _finish(service, running_id)  # settled by the first state, then it ends: the
        # queue's first goes out
        await service.committed(high.json()["orderId"])  # written ahead, then sent
        first = publisher.orders()[-1]
        assert first["orderId"] == high.json()["orderId"]
        assert first["nodes"][-1]["nodeId"] == "n9"
        _finish(service, first["orderId"])
        await service.committed(low.json()["orderId"])
        second = publisher.orders()[-1]
        assert second["orderId"] == low.json()["orderId"]
        await writer.flush()
        history = await store.order_events(second["orderId"])
        record = await store.get_order(second["orderId"])
    assert record is not None
    assert (record.manufacturer, record.status) == ("acme", "SENT")
    assert [e.event for e in history][:3] == ["queued", "created", "published"]


async def test_a_queued_order_s_priority_changes_its_place_and_survives_a_restart(
    tmp_path: Path,
) -> None:
    """``PATCH /orders/{id}`` moves a waiting order in the queue, is written to its history and
    its record (so the order keeps its place after a restart), and is refused for an order a
    vehicle took (409), an unknown one (404) and a body with anything but a priority (422)."""
    async with journaled(tmp_path) as (service, _, _, writer):
        online(service)
        async with _client(service) as client:
            running = await client.post("/orders", json={**FOR_ROBOT_0, "destination": "n5"})
            first = await client.post("/orders", json={"destination": "n3", "queue": True})
            second = await client.post("/orders", json={"destination": "n9", "queue": True})
            first_id, second_id = first.json()["orderId"], second.json()["orderId"]
            assert [service.position(i) for i in (first_id, second_id)] == [1, 2]

            raised = await client.patch(f"/orders/{second_id}", json={"priority": 5})
            assert raised.status_code == 200, raised.text
            view = OrderInfo.model_validate(raised.json())
            assert (view.status, view.priority, view.queue_position) == (OrderStatus.QUEUED, 5, 1)
            assert service.position(first_id) == 2

            sent = await client.patch(f"/orders/{running.json()['orderId']}", json={"priority": 1})
            assert sent.status_code == 409
            assert "only a queued order" in sent.json()["detail"]
            unknown = await client.patch("/orders/nope", json={"priority": 1})
            assert unknown.status_code == 404
            extra = await client.patch(f"/orders/{first_id}", json={"destination": "n1"})
            assert extra.status_code == 422
        await writer.flush()

    async with journaled(tmp_path) as (service, _, store, _):
        await service.resume_from(store)
        assert [service.position(i) for i in (first_id, second_id)] == [2, 1]
        history = await store.order_events(second_id)
    assert [e.event for e in history] == ["queued", "reprioritized"]
    assert history[-1].details == {"priority": 5, "previous": 0}
