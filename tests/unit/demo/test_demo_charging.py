"""``--forever`` and the batteries: charging is master control's (docs/master.md, *Charging*);
the demo gives a robot its next transport only once it is available again, and shows what
master control's own order of it is for."""

from __future__ import annotations

import random

import httpx

from vda_demo.missions import Mission, transport_mission
from vda_demo.runner import Progress, refill, render

GRAPH: dict[str, object] = {
    "nodes": [
        {"nodeId": "A2", "stationType": "pick"},
        {"nodeId": "DR1", "stationType": "drop"},
        {"nodeId": "CH1", "stationType": "charging"},
    ]
}


def _finished(serial: str) -> Mission:
    mission = transport_mission(serial, "A2", "DR1")
    mission.step = len(mission.steps)
    mission.title = "done"
    return mission


def test_a_robot_master_control_charges_gets_its_next_transport_once_available() -> None:
    progress = Progress([_finished("robot_0"), _finished("robot_1")])
    vehicles: list[dict[str, object]] = [
        {"serialNumber": "robot_0", "available": False},  # sent to charge, or charging
        {"serialNumber": "robot_1", "available": True},
    ]
    refill(progress, vehicles, random.Random(1), GRAPH)
    assert progress.missions[0].done
    assert progress.missions[0].title == "done"
    assert progress.missions[1].title == "transport A2 → DR1"
    assert not progress.missions[1].done

    vehicles[0]["available"] = True
    refill(progress, vehicles, random.Random(1), GRAPH)
    assert progress.missions[0].title == "transport A2 → DR1"


async def test_the_line_of_a_robot_on_a_charging_order_shows_why() -> None:
    """robot_0's last order is master control's own charging order: the line names it."""
    note = "charging: battery 24 % is below charge_below_pct 30 %"

    def handle(request: httpx.Request) -> httpx.Response:
        path = request.url.path
        if path.startswith("/vehicles/"):
            serial = path.rsplit("/", 1)[-1]
            order_id = "c1" if serial == "robot_0" else "d1"
            battery = {"batteryCharge": 24.0, "charging": serial == "robot_0"}
            return httpx.Response(
                200,
                json={"serialNumber": serial, "orderId": order_id, "lastNodeId": "CH1",
                      "state": {"batteryState": battery}},
            )  # fmt: skip
        assert path == "/orders/c1", path  # only the order the demo did not send is looked up
        return httpx.Response(200, json={"orderId": "c1", "status": "FINISHED", "note": note})

    progress = Progress([_finished("robot_0")])
    progress.started["d1"] = 0.0
    transport = httpx.MockTransport(handle)
    async with httpx.AsyncClient(transport=transport, base_url="http://demo") as http:
        lines = await render(http, progress, [])
    robot_0 = next(line for line in lines if line.startswith("robot_0"))
    assert robot_0.endswith(note), robot_0
    assert "charging" in robot_0.split("%")[1]
    robot_1 = next(line for line in lines if line.startswith("robot_1"))
    assert "charging:" not in robot_1
