"""A mixed fleet under one master with traffic control (issue 9): two of our simulated vehicles
and two vda-5050-lib virtual AGVs (which only follow their base) take random orders on the demo
warehouse. Every order finishes, and an independent observer of their positions (visualization
and state over MQTT) never sees two vehicles closer than the safety distance."""

from __future__ import annotations

import asyncio
import json
import math
import random
import time
from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.integration.mqtt_helpers import client_for
from tests.interop.node_lib import NodeRuntime
from tests.interop.peers import StartPose, running_agvs
from tests.interop.services import OurMaster, running_our_master, running_our_vehicle
from tests.mosquitto import Mosquitto
from vda5050.broker import BrokerAddress

pytestmark = [pytest.mark.interop]

GRAPH = Path(__file__).resolve().parents[2] / "config" / "graphs" / "demo.json"
NODES = {n["nodeId"]: (n["x"], n["y"]) for n in json.loads(GRAPH.read_text())["nodes"]}
#: Our simulated vehicles' footprint gives the safety distance: √(1.2² + 0.8²) + 0.25 m.
SAFETY_M = 1.69
#: Positions of two vehicles are compared as last reported; at 6 m/s and 40 reports per second
#: either may be 0.15 m behind.
STALENESS_M = 0.2
ORDERS_PER_VEHICLE = 2
TIME_LAPSE = 4
OURS = {"ours-1": "7", "ours-2": "3"}
LIBS = {"lib-1": "4", "lib-2": "9"}


@dataclass
class Observer:
    """The latest position of every vehicle and the smallest distance between two of them."""

    positions: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    minimum_m: float = math.inf
    closest: tuple[str, str] = ("", "")
    updates: int = 0

    def see(self, serial: str, x: float, y: float) -> None:
        now = time.monotonic()
        self.positions[serial] = (x, y, now)
        self.updates += 1
        for other, (ox, oy, seen) in self.positions.items():
            if other == serial or now - seen > 1.0:
                continue
            distance = math.hypot(x - ox, y - oy)
            if distance < self.minimum_m:
                self.minimum_m, self.closest = distance, (serial, other)


@asynccontextmanager
async def observing(address: BrokerAddress, interface: str) -> AsyncIterator[Observer]:
    observer = Observer()

    async def listen() -> None:
        async with client_for(address) as client:
            await client.subscribe(f"{interface}/v2/+/+/visualization")
            await client.subscribe(f"{interface}/v2/+/+/state")
            async for message in client.messages:
                try:
                    payload = json.loads(message.payload)
                except ValueError:
                    continue
                position = payload.get("agvPosition") if isinstance(payload, dict) else None
                if isinstance(position, dict) and {"x", "y"} <= set(position):
                    serial = str(message.topic).split("/")[3]
                    observer.see(serial, float(position["x"]), float(position["y"]))

    async with asyncio.TaskGroup() as group:
        task = group.create_task(listen(), name="test.observer")
        try:
            yield observer
        finally:
            task.cancel()


async def drive_random_orders(master: OurMaster, serials: list[str], seed: int) -> int:
    """Give every vehicle ORDERS_PER_VEHICLE random destinations, one after the other; returns
    how many finished. A 409 (busy: e.g. moved to parking by traffic control) is retried."""
    rng = random.Random(seed)
    left = dict.fromkeys(serials, ORDERS_PER_VEHICLE)
    running: dict[str, str] = {}
    finished = 0
    async with asyncio.timeout(120):
        while left or running:
            for serial, order_id in list(running.items()):
                info = (await master.http.get(f"{master.api}/orders/{order_id}")).json()
                assert info["status"] not in {"FAILED", "REJECTED", "CANCELLED"}, info
                if info["status"] == "FINISHED":
                    del running[serial]
                    finished += 1
            for serial in [s for s in left if s not in running]:
                manufacturer = "ours" if serial.startswith("ours") else "vdalib"
                destination = rng.choice(sorted(NODES))
                answer = await master.http.post(
                    f"{master.api}/orders",
                    json={
                        "manufacturer": manufacturer,
                        "serialNumber": serial,
                        "destination": destination,
                    },
                )
                if answer.status_code == 201:
                    running[serial] = answer.json()["orderId"]
                    left[serial] -= 1
                    if not left[serial]:
                        del left[serial]
                else:
                    assert answer.status_code == 409, answer.text
            await asyncio.sleep(0.1)
    return finished


async def test_mixed_fleet_random_orders_keep_their_distance(
    node_runtime: NodeRuntime, mosquitto: Mosquitto, unique_interface_name: str, tmp_path: Path
) -> None:
    """Random orders for two of ours and two vda-5050-lib AGVs all finish; never closer than
    the safety distance (observed over MQTT, not by the master)."""
    url = mosquitto.address.url
    poses = {serial: StartPose(*NODES[node], 0.0, "demo", node) for serial, node in LIBS.items()}
    async with AsyncExitStack() as stack:
        observer = await stack.enter_async_context(
            observing(mosquitto.address, unique_interface_name)
        )
        for serial, node in OURS.items():
            await stack.enter_async_context(
                running_our_vehicle(
                    tmp_path,
                    "--graph",
                    str(GRAPH),
                    "--start-node",
                    node,
                    "--visualization-interval-s",
                    "0.025",
                    "--tick-hz",
                    "20",
                    broker_url=url,
                    interface_name=unique_interface_name,
                    manufacturer="ours",
                    serial_number=serial,
                    time_lapse=TIME_LAPSE,
                )
            )
        await stack.enter_async_context(
            running_agvs(
                node_runtime,
                broker_url=url,
                interface_name=unique_interface_name,
                manufacturer="vdalib",
                poses=poses,
                timeLapse=TIME_LAPSE,
                tickRate=20,
                vehicleSpeed=1.5,
                visualizationIntervalS=0.025,
            )
        )
        master = await stack.enter_async_context(
            running_our_master(
                tmp_path, broker_url=url, interface_name=unique_interface_name, graph=GRAPH
            )
        )
        serials = [*OURS, *LIBS]
        await master.wait_available(serials, timeout=15)
        finished = await drive_random_orders(master, serials, seed=9)
        traffic = (await master.http.get(f"{master.api}/traffic")).json()
    print(  # noqa: T201 - the figure the closing note reports
        f"\nmixed fleet: {finished} orders, min separation {observer.minimum_m:.2f} m "
        f"({observer.closest}), {observer.updates} position reports"
    )
    assert finished == ORDERS_PER_VEHICLE * len(serials)
    assert observer.updates > 200
    assert observer.minimum_m >= SAFETY_M - STALENESS_M, (observer.minimum_m, observer.closest)
    assert traffic["safetyDistanceM"] == pytest.approx(SAFETY_M, abs=0.01)
    assert {v["serialNumber"] for v in traffic["vehicles"]} >= set(serials)
