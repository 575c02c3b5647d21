"""Master control with scripted vehicles over the embedded broker: dispatch, confirmation,
resend, rejection, cancel, base extension, vehicle selection (§6.6; R45, R56–R58, R66, R84)."""

from __future__ import annotations

import asyncio
import itertools
from typing import TYPE_CHECKING

import pytest

from tests.integration.master_helpers import (
    api_client,
    running_master,
    serving,
    wait_reported,
    wait_status,
)
from tests.integration.master_vehicle import ScriptedVehicle, running_vehicle
from vda5050.models import OperatingMode
from vda5050.validation import check_order
from vda_master.testing import demo_graph

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

AGV = {"manufacturer": "acme", "serialNumber": "robot_1"}


async def test_order_is_dispatched_confirmed_and_finished(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """POST /orders sends the reference route; the vehicle's states drive it to FINISHED."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph())
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        _,
        client,
    ):
        response = await client.post("/orders", json={**AGV, "route": ["17", "12", "11"]})
        assert response.status_code == 201, response.text
        body = response.json()
        order = body["order"]
        assert [n["nodeId"] for n in order["nodes"]] == ["7", "1", "2", "10"]
        assert [n["sequenceId"] for n in order["nodes"]] == [0, 2, 4, 6]
        assert [e["sequenceId"] for e in order["edges"]] == [1, 3, 5]
        await wait_status(client, body["orderId"], "FINISHED")
        assert vehicle.last_node == "10"


async def test_lost_order_is_resent_unchanged(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """An order the vehicle never saw is sent again with the same ids and a new headerId."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph(), drop_orders=1)
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        _,
        client,
    ):
        response = await client.post("/orders", json={**AGV, "destination": "10"})
        order_id = response.json()["orderId"]
        await wait_status(client, order_id, "FINISHED")
    first, second = vehicle.received[0], vehicle.received[1]
    assert (first.order_id, first.order_update_id) == (second.order_id, second.order_update_id)
    assert first.nodes == second.nodes
    assert second.header_id == first.header_id + 1


async def test_rejected_order_is_reported(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """An error referencing the order in the vehicle's state makes it REJECTED."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph(), reject=True)
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        _,
        client,
    ):
        response = await client.post("/orders", json={**AGV, "destination": "10"})
        order_id = response.json()["orderId"]
        await wait_status(client, order_id, "REJECTED")
        info = (await client.get(f"/orders/{order_id}")).json()
        assert "orderError" in info["reason"]


async def test_delete_cancels_a_running_order(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """DELETE /orders/{id} answers 202, sends cancelOrder and ends CANCELLED (§6.6.3, R66)."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph(), step_s=0.3)
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        _,
        client,
    ):
        response = await client.post("/orders", json={**AGV, "destination": "18"})
        order_id = response.json()["orderId"]
        await wait_status(client, order_id, "RUNNING")
        cancelled = await client.delete(f"/orders/{order_id}")
        assert cancelled.status_code == 202, cancelled.text
        await wait_status(client, order_id, "CANCELLED")
        assert [a.action_type for a in vehicle.instant[0].actions] == ["cancelOrder"]
        again = await client.delete(f"/orders/{order_id}")
        assert again.status_code == 409
        assert "already CANCELLED" in again.json()["detail"]


async def test_an_order_cleared_by_manual_mode_fails_and_the_vehicle_is_free_again(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """An operator switches a driving vehicle to MANUAL: it clears its order where it stands
    (§6.10.6 Table 1) and keeps its orderId. The order ends FAILED, saying why, instead of
    FINISHED; the vehicle takes no order while in MANUAL and takes the next one once back in
    AUTOMATIC."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph(), step_s=0.3)
    async with serving(vehicle, embedded_broker, unique_interface_name) as (_, client):
        response = await client.post("/orders", json={**AGV, "destination": "18"})
        order_id = response.json()["orderId"]
        await wait_status(client, order_id, "RUNNING")
        vehicle.switch_mode(OperatingMode.MANUAL)
        await wait_status(client, order_id, "FAILED")
        reason = (await client.get(f"/orders/{order_id}")).json()["reason"]
        assert reason.startswith("the vehicle cleared the order in operatingMode MANUAL at node")
        assert reason.endswith("before reaching 18")
        refused = await client.post("/orders", json={**AGV, "destination": "10"})
        assert refused.status_code == 409
        assert "operatingMode is MANUAL" in refused.json()["detail"]
        vehicle.switch_mode(OperatingMode.AUTOMATIC)
        async with asyncio.timeout(5):
            while (
                again := await client.post("/orders", json={**AGV, "destination": "10"})
            ).status_code == 409:
                await asyncio.sleep(0.05)
        assert again.status_code == 201, again.text
        await wait_status(client, again.json()["orderId"], "FINISHED")
        assert vehicle.last_node == "10"


async def test_long_route_is_released_step_by_step(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """With a one-node window, stitched updates extend the base to the destination (R56–R58).
    (Traffic control off: on the demo graph every lane is two-way, so traffic control would
    release each route whole, up to the next node where a vehicle may wait.)"""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph())
    async with serving(
        vehicle,
        embedded_broker,
        unique_interface_name,
        release_window_nodes=1,
        traffic_control=False,
    ) as (
        _,
        client,
    ):
        response = await client.post("/orders", json={**AGV, "destination": "18"})
        order_id = response.json()["orderId"]
        await wait_status(client, order_id, "FINISHED", timeout=10)
    assert vehicle.last_node == "18"
    received = [o for o in vehicle.received if o.order_id == order_id]
    # A copy may be resent when a confirmation is slow (confirm_timeout_s is short here); a
    # resend is the same message with a new header.
    updates = [next(group) for _, group in itertools.groupby(received, lambda o: o.order_update_id)]
    for copy in received:
        first = next(u for u in updates if u.order_update_id == copy.order_update_id)
        assert (copy.nodes, copy.edges) == (first.nodes, first.edges)
    assert [o.order_update_id for o in updates] == list(range(len(updates)))
    assert len(updates) >= 5
    for before, after in itertools.pairwise(updates):
        decision = max((n for n in before.nodes if n.released), key=lambda n: n.sequence_id)
        assert after.nodes[0] == decision
        assert check_order(after, first_sequence_id=decision.sequence_id) == []


async def test_master_picks_the_closest_available_vehicle(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """With no vehicle named, the available vehicle with the shortest route gets the order."""
    graph = demo_graph()
    far = ScriptedVehicle(embedded_broker, unique_interface_name, graph, serial="far")
    near = ScriptedVehicle(
        embedded_broker, unique_interface_name, graph, serial="near", start_node="3"
    )
    async with (
        running_master(embedded_broker, unique_interface_name) as master,
        running_vehicle(far),
        running_vehicle(near),
        api_client(master) as client,
    ):
        await wait_reported(master, far.agv, near.agv)
        response = await client.post("/orders", json={"destination": "12"})
        assert response.status_code == 201, response.text
        assert response.json()["serialNumber"] == "near"
        await wait_status(client, response.json()["orderId"], "FINISHED")
