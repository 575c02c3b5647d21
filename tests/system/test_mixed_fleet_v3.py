"""A mixed fleet under one master on Mosquitto (issue 13 item 4): a 2.0.0, a 2.1.0 and a 3.0.0
vehicle, real processes. Each vehicle is addressed in its own version (3.0 under its own
interface name and ``v3``), each drives its order to FINISHED, and every message either side
sends validates against the official schema of its version (and the project's own)."""

from __future__ import annotations

import httpx
import pytest

from tests.system.stack import Captured, Stack, capturing

pytestmark = pytest.mark.mosquitto

#: Disjoint routes on the demo graph: robot_0 7→10, robot_1 9→3, robot_2 5→8.
ROUTES = {"robot_0": ["17", "12", "11"], "robot_1": ["41", "39"], "robot_2": ["24", "26"]}
VERSIONS = {"robot_0": "2.0.0", "robot_1": "2.1.0", "robot_2": "3.0.0"}


@pytest.mark.parametrize("broker", ["mosquitto"], indirect=True)
async def test_mixed_fleet_2_0_2_1_3_0_under_one_master(stack: Stack, capture: Captured) -> None:
    """T01, T10, T12, T18, T79, T80: every vehicle reports in its version, takes an order built
    from the same graph in that version and finishes it; 3.0 traffic runs under
    ``<interface>-v3/v3``; the 3.0 vehicle hibernates and wakes through the API (T06); no
    message of either side breaks its official schema."""
    interface_v3 = f"{stack.interface}-v3"
    async with capturing(stack.broker.address, interface_v3) as capture_v3:
        stack.start_master("--interface-name-v3", interface_v3)
        stack.start_vehicle("robot_0", "--vda-version", "2.0.0")
        stack.start_vehicle("robot_1", "--vda-version", "2.1.0")
        stack.start_vehicle(
            "robot_2",
            "--vda-version",
            "3.0.0",
            "--interface-name",
            interface_v3,
            "--start-node",
            "5",
        )
        async with httpx.AsyncClient(timeout=5) as http:
            for robot, version in VERSIONS.items():
                view = await stack.wait_vehicle(http, robot, lambda v: bool(v.get("available")))
                assert view["version"] == version
            order_ids = {}
            for robot, route in ROUTES.items():
                answer = await http.post(
                    f"{stack.api}/orders",
                    json={"manufacturer": "vda-sim", "serialNumber": robot, "route": route},
                )
                assert answer.status_code == 201, answer.text
                order_ids[robot] = answer.json()["orderId"]
            for order_id in order_ids.values():
                await stack.wait_order(http, order_id, "FINISHED", timeout=60)
            final = await stack.vehicle(http, "robot_2")
            assert final["lastNodeId"] == "8"
            # T06: hibernation through the API, and back.
            path = f"{stack.api}/vehicles/vda-sim/robot_2/instantActions"
            asked = await http.post(path, json={"actions": [{"actionType": "startHibernation"}]})
            assert asked.status_code == 202, asked.text
            await stack.wait_vehicle(http, "robot_2", lambda v: bool(v.get("hibernating")))
            asked = await http.post(path, json={"actions": [{"actionType": "stopHibernation"}]})
            assert asked.status_code == 202, asked.text
            await stack.wait_vehicle(http, "robot_2", lambda v: bool(v.get("available")))
        await stack.stop_all()  # OFFLINE from every vehicle is captured and checked too
    prefix_v3 = f"{interface_v3}/v3/vda-sim/robot_2"
    orders = capture_v3.payloads(f"{prefix_v3}/order")
    assert orders, "no 3.0 order captured"
    assert {o["version"] for o in orders} == {"3.0.0"}
    assert all("startNodeId" not in e for o in orders for e in o["edges"])  # type: ignore[attr-defined]
    states = capture_v3.payloads(f"{prefix_v3}/state")
    assert states[-1]["lastNodeId"] == "8"
    state_ids = {s["headerId"] for s in states}
    visualizations = capture_v3.payloads(f"{prefix_v3}/visualization")
    assert visualizations, "no 3.0 visualization captured"
    assert all(v["referenceStateHeaderId"] in state_ids for v in visualizations[1:])
    connections = [c["connectionState"] for c in capture_v3.payloads(f"{prefix_v3}/connection")]
    assert connections[0] == "ONLINE"
    assert "HIBERNATING" in connections
    assert connections[-1] == "OFFLINE"
    for robot in ("robot_0", "robot_1"):
        sent = capture.payloads(f"{stack.interface}/v2/vda-sim/{robot}/order")
        assert {o["version"] for o in sent} == {VERSIONS[robot]}
    problems = capture_v3.schema_problems()
    assert not problems, "3.0 messages that fail a schema:\n" + "\n".join(problems[:10])
