"""Master control and a VDA 5050 3.0 vehicle in one event loop (issue 13 items 2-3).

The master addresses the vehicle under ``<interface_v3>/v3`` in 3.0, builds 3.0 orders from the
same graph and routes (no edge endpoints, stitched updates under a release window), reads its
3.0 states, and the order is driven to FINISHED. A 3.0 cancelOrder reaches it too."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING, Any

import aiomqtt
import httpx
import pytest

from tests.integration.master_helpers import (
    api_client,
    running_master,
    simulated_vehicle,
    wait_status,
    wait_until,
)
from vda5050.topics import AgvId

if TYPE_CHECKING:
    from contextlib import AbstractAsyncContextManager

    from vda5050.broker import BrokerAddress
    from vda_master.runtime import MasterProcess
    from vda_vehicle.service import VehicleService

pytestmark = pytest.mark.integration

AGV = AgvId("acme", "r3")
BODY = {"manufacturer": "acme", "serialNumber": "r3"}


def vehicle_v3(
    address: BrokerAddress, interface: str
) -> AbstractAsyncContextManager[VehicleService]:
    """The simulated vehicle ``acme/r3`` speaking 3.0 under ``<interface>/v3``."""
    return simulated_vehicle(
        address,
        interface,
        vda_version="3.0.0",
        serial_number="r3",
        visualization_interval_s=0.5,
    )


@asynccontextmanager
async def orders_seen(address: BrokerAddress, interface: str) -> AsyncIterator[list[Any]]:
    """Every order message published under ``<interface>/v3``, decoded, while the block runs."""
    seen: list[Any] = []

    async def collect() -> None:
        async with aiomqtt.Client(address.host, address.port) as client:
            await client.subscribe(f"{interface}/v3/+/+/order", qos=1)
            async for message in client.messages:
                seen.append(json.loads(message.payload))  # noqa: PERF401 - collected live

    task = asyncio.create_task(collect(), name="test.orders_seen")
    await asyncio.sleep(0.3)
    try:
        yield seen
    finally:
        task.cancel()


async def test_master_drives_a_3_0_vehicle_with_stitched_3_0_orders(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """T01, T18, T39, T40: orders go to ``<v3 interface>/v3/acme/r3/order`` in 3.0 shape (edges
    without start/end node ids); with a release window of 1 node the order is extended by
    updates that start at the decision point resent unchanged; the vehicle's 3.0 states drive
    the order to FINISHED and the fleet view shows it available again."""
    interface_v3 = f"{unique_interface_name}-v3"
    async with (
        orders_seen(embedded_broker, interface_v3) as orders,
        running_master(
            embedded_broker,
            unique_interface_name,
            interface_name_v3=interface_v3,
            release_window_nodes=1,
            traffic_control=False,  # else the two-way demo lanes are released whole
        ) as master,
        vehicle_v3(embedded_broker, interface_v3),
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        view = (await client.get("/vehicles/acme/r3")).json()
        assert view["version"] == "3.0.0"
        created = await client.post("/orders", json={**BODY, "destination": "18"})
        assert created.status_code == 201, created.text
        order_id = created.json()["orderId"]
        await wait_status(client, order_id, "FINISHED", timeout=30)
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        assert (await client.get("/vehicles/acme/r3")).json()["lastNodeId"] == "18"
    mine = [o for o in orders if o["orderId"] == order_id]
    assert {o["version"] for o in mine} == {"3.0.0"}
    assert all("startNodeId" not in e for o in mine for e in o["edges"])
    by_update = {o["orderUpdateId"]: o for o in mine}
    assert len(by_update) > 1, "a 1-node release window extends the base by updates"
    assert sorted(by_update) == list(range(len(by_update)))
    for update_id in sorted(by_update)[1:]:
        update, before = by_update[update_id], by_update[update_id - 1]
        decision = [n for n in before["nodes"] if n["released"]][-1]
        assert update["nodes"][0] == decision  # T40: the stitching node resent unchanged


async def test_master_cancels_a_3_0_order(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """T44, T45: DELETE /orders/{id} sends a 3.0 cancelOrder (blockingType NONE); the vehicle
    reports it in instantActionStates, the order ends CANCELLED, the vehicle is available."""
    interface_v3 = f"{unique_interface_name}-v3"
    async with (
        running_master(
            embedded_broker, unique_interface_name, interface_name_v3=interface_v3
        ) as master,
        vehicle_v3(embedded_broker, interface_v3) as vehicle,
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        created = (await client.post("/orders", json={**BODY, "destination": "3"})).json()
        runtime = vehicle.runtimes[0]
        await wait_until(lambda: runtime.state.driving, timeout=5)
        assert (await client.delete(f"/orders/{created['orderId']}")).status_code == 202
        await wait_status(client, created["orderId"], "CANCELLED", timeout=10)
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=10)
        cancels = [r for r in runtime.state.actions if r.action_type == "cancelOrder"]
        assert [r.status.value for r in cancels] == ["FINISHED"]


@asynccontextmanager
async def _master_and_idle_vehicle(
    address: BrokerAddress, interface: str
) -> AsyncIterator[tuple[MasterProcess, VehicleService, httpx.AsyncClient]]:
    """A master and the 3.0 vehicle r3, once master control may give it an order."""
    interface_v3 = f"{interface}-v3"
    async with (
        running_master(address, interface, interface_name_v3=interface_v3) as master,
        vehicle_v3(address, interface_v3) as vehicle,
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        yield master, vehicle, client


async def _instant(client: httpx.AsyncClient, action_type: str) -> None:
    """``action_type`` to r3 through the master's instant-action API (202)."""
    path = "/vehicles/acme/r3/instantActions"
    sent = await client.post(path, json={"actions": [{"actionType": action_type}]})
    assert sent.status_code == 202, sent.text


async def test_hibernation_through_the_master(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """T06, T09: startHibernation sent through the API makes the 3.0 vehicle HIBERNATING: the
    master no longer calls it available (and expects no heartbeat); stopHibernation brings it
    back ONLINE and available."""
    async with _master_and_idle_vehicle(embedded_broker, unique_interface_name) as (
        master,
        vehicle,
        client,
    ):
        await _instant(client, "startHibernation")
        runtime = vehicle.runtimes[0]
        await wait_until(lambda: getattr(runtime, "hibernating", False), timeout=5)
        await wait_until(lambda: master.service.availability_of(AGV) is not None, timeout=5)
        view = (await client.get("/vehicles/acme/r3")).json()
        assert view["available"] is False
        await _instant(client, "stopHibernation")
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        assert not getattr(runtime, "hibernating", True)


async def test_shutdown_through_the_master(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """T07: shutdown sent through the API to the idle 3.0 vehicle: it reports the action
    FINISHED, publishes OFFLINE and disconnects; master control shows it OFFLINE and no longer
    available, and the vehicle process goes on serving until it is stopped."""
    async with _master_and_idle_vehicle(embedded_broker, unique_interface_name) as (
        master,
        vehicle,
        client,
    ):
        await _instant(client, "shutdown")
        await wait_until(lambda: _connection(master) == "OFFLINE", timeout=5)
        view = (await client.get("/vehicles/acme/r3")).json()
        assert (view["connectionState"], view["available"]) == ("OFFLINE", False)
        # the OFFLINE may reach master control before the session has marked itself closed
        await wait_until(lambda: not vehicle.vehicles[0].session.connected, timeout=5)


def _connection(master: MasterProcess) -> str | None:
    seen = master.service.fleet.get(AGV)
    return None if seen is None or seen.connection is None else seen.connection.value
