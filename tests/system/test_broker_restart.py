"""The broker restarts in the middle of an order: both services recover by themselves."""

from __future__ import annotations

import asyncio

import httpx

from tests.system.stack import Captured, Stack


async def test_order_finishes_across_a_broker_restart(stack: Stack, capture: Captured) -> None:
    """R13: services reconnect, the vehicle keeps its order, it finishes, the view is right."""
    stack.start_master()
    stack.start_vehicle("robot_0", "--time-lapse", "3")
    async with httpx.AsyncClient(timeout=5) as http:
        await stack.wait_vehicle(http, "robot_0", lambda v: bool(v.get("available")))
        answer = await http.post(
            f"{stack.api}/orders",
            json={"manufacturer": "vda-sim", "serialNumber": "robot_0", "destination": "3"},
        )
        assert answer.status_code == 201, answer.text
        order_id = answer.json()["orderId"]
        node_ids = answer.json()["order"]["nodes"]
        assert len(node_ids) >= 4
        await stack.wait_vehicle(http, "robot_0", lambda v: v.get("lastNodeId") != "7")
        before = (await http.get(f"{stack.api}/orders/{order_id}")).json()
        assert before["status"] == "RUNNING", "the restart must happen mid-order"
        await asyncio.to_thread(stack.broker.stop)
        await asyncio.sleep(1.0)
        await asyncio.to_thread(stack.broker.start)
        info = await stack.wait_order(http, order_id, "FINISHED", timeout=40)
        view = await stack.wait_vehicle(
            http, "robot_0", lambda v: v.get("connectionState") == "ONLINE" and v["available"]
        )
    assert info["status"] == "FINISHED"
    assert view["lastNodeId"] == "3"
    assert view["reachable"] is True
    for service in stack.services:
        assert service.running, f"{service.name} exited:\n{service.log()[-2000:]}"
    assert capture.messages
