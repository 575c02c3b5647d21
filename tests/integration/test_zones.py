"""Zones of the graph file end to end: master control routes a simulated vehicle around a
BLOCKED zone, tells it a SPEED_LIMIT in the order, refuses what the zone closes and lists the
zones (docs/master.md, Zones)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

import pytest

from tests.integration.master_helpers import (
    SIMULATED,
    SIMULATED_BODY,
    api_client,
    running_master,
    simulated_vehicle,
    wait_status,
    wait_until,
)
from vda5050.graph_file import GraphVertex
from vda5050.polygons import inside
from vda_master.testing import demo_graph_with_zones, zone
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.runtime3 import VehicleRuntimeV3

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

AROUND_10 = [[13.0, -1.5], [17.0, -1.5], [17.0, 1.5], [13.0, 1.5]]
ZONE_10 = [GraphVertex(x=x, y=y) for x, y in AROUND_10]
GRAPH = demo_graph_with_zones(
    zone("maintenance", "BLOCKED", AROUND_10),
    zone("slow", "SPEED_LIMIT", [[18.0, 3.0], [22.0, 3.0], [22.0, 5.0]], maximumSpeed=0.4),
)


async def test_a_vehicle_is_routed_around_a_blocked_zone_and_slowed_in_a_limited_one(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """r1 on node 7 is sent to node 3 at the far end of aisle A, whose way along the aisle
    runs through the closed zone around node 10: it goes round by aisle B and comes back by the
    east cross aisle, through the slow zone round node 21, whose edges the order limits to
    0.4 m/s; it never enters the closed zone, and arrives. Node 10 itself is refused with the
    zone's name; GET /zones lists both."""
    async with (
        running_master(embedded_broker, unique_interface_name, graph=GRAPH) as master,
        simulated_vehicle(embedded_broker, unique_interface_name) as vehicle,
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=5)
        refused = await client.post("/orders", json={**SIMULATED_BODY, "destination": "10"})
        assert refused.status_code == 409
        assert refused.json()["detail"] == "node '10' lies in BLOCKED zone 'maintenance'"

        created = await client.post("/orders", json={**SIMULATED_BODY, "destination": "3"})
        assert created.status_code == 201, created.text
        edges = created.json()["order"]["edges"]
        limited = [e for e in edges if e["edgeId"] in GRAPH.limited_edges]
        assert limited
        assert {e["maxSpeed"] for e in limited} == {0.4}
        runtime = vehicle.runtimes[0]
        async with _kept_out(runtime):
            await wait_status(client, created.json()["orderId"], "FINISHED", timeout=30)
        assert runtime.state.last_node_id == "3"

        zones = (await client.get("/zones")).json()
        assert [(z["zoneId"], z["zoneType"]) for z in zones] == [
            ("maintenance", "BLOCKED"),
            ("slow", "SPEED_LIMIT"),
        ]
        assert zones[0]["nodesInside"] == ["10"]


async def test_a_3_0_robot_is_given_the_zones_and_enables_them(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A 3.0 simulated vehicle, whose factsheet lists BLOCKED and SPEED_LIMIT, holds the
    graph's zone set ENABLED soon after it connects (zoneSet, then enableZoneSet), and still
    takes and finishes the master's orders round the closed zone."""
    interface_v3 = f"{unique_interface_name}-v3"
    async with (
        running_master(
            embedded_broker, unique_interface_name, graph=GRAPH, interface_name_v3=interface_v3
        ) as master,
        simulated_vehicle(embedded_broker, interface_v3, vda_version="3.0.0") as vehicle,
        api_client(master) as client,
    ):
        runtime = vehicle.runtimes[0]
        assert isinstance(runtime, VehicleRuntimeV3)
        zone_set_id = master.service.zone_sets["demo"].zone_set_id
        await wait_until(
            lambda: any(h.zone_set.zone_set_id == zone_set_id and h.enabled for h in runtime.zones),
            timeout=10,
        )
        zones = (await client.get("/zones")).json()
        assert {z["zoneSetId"] for z in zones} == {zone_set_id}
        await wait_until(
            lambda: master.service.zone_set_status(SIMULATED, zone_set_id) == "ENABLED", timeout=5
        )
        assert (await client.get("/zones")).json()[0]["robots"] == {"acme/r1": "ENABLED"}
        await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=5)
        created = await client.post("/orders", json={**SIMULATED_BODY, "destination": "3"})
        assert created.status_code == 201, created.text
        await wait_status(client, created.json()["orderId"], "FINISHED", timeout=30)


@pytest.mark.parametrize(
    ("traffic_control", "version"), [(False, "2.0.0"), (True, "2.0.0"), (False, "3.0.0")]
)
async def test_a_zone_added_while_a_vehicle_drives_keeps_it_out(
    embedded_broker: BrokerAddress, unique_interface_name: str, traffic_control: bool, version: str
) -> None:
    """r1 drives from node 7 along aisle A to node 3 when a spill closes the aisle round node
    10 (POST /zones). Without traffic control, released one node ahead, it is sent round by
    aisle B and arrives; with it, the aisle (one lane) is released whole, so master control
    stops the order and it ends FAILED naming the zone. Either way the vehicle never enters
    the zone; once the zone is lifted (DELETE), the aisle is driven again. A 3.0 robot is also
    given the new zone set while it drives, and still arrives by the new way."""
    settings: dict[str, object] = {"traffic_control": traffic_control, "release_window_nodes": 1}
    interface = unique_interface_name
    if version == "3.0.0":
        interface = settings["interface_name_v3"] = f"{unique_interface_name}-v3"
    async with (
        running_master(embedded_broker, unique_interface_name, **settings) as master,
        simulated_vehicle(embedded_broker, interface, vda_version=version) as vehicle,
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=5)
        created = await client.post("/orders", json={**SIMULATED_BODY, "destination": "3"})
        assert created.status_code == 201, created.text
        order_id = created.json()["orderId"]
        added = await client.post("/zones", json=zone("spill", "BLOCKED", AROUND_10))
        assert added.status_code == 201, added.text
        runtime = vehicle.runtimes[0]
        async with _kept_out(runtime):
            await wait_status(
                client, order_id, "FAILED" if traffic_control else "FINISHED", timeout=30
            )
            document = (await client.get(f"/orders/{order_id}")).json()
            if traffic_control:
                assert "enters BLOCKED zone 'spill'" in document["reason"]
            else:
                assert runtime.state.last_node_id == "3"
                assert "10" not in document["nodeIds"]

        assert (await client.delete("/zones/spill")).status_code == 204
        assert (await client.get("/zones")).json() == []
        await wait_until(lambda: master.service.availability_of(SIMULATED) is None, timeout=5)
        start = runtime.state.last_node_id
        back = await client.post("/orders", json={**SIMULATED_BODY, "destination": "7"})
        assert back.status_code == 201, back.text
        if start == "3":  # the way back along aisle A is open again
            assert "10" in [n["nodeId"] for n in back.json()["order"]["nodes"]]
        await wait_status(client, back.json()["orderId"], "FINISHED", timeout=30)


@asynccontextmanager
async def _kept_out(runtime: VehicleRuntime) -> AsyncIterator[None]:
    """Samples the simulated vehicle's pose every 10 ms while the block runs; fails if it was
    ever inside the zone round node 10."""
    entered = False

    async def watch() -> None:
        nonlocal entered
        while True:
            pose = runtime.state.pose
            entered = entered or inside(ZONE_10, (pose.x, pose.y))
            await asyncio.sleep(0.01)

    watcher = asyncio.create_task(watch())
    try:
        yield
    finally:
        watcher.cancel()
    assert not entered
