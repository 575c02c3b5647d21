"""The master HTTP API against live vehicles (architecture §3.4), bad input at the MQTT edge, and
the protocol version each vehicle is addressed in (§6.4, R84, R112)."""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING

import httpx
import pytest
from structlog.testing import capture_logs

from tests.integration.master_helpers import (
    has_factsheet,
    running_master,
    serving,
    wait_reported,
    wait_status,
    wait_until,
)
from tests.integration.master_vehicle import ScriptedVehicle, running_vehicle
from vda5050.models import OperatingMode
from vda5050.topics import Topic
from vda_master.testing import demo_graph

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

AGV = {"manufacturer": "acme", "serialNumber": "robot_1"}


async def test_api_answers_with_precise_errors(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """404, 409 and 422 answers say exactly what is wrong."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph(), step_s=0.3)
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        _,
        client,
    ):
        cases = [
            ({"manufacturer": "acme", "serialNumber": "ghost", "destination": "10"}, 404, "ghost"),
            ({**AGV, "destination": "999"}, 404, "node '999' is not in the graph"),
            ({**AGV, "route": ["12"]}, 422, "vehicle stands at node '7'"),
            ({**AGV, "destination": "10", "route": ["17"]}, 422, "exactly one of destination"),
            ({"serialNumber": "robot_1", "destination": "10"}, 422, "both manufacturer"),
            ({**AGV, "destination": 10.5}, 422, "destination"),
        ]
        for body, status, text in cases:
            response = await client.post("/orders", json=body)
            assert response.status_code == status, (body, response.text)
            assert text in response.json()["detail"], response.text
        first = await client.post("/orders", json={**AGV, "destination": "18"})
        assert first.status_code == 201
        busy = await client.post("/orders", json={**AGV, "destination": "10"})
        assert busy.status_code == 409
        assert "it runs order" in busy.json()["detail"]
        assert (await client.get("/orders/nope")).status_code == 404
        assert (await client.delete("/orders/nope")).status_code == 404


async def test_vehicle_views(embedded_broker: BrokerAddress, unique_interface_name: str) -> None:
    """GET /vehicles lists vehicles; the detail view holds the last state and the factsheet."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph())
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        master,
        client,
    ):
        await wait_until(lambda: has_factsheet(master, vehicle.agv))
        (summary,) = (await client.get("/vehicles")).json()
        assert summary["connectionState"] == "ONLINE"
        assert summary["lastNodeId"] == "7"
        assert summary["driving"] is False
        assert summary["charging"] is False
        detail = (await client.get("/vehicles/acme/robot_1")).json()
        assert detail["state"]["lastNodeId"] == "7"
        assert detail["factsheet"]["protocolLimits"]["timing"]["minOrderInterval"] == 0.0
        missing = await client.get("/vehicles/acme/nobody")
        assert missing.status_code == 404
        assert "acme/nobody is unknown" in missing.json()["detail"]
        health = (await client.get("/health")).json()
        assert health == {
            "status": "ok",
            "vehicles": 1,
            "availableVehicles": 1,
            "activeOrders": 0,
            "queuedOrders": 0,
            "broker": {"connected": True, "problems": []},
        }
        assert (await client.get("/docs")).status_code == 200


async def test_instant_actions_are_checked_and_sent(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Declared instant actions get ids and reach the vehicle; undeclared ones are refused."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph())
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        master,
        client,
    ):
        await wait_until(lambda: has_factsheet(master, vehicle.agv))
        url = "/vehicles/acme/robot_1/instantActions"
        response = await client.post(url, json={"actions": [{"actionType": "startPause"}]})
        assert response.status_code == 202, response.text
        (action_id,) = response.json()["actionIds"]
        # The master may also have sent a stateRequest when the vehicle appeared.
        await wait_until(
            lambda: any(a.action_id == action_id for m in vehicle.instant for a in m.actions)
        )
        refused = await client.post(url, json={"actions": [{"actionType": "pick"}]})
        assert refused.status_code == 422
        assert "not allowed as INSTANT" in refused.json()["detail"]
        empty = await client.post(url, json={"actions": []})
        assert empty.status_code == 422


async def test_nothing_is_sent_to_a_manual_vehicle(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A vehicle in MANUAL gets no order and no instant action (R84)."""
    vehicle = ScriptedVehicle(
        embedded_broker, unique_interface_name, demo_graph(), mode=OperatingMode.MANUAL
    )
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        _,
        client,
    ):
        order = await client.post("/orders", json={**AGV, "destination": "10"})
        assert order.status_code == 409
        assert "operatingMode is MANUAL" in order.json()["detail"]
        url = "/vehicles/acme/robot_1/instantActions"
        action = await client.post(url, json={"actions": [{"actionType": "startPause"}]})
        assert action.status_code == 409
        await asyncio.sleep(0.1)
        assert vehicle.received == []
        assert vehicle.instant == []


async def test_vehicle_is_addressed_in_its_own_version(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A 2.0.0 vehicle without a factsheet gets 2.0.0 orders with the full graph content:
    nodePosition with mapId, edge length (a factsheet narrows, its absence does not, issue 8)."""
    vehicle = ScriptedVehicle(
        embedded_broker, unique_interface_name, demo_graph(), version="2.0.0", with_factsheet=False
    )
    async with serving(vehicle, embedded_broker, unique_interface_name) as (
        _,
        client,
    ):
        response = await client.post("/orders", json={**AGV, "destination": "10"})
        assert response.status_code == 201, response.text
        await wait_status(client, response.json()["orderId"], "FINISHED")
    order = vehicle.received[0]
    assert order.version == "2.0.0"
    assert all(
        node.node_position is not None and node.node_position.map_id == "demo"
        for node in order.nodes
    )
    assert all(edge.length is not None for edge in order.edges)


async def test_invalid_vehicle_messages_are_dropped_with_one_log_line(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """A broken state is dropped with one line naming vehicle, topic and reason; the view holds."""
    vehicle = ScriptedVehicle(embedded_broker, unique_interface_name, demo_graph())
    topic = vehicle._topic(Topic.STATE)
    async with (
        running_master(embedded_broker, unique_interface_name) as master,
        running_vehicle(vehicle),
    ):
        await wait_reported(master, vehicle.agv)
        before = master.service.fleet.get(vehicle.agv)
        with capture_logs() as logs:
            vehicle.session.publish(topic, Topic.STATE, b'{"headerId": "nope"}')
            await wait_until(lambda: any(e["event"] == "message.dropped" for e in logs))
        (dropped,) = [e for e in logs if e["event"] == "message.dropped"]
        assert dropped["agv"] == "acme/robot_1"
        assert dropped["topic"] == topic
        assert "headerId" in dropped["reason"]
        after = master.service.fleet.get(vehicle.agv)
        assert after is not None
        assert before is not None
        assert after.state == before.state
        vehicle.publish_state()
        await wait_until(lambda: (master.service.fleet.get(vehicle.agv) or before) is not after)


async def test_real_http_server_answers(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """uvicorn serves the API in the master's own event loop on the configured port."""
    async with running_master(embedded_broker, unique_interface_name) as master:
        await wait_until(lambda: master.api_port is not None)
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{master.api_port}") as client:
            response = await client.get("/health")
    assert response.status_code == 200
    assert response.json()["status"] == "ok"
