"""``--forever`` and the batteries: a low robot goes to a charger nobody else uses, charges
there until it is full enough, is sent stopCharging (VDA 5050 §6.8.2), and only then gets its
next transport."""

from __future__ import annotations

import random

import httpx

from vda_demo.missions import CHARGED, Mission, Stations, next_mission, transport_mission
from vda_demo.runner import Progress, refill, stop_charging

STATIONS = Stations(pick=("A2",), drop=("DR1",), charging=("CH1", "CH2"))
GRAPH: dict[str, object] = {
    "nodes": [
        {"nodeId": "A2", "stationType": "pick"},
        {"nodeId": "DR1", "stationType": "drop"},
        {"nodeId": "CH1", "stationType": "charging"},
        {"nodeId": "CH2", "stationType": "charging"},
    ]
}


def _finished(serial: str) -> Mission:
    mission = transport_mission(serial, "A2", "DR1")
    mission.step = len(mission.steps)
    return mission


def _vehicle(serial: str, battery: float, *, charging: bool, node: str) -> dict[str, object]:
    return {"serialNumber": serial, "batteryCharge": battery, "charging": charging,
            "lastNodeId": node}  # fmt: skip


def test_a_low_robot_goes_to_a_charger_nobody_else_uses() -> None:
    rng = random.Random(1)
    for _ in range(20):
        mission = next_mission("robot_0", 20.0, STATIONS, rng, busy_chargers={"CH1"})
        assert mission is not None
        assert mission.steps[0]["destination"] == "CH2"
    assert next_mission("robot_0", 20.0, STATIONS, rng, busy_chargers={"CH1", "CH2"}) is None
    transport = next_mission("robot_0", 80.0, STATIONS, rng, busy_chargers={"CH1", "CH2"})
    assert transport is not None
    assert transport.title == "transport A2 → DR1"


def test_refill_keeps_a_charging_robot_on_its_charger_until_charged() -> None:
    """robot_0 charges on CH1; robot_1, low, stands on CH2 and charges there; robot_2, low,
    finds both chargers taken and waits. Once robot_0 has CHARGED it is named for stopCharging,
    and it gets a transport only when its state no longer says charging."""
    progress = Progress([_finished("robot_0"), _finished("robot_1"), _finished("robot_2")])
    rng = random.Random(2)
    vehicles = [
        _vehicle("robot_0", 50.0, charging=True, node="CH1"),
        _vehicle("robot_1", 25.0, charging=False, node="CH2"),
        _vehicle("robot_2", 20.0, charging=False, node="A2"),
    ]
    assert refill(progress, vehicles, rng, GRAPH) == []
    assert progress.missions[0].done
    assert progress.missions[1].title == "charge at CH2"
    assert progress.missions[2].done
    vehicles[0] = _vehicle("robot_0", CHARGED, charging=True, node="CH1")
    assert refill(progress, vehicles, rng, GRAPH) == ["robot_0"]
    assert progress.missions[0].done
    vehicles[0] = _vehicle("robot_0", CHARGED, charging=False, node="CH1")
    assert refill(progress, vehicles, rng, GRAPH) == []
    assert progress.missions[0].title == "transport A2 → DR1"
    assert progress.missions[2].done  # CH1 is still taken: robot_0 stands on it


async def test_stop_charging_is_sent_once_while_the_state_still_says_charging() -> None:
    sent: list[tuple[str, object]] = []

    def handle(request: httpx.Request) -> httpx.Response:
        sent.append((request.url.path, request.read()))
        return httpx.Response(202, json={"actionIds": ["a1"]})

    progress = Progress([])
    transport = httpx.MockTransport(handle)
    async with httpx.AsyncClient(transport=transport, base_url="http://master") as http:
        await stop_charging(http, ["robot_0"], progress)
        await stop_charging(http, ["robot_0"], progress)
    assert [path for path, _ in sent] == ["/vehicles/vda-sim/robot_0/instantActions"]
    assert b'"stopCharging"' in sent[0][1]  # type: ignore[operator]
