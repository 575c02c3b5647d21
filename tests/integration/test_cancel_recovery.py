"""No dead end after a cancel (issue 8 item 3): master control and the simulated vehicle in one
event loop. Whether the vehicle finishes its edge (line-guided, R63) or stops between nodes, the
next order is accepted and finishes without a manual step, and the fleet view never calls the
vehicle available while its next order would be rejected."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pytest

from tests.integration.master_helpers import (
    SIMULATED,
    SIMULATED_BODY,
    master_with_simulated_vehicle,
    wait_status,
    wait_until,
)

if TYPE_CHECKING:
    import httpx

    from vda5050.broker import BrokerAddress
    from vda_master.runtime import MasterProcess
    from vda_vehicle.service import VehicleService

pytestmark = pytest.mark.integration

AGV = SIMULATED
BODY = SIMULATED_BODY


async def _vehicle_view(client: httpx.AsyncClient) -> dict[str, Any]:
    response = await client.get("/vehicles/acme/r1")
    view: dict[str, Any] = response.json()
    return view


async def _cancel_midway_then_drive_again(
    master: MasterProcess, client: httpx.AsyncClient, vehicle: VehicleService
) -> dict[str, Any]:
    await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
    first = (await client.post("/orders", json={**BODY, "destination": "3"})).json()
    runtime = vehicle.runtimes[0]
    # Cancel while the vehicle is between nodes 7 and 1 (x in (0.5, 4.5)).
    await wait_until(lambda: 0.5 < runtime.state.pose.x < 4.5, timeout=5)
    assert (await client.delete(f"/orders/{first['orderId']}")).status_code == 202
    await wait_status(client, first["orderId"], "CANCELLED", timeout=10)
    # Never "available" while the next order would be rejected; available once it would not.
    await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=10)
    view = await _vehicle_view(client)
    assert view["available"] is True, view
    follow_up = await client.post("/orders", json={**BODY, "destination": "10"})
    assert follow_up.status_code == 201, follow_up.text
    order: dict[str, Any] = follow_up.json()
    await wait_status(client, order["orderId"], "FINISHED", timeout=15)
    assert runtime.state.last_node_id == "10"
    return order


async def test_line_guided_vehicle_finishes_its_edge_and_takes_the_next_order(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """R63: the cancelled vehicle drives on to node 1 and stands there; the next order starts at
    node 1 with the normal deviation and finishes."""
    async with master_with_simulated_vehicle(embedded_broker, unique_interface_name) as (
        master,
        vehicle,
        client,
    ):
        order = await _cancel_midway_then_drive_again(master, client, vehicle)
    first_node = order["order"]["nodes"][0]
    assert first_node["nodeId"] == "1"
    assert "allowedDeviationXY" not in first_node["nodePosition"]


async def test_vehicle_that_stops_between_nodes_restarts_where_it_stands(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """§6.6.3.1 method 1: the vehicle stopped on edge 7→1; the next order starts with a
    temporary node where it stands, continues along that edge to node 1, and finishes."""
    async with master_with_simulated_vehicle(
        embedded_broker, unique_interface_name, stop_between_nodes=True
    ) as (master, vehicle, client):
        order = await _cancel_midway_then_drive_again(master, client, vehicle)
    nodes = order["order"]["nodes"]
    assert [n["nodeId"] for n in nodes[:2]] == ["7~here", "1"]
    assert 0.5 < nodes[0]["nodePosition"]["x"] < 4.5
