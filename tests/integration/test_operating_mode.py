"""The robot's operating mode and e-stop, end to end: the simulated vehicle's stack reports them
(``VehicleRuntime.on_stack_status``), master control reacts (§6.10.6 Table 1, R104, R105)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING, Any

import httpx
import pytest

from tests.integration.master_helpers import (
    SIMULATED,
    SIMULATED_BODY,
    api_client,
    master_with_simulated_vehicle,
    running_master,
    simulated_vehicle,
    wait_status,
    wait_until,
)
from vda5050.models import EStop
from vda5050.topics import AgvId
from vda_vehicle.model import Pose, RobotMode
from vda_vehicle.vehicle_status import StackStatus

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress
    from vda_master.runtime import MasterProcess
    from vda_vehicle.runtime import VehicleRuntime

pytestmark = pytest.mark.integration

AGV, BODY = SIMULATED, SIMULATED_BODY


async def test_manual_mid_order_fails_the_order_and_automatic_makes_the_vehicle_usable(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """An operator switches the driving vehicle to MANUAL: it stops and clears its order where
    it stands, and master control ends the order FAILED (not FINISHED) and gives the vehicle no
    order while it is in MANUAL. Back in AUTOMATIC, the next order starts where it stands and
    finishes."""
    async with master_with_simulated_vehicle(
        embedded_broker, unique_interface_name, stop_between_nodes=True
    ) as (master, vehicle, client):
        first = (await client.post("/orders", json={**BODY, "destination": "3"})).json()
        runtime = vehicle.runtimes[0]
        await wait_until(lambda: 0.5 < runtime.state.pose.x < 4.5, timeout=5)
        runtime.on_stack_status(StackStatus(RobotMode.MANUAL))
        await wait_status(client, first["orderId"], "FAILED", timeout=5)
        reason = (await client.get(f"/orders/{first['orderId']}")).json()["reason"]
        assert reason.startswith("the vehicle cleared the order in operatingMode MANUAL at node 7")
        stopped_at = runtime.state.pose
        await asyncio.sleep(0.3)
        assert runtime.state.pose == stopped_at
        refused = await client.post("/orders", json={**BODY, "destination": "10"})
        assert refused.status_code == 409, refused.text
        assert "operatingMode is MANUAL" in refused.json()["detail"]

        runtime.on_stack_status(StackStatus(RobotMode.AUTOMATIC))
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        again = await client.post("/orders", json={**BODY, "destination": "10"})
        assert again.status_code == 201, again.text
        await wait_status(client, again.json()["orderId"], "FINISHED", timeout=15)
        assert runtime.state.last_node_id == "10"


async def test_an_e_stop_holds_the_vehicle_and_its_order_finishes_after_the_release(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """R104: an active e-stop stops the vehicle and shows in its state; the order is kept (an
    e-stop is no reason to clear it) and finishes once the stop is released."""
    async with master_with_simulated_vehicle(embedded_broker, unique_interface_name) as (
        master,
        vehicle,
        client,
    ):
        order = (await client.post("/orders", json={**BODY, "destination": "3"})).json()
        runtime = vehicle.runtimes[0]
        await wait_until(lambda: 0.5 < runtime.state.pose.x < 4.5, timeout=5)
        runtime.on_stack_status(StackStatus(e_stop=EStop.REMOTE))
        await asyncio.sleep(0.2)
        stopped_at = runtime.state.pose
        await asyncio.sleep(0.3)
        assert runtime.state.pose == stopped_at
        assert not runtime.state.driving
        seen = master.service.fleet.get(AGV)
        assert seen is not None
        assert seen.state is not None
        assert seen.state.safety_state.e_stop is EStop.REMOTE
        assert (await client.get(f"/orders/{order['orderId']}")).json()["status"] == "RUNNING"

        runtime.on_stack_status(StackStatus())
        await wait_status(client, order["orderId"], "FINISHED", timeout=15)
        assert runtime.state.last_node_id == "3"


async def test_an_operator_switch_over_the_control_api_reaches_master_control(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """``control_port``: an HTTP PATCH puts the simulated vehicle into MANUAL as an operator
    would; master control ends its order FAILED and sees it unavailable; AUTOMATIC over the
    same API makes it available again."""
    async with master_with_simulated_vehicle(
        embedded_broker, unique_interface_name, stop_between_nodes=True, control_port=0
    ) as (master, vehicle, client):
        control = vehicle.control
        assert control is not None
        await wait_until(lambda: control.port is not None, timeout=5)
        order = (await client.post("/orders", json={**BODY, "destination": "3"})).json()
        runtime = vehicle.runtimes[0]
        await wait_until(lambda: 0.5 < runtime.state.pose.x < 4.5, timeout=5)
        url = f"http://127.0.0.1:{control.port}/vehicles/r1/status"
        async with httpx.AsyncClient() as operator:
            manual = await operator.patch(url, json={"operatingMode": "MANUAL"})
            assert manual.json()["operatingMode"] == "MANUAL"
            await wait_status(client, order["orderId"], "FAILED", timeout=5)
            await wait_until(lambda: master.service.availability_of(AGV) is not None, timeout=5)
            await operator.patch(url, json={"operatingMode": "AUTOMATIC"})
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)


async def test_no_vehicle_is_released_next_to_one_left_between_nodes_in_manual(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Issue 9 §2 with a vehicle master control no longer drives: r1, bound from node 7 to
    node 20, is switched to MANUAL on the edge from node 1 (5, 0) to node 2 (10, 0), under
    the safety distance short of node 2, and its order ends there. Its lastNodeId is still
    node 1, but traffic control makes it hold what it covers where it stands, node 2 among it.
    So r2, sent from node 3 to node 20 through node 2, waits for r1 instead of being released
    onto node 2 next to it."""
    async with (
        master_with_simulated_vehicle(
            embedded_broker, unique_interface_name, stop_between_nodes=True
        ) as (master, first, client),
        simulated_vehicle(
            embedded_broker, unique_interface_name, serial_number="r2", start_node="3"
        ) as second,
    ):
        other = AgvId("acme", "r2")
        await wait_until(lambda: master.service.availability_of(other) is None, timeout=5)
        order = (await client.post("/orders", json={**BODY, "destination": "20"})).json()
        runtime = first.runtimes[0]
        await wait_until(lambda: 8.5 < runtime.state.pose.x < 9.5, timeout=5)
        runtime.on_stack_status(StackStatus(RobotMode.MANUAL))
        await wait_status(client, order["orderId"], "FAILED", timeout=5)
        assert runtime.state.last_node_id == "1"
        stands_at = runtime.state.pose.x

        crossing = await client.post(
            "/orders", json={"manufacturer": "acme", "serialNumber": "r2", "destination": "20"}
        )
        assert crossing.status_code == 201, crossing.text
        traffic: dict[str, Any] = {}
        async with asyncio.timeout(10):
            while not any(
                v["serialNumber"] == "r2" and v["waitingFor"] == ["acme/r1"]
                for v in traffic.get("vehicles", [])
            ):
                await asyncio.sleep(0.05)
                traffic = (await client.get("/traffic")).json()
        holder = next(v for v in traffic["vehicles"] if v["serialNumber"] == "r1")
        assert {"node:2", "edge:12", "edge:13"} <= set(holder["holds"])
        await asyncio.sleep(0.5)
        assert second.runtimes[0].state.pose.x >= stands_at + 1.69  # never within the distance


