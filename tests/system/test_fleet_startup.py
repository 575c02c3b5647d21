"""A fleet of 100 vehicles in one process starting at once (issue 12, start-up): each vehicle
has its own MQTT connection with its own last will, the master reads every ONLINE, state and
factsheet without asking for what is on its way, and a crash leaves 100 CONNECTIONBROKEN."""

from __future__ import annotations

import asyncio
import json
import signal
from pathlib import Path

import httpx
import pytest

from tests.system.stack import Captured, ServiceProcess, Stack, process_env

VEHICLES = 100
MANUFACTURER = "fleet"


def _lanes(path: Path, vehicles: int) -> None:
    """Vehicle i stands on a_i; a_i -> b_i is 8 m (the graph of benchmarks/fleet.py)."""
    nodes = [{"nodeId": f"a{i}", "x": 0.0, "y": 3.0 * i, "theta": 0.0} for i in range(vehicles)]
    nodes += [{"nodeId": f"b{i}", "x": 8.0, "y": 3.0 * i, "theta": 0.0} for i in range(vehicles)]
    edges = [
        {"edgeId": f"e{i}", "startNodeId": f"a{i}", "endNodeId": f"b{i}"} for i in range(vehicles)
    ]
    path.write_text(json.dumps({"mapId": "lanes", "nodes": nodes, "edges": edges}))


def _fleet(stack: Stack, graph: Path) -> ServiceProcess:
    service = ServiceProcess(
        "fleet",
        [
            "vda_vehicle",
            *("--broker-url", stack.broker.address.url, "--interface-name", stack.interface),
            *("--graph", str(graph), "--start-node", "a0", "--count", str(VEHICLES)),
            *("--manufacturer", MANUFACTURER, "--serial-number", "v"),
        ],
        stack.logs / "fleet.log",
        process_env(),
    ).start()
    stack.services.append(service)
    return service


async def _healthy(http: httpx.AsyncClient, stack: Stack) -> None:
    async with asyncio.timeout(20):
        while True:
            try:
                health = (await http.get(f"{stack.api}/health")).json()
                if health.get("broker", {}).get("connected"):
                    return
            except httpx.TransportError:
                pass
            await asyncio.sleep(0.1)


async def _listed(http: httpx.AsyncClient, stack: Stack) -> list[dict[str, object]]:
    answer = await http.get(f"{stack.api}/vehicles")
    return [v for v in answer.json() if v["manufacturer"] == MANUFACTURER]


def _topics(stack: Stack, kind: str) -> list[str]:
    return [f"{stack.interface}/v2/{MANUFACTURER}/v-{i + 1}/{kind}" for i in range(VEHICLES)]


@pytest.mark.mosquitto
@pytest.mark.parametrize("broker", ["mosquitto"], indirect=True)
async def test_a_hundred_vehicles_start_at_once_and_each_has_its_own_will(
    stack: Stack, capture: Captured, tmp_path: Path
) -> None:
    """All 100 become available at the master with a factsheet each; no stateRequest or
    factsheetRequest is sent (their own state and factsheet were on the way); SIGKILL of the
    process makes the broker publish each vehicle's own CONNECTIONBROKEN (R08, R11)."""
    graph = tmp_path / "lanes.json"
    _lanes(graph, VEHICLES)
    stack.start_master("--graph", str(graph), "--no-traffic-control")
    async with httpx.AsyncClient(timeout=5) as http:
        await _healthy(http, stack)  # subscribed: the ONLINEs arrive live, not retained
        fleet = _fleet(stack, graph)
        async with asyncio.timeout(30):
            while True:
                vehicles = await _listed(http, stack)
                if len(vehicles) == VEHICLES and all(v["available"] for v in vehicles):
                    break
                await asyncio.sleep(0.2)
        assert all(v["hasFactsheet"] and v["connectionState"] == "ONLINE" for v in vehicles)
        requests = [
            topic for topic in {str(m.topic) for m in capture.messages} if "instantActions" in topic
        ]
        assert requests == []
        fleet.signal(signal.SIGKILL)
        await fleet.wait()
        broken = _topics(stack, "connection")

        def all_broken() -> bool:
            return all(
                (payloads := capture.payloads(topic))
                and payloads[-1]["connectionState"] == "CONNECTIONBROKEN"
                for topic in broken
            )

        await capture.wait_until(all_broken, timeout=30)
        async with asyncio.timeout(30):
            while any(v["available"] for v in await _listed(http, stack)):
                await asyncio.sleep(0.2)
    for index, topic in enumerate(broken):
        will = capture.payloads(topic)[-1]
        assert will["serialNumber"] == f"v-{index + 1}"
        assert [p["connectionState"] for p in capture.payloads(topic)].count("ONLINE") == 1
