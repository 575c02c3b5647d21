"""A small fleet in one event loop for traffic scenarios: the master (traffic control on) and
simulated vehicles on a test graph, a separation monitor, and order helpers."""

from __future__ import annotations

import asyncio
import itertools
import math
from collections.abc import AsyncIterator, Mapping
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import httpx

from tests.integration.master_helpers import api_client, wait_until
from vda5050.graph_file import GraphFile
from vda_master.config import MasterConfig
from vda_master.graph import Graph, build_graph
from vda_master.runtime import MasterProcess
from vda_vehicle.config import VehicleSettings
from vda_vehicle.service import VehicleService

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

#: Simulated time runs this much faster in the scenarios.
TIME_LAPSE = 5.0


def graph_document(
    positions: Mapping[str, tuple[float, float]],
    *,
    two_way: tuple[tuple[str, str], ...] = (),
    one_way: tuple[tuple[str, str], ...] = (),
    stations: Mapping[str, str] | None = None,
) -> dict[str, Any]:
    """A graph file document: nodes at ``positions``, edges ``<a>-<b>``."""
    nodes: list[dict[str, object]] = []
    for node_id, (x, y) in positions.items():
        node: dict[str, object] = {"nodeId": node_id, "x": x, "y": y}
        if stations and node_id in stations:
            node["stationType"] = stations[node_id]
        nodes.append(node)
    pairs = [*one_way, *two_way, *((b, a) for a, b in two_way)]
    edges = [{"edgeId": f"{a}-{b}", "startNodeId": a, "endNodeId": b} for a, b in pairs]
    return {"mapId": "test", "nodes": nodes, "edges": edges}


@dataclass
class Separation:
    """The smallest distance between any two vehicles seen so far."""

    minimum_m: float = math.inf
    closest: tuple[str, str] = ("", "")
    samples: int = 0


@dataclass
class Fleet:
    master: MasterProcess
    client: httpx.AsyncClient
    vehicles: dict[str, VehicleService]
    separation: Separation = field(default_factory=Separation)

    async def order(self, serial: str, destination: str, **extra: object) -> str:
        body = {"manufacturer": "acme", "serialNumber": serial, "destination": destination}
        answer = await self.client.post("/orders", json={**body, **extra})
        assert answer.status_code == 201, answer.text
        order_id: str = answer.json()["orderId"]
        return order_id

    async def status(self, order_id: str) -> dict[str, Any]:
        answer: dict[str, Any] = (await self.client.get(f"/orders/{order_id}")).json()
        return answer

    async def wait_finished(self, *order_ids: str, timeout: float = 40.0) -> None:
        async with asyncio.timeout(timeout):
            while True:
                statuses = [(await self.status(o))["status"] for o in order_ids]
                if all(s == "FINISHED" for s in statuses):
                    return
                assert not {"FAILED", "REJECTED", "CANCELLED"} & set(statuses), statuses
                await asyncio.sleep(0.05)

    def node_of(self, serial: str) -> str:
        return self.vehicles[serial].runtimes[0].state.last_node_id


async def _monitor(vehicles: Mapping[str, VehicleService], separation: Separation) -> None:
    while True:
        poses = {serial: service.runtimes[0].state.pose for serial, service in vehicles.items()}
        for (a, pa), (b, pb) in itertools.combinations(poses.items(), 2):
            distance = math.hypot(pa.x - pb.x, pa.y - pb.y)
            if distance < separation.minimum_m:
                separation.minimum_m, separation.closest = distance, (a, b)
        separation.samples += 1
        await asyncio.sleep(0.01)


@asynccontextmanager
async def running_fleet(
    address: BrokerAddress,
    interface: str,
    document: dict[str, Any],
    starts: Mapping[str, str],
    **master_settings: object,
) -> AsyncIterator[Fleet]:
    """The master and one simulated vehicle per (serial, start node), all reported."""
    graph: Graph = build_graph(document, source="test")
    graph_file = GraphFile.model_validate(document)
    config = MasterConfig.model_validate(
        {
            "broker_url": address.url,
            "interface_name": interface,
            "client_id": f"{interface}-master",
            "api_port": 0,
            "confirm_timeout_s": 0.5,
            "tick_s": 0.02,
            **master_settings,
        }
    )
    master = MasterProcess(config, graph=graph)
    vehicles = {
        serial: VehicleService(
            VehicleSettings.model_validate(
                {
                    "broker_url": address.url,
                    "interface_name": interface,
                    "manufacturer": "acme",
                    "serial_number": serial,
                    "start_node": node,
                    "time_lapse": TIME_LAPSE,
                    "tick_hz": 20.0,
                    "visualization_interval_s": 0,
                    "client_id": f"{interface}-{serial}",
                }
            ),
            graph_file,
        )
        for serial, node in starts.items()
    }
    stop = asyncio.Event()
    async with asyncio.TaskGroup() as group:
        group.create_task(master.run(stop), name="test.master")
        for serial, vehicle in vehicles.items():
            group.create_task(vehicle.run(), name=f"test.{serial}")
        fleet = Fleet(master, httpx.AsyncClient(), vehicles)
        monitor = group.create_task(_monitor(vehicles, fleet.separation), name="test.monitor")
        try:
            async with api_client(master) as client:
                fleet.client = client
                await wait_until(
                    lambda: all(
                        master.service.availability_of(v.runtimes[0].agv) is None
                        for v in vehicles.values()
                    ),
                    timeout=10,
                )
                yield fleet
        finally:
            monitor.cancel()
            for vehicle in vehicles.values():
                vehicle.stop()
            stop.set()