@asynccontextmanager
async def _intervened_mid_order(
    address: BrokerAddress, interface: str
) -> AsyncIterator[tuple[VehicleRuntime, httpx.AsyncClient, str]]:
    """A master and a 3.0 simulated r1 sent from node 7 to node 3, taken over by an operator
    (INTERVENED) between nodes 7 and 1 once master control has seen it: the runtime, an API
    client and the orderId."""
    interface_v3 = f"{interface}-v3"
    async with (
        running_master(address, interface, interface_name_v3=interface_v3) as master,
        simulated_vehicle(address, interface_v3, vda_version="3.0.0") as vehicle,
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        order = (await client.post("/orders", json={**BODY, "destination": "3"})).json()
        runtime = vehicle.runtimes[0]
        await wait_until(lambda: 0.5 < runtime.state.pose.x < 4.5, timeout=5)
        runtime.on_stack_status(StackStatus(RobotMode.INTERVENED))
        await wait_until(lambda: _intervened(master), timeout=5)
        yield runtime, client, order["orderId"]


def _intervened(master: MasterProcess) -> bool:
    """Master control sees r1 INTERVENED, its operatingMode read as MANUAL."""
    seen = master.service.fleet.get(AGV)
    if seen is None or seen.state is None or not seen.intervened:
        return False
    return seen.state.operating_mode.value == "MANUAL"


async def test_a_3_0_robot_intervened_keeps_its_order_and_finishes_it_after(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """3.0 §6.6.6 (T63): an operator takes a 3.0 robot over (INTERVENED) mid-order; it stops
    and keeps its order, which master control keeps RUNNING (no clearing, no failure, nothing
    sent meanwhile). Back in AUTOMATIC, the robot drives on and the order FINISHES."""
    async with _intervened_mid_order(embedded_broker, unique_interface_name) as (
        runtime,
        client,
        order_id,
    ):
        stopped_at = runtime.state.pose
        await asyncio.sleep(0.5)
        assert runtime.state.pose == stopped_at
        assert runtime.state.nodes
        assert (await client.get(f"/orders/{order_id}")).json()["status"] == "RUNNING"
        runtime.on_stack_status(StackStatus(RobotMode.AUTOMATIC))
        await wait_status(client, order_id, "FINISHED", timeout=15)
        assert runtime.state.last_node_id == "3"


async def test_an_order_of_an_intervened_3_0_robot_can_be_cancelled(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """3.0 Table 11 (T58): DELETE /orders while an operator steers the robot (INTERVENED) sends
    cancelOrder at once; the robot takes it, and once back in AUTOMATIC it stops at its next
    node (R63) and the order ends CANCELLED."""
    async with _intervened_mid_order(embedded_broker, unique_interface_name) as (
        runtime,
        client,
        order_id,
    ):
        assert (await client.delete(f"/orders/{order_id}")).status_code == 202
        await wait_until(lambda: runtime.state.cancel_action_id is not None, timeout=5)
        runtime.on_stack_status(StackStatus(RobotMode.AUTOMATIC))
        await wait_status(client, order_id, "CANCELLED", timeout=15)
        assert runtime.state.last_node_id == "1"  # the next node after where it was taken over


async def test_a_3_0_robot_moved_by_hand_is_taken_up_where_it_was_put(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """3.0 Table 10 (T62): an operator pushes r1 in MANUAL from node 7 off the graph; it reports
    lastNodeId "" and master control sees it there, not on node 7. Put down on node 1 and back
    in AUTOMATIC, it is given its next order from node 1, which it takes and finishes."""
    interface_v3 = f"{unique_interface_name}-v3"
    async with (
        running_master(
            embedded_broker, unique_interface_name, interface_name_v3=interface_v3
        ) as master,
        simulated_vehicle(embedded_broker, interface_v3, vda_version="3.0.0") as vehicle,
        api_client(master) as client,
    ):
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        runtime = vehicle.runtimes[0]
        runtime.on_stack_status(StackStatus(RobotMode.MANUAL))
        pose = runtime.state.pose
        assert runtime.move_by_hand(Pose(2.5, 2.0, pose.theta, pose.map_id)) is None

        def seen_off_its_node() -> bool:
            view = master.service.fleet.get(AGV)
            state = None if view is None else view.state
            return (
                state is not None
                and state.last_node_id == ""
                and state.agv_position is not None
                and state.agv_position.y == 2.0
            )

        await wait_until(seen_off_its_node, timeout=5)
        assert runtime.move_by_hand(Pose(5.02, 0.01, pose.theta, pose.map_id)) is None
        runtime.on_stack_status(StackStatus(RobotMode.AUTOMATIC))
        await wait_until(lambda: master.service.availability_of(AGV) is None, timeout=5)
        created = await client.post("/orders", json={**BODY, "destination": "3"})
        assert created.status_code == 201, created.text
        assert created.json()["order"]["nodes"][0]["nodeId"] == "1"
        await wait_status(client, created.json()["orderId"], "FINISHED", timeout=15)
        assert runtime.state.last_node_id == "3"
