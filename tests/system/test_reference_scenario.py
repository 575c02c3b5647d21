"""The reference scenario with real processes, on the embedded amqtt broker and on Mosquitto."""

from __future__ import annotations

import httpx

from tests.system.stack import Captured, Stack, retained


def topic(stack: Stack, robot: str, name: str) -> str:
    return f"{stack.interface}/v2/vda-sim/{robot}/{name}"


async def test_reference_route_is_driven_to_the_end(stack: Stack, capture: Captured) -> None:
    """robot_0 drives nodes 7, 1, 2, 10 over edges 17, 12, 11; nodeStates shrink; FINISHED."""
    stack.start_master()
    for robot in ("robot_0", "robot_1"):
        stack.start_vehicle(robot)
    async with httpx.AsyncClient(timeout=5) as http:
        for robot in ("robot_0", "robot_1"):
            await stack.wait_vehicle(http, robot, lambda v: bool(v.get("available")))
        for robot in ("robot_0", "robot_1"):  # R06/R09: ONLINE, retained
            connection = await retained(stack.broker.address, topic(stack, robot, "connection"))
            assert connection["connectionState"] == "ONLINE"
        answer = await http.post(
            f"{stack.api}/orders",
            json={
                "manufacturer": "vda-sim",
                "serialNumber": "robot_0",
                "route": ["17", "12", "11"],
            },
        )
        assert answer.status_code == 201, answer.text
        order_id = answer.json()["orderId"]
        await stack.wait_order(http, order_id, "FINISHED")
        view = await stack.vehicle(http, "robot_0")
    orders = [
        o for o in capture.payloads(topic(stack, "robot_0", "order")) if o["orderId"] == order_id
    ]
    assert orders, "no order message captured"
    nodes = [(n["nodeId"], n["sequenceId"]) for o in orders for n in o["nodes"]]  # type: ignore[attr-defined]
    edges = [(e["edgeId"], e["sequenceId"]) for o in orders for e in o["edges"]]  # type: ignore[attr-defined]
    assert sorted(set(nodes), key=lambda n: n[1]) == [("7", 0), ("1", 2), ("2", 4), ("10", 6)]
    assert sorted(set(edges), key=lambda e: e[1]) == [("17", 1), ("12", 3), ("11", 5)]
    states = [
        s for s in capture.payloads(topic(stack, "robot_0", "state")) if s["orderId"] == order_id
    ]
    pending = [len(s["nodeStates"]) for s in states]  # type: ignore[arg-type]
    assert pending == sorted(pending, reverse=True), "nodeStates must only shrink"
    assert max(pending) > 0
    final = states[-1]
    assert (final["lastNodeId"], final["nodeStates"], final["edgeStates"]) == ("10", [], [])
    assert view["lastNodeId"] == "10"
