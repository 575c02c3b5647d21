"""A RELEASE zone end to end over MQTT: a 3.0 simulated robot that asks for the zone
(zoneRequest, answered on ``responses``) and a 2.x one that cannot ask, crossing one zone at
two places 8 m apart, never inside it at the same time (3.0 §6.4.1.1, §6.4.3; T91-T93;
docs/master.md, Release zones)."""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from tests.integration.master_helpers import (
    api_client,
    running_master,
    simulated_vehicle,
    wait_status,
    wait_until,
)
from vda5050.graph_file import GraphVertex
from vda5050.models.v3.state import RequestStatus
from vda5050.polygons import point_near
from vda5050.topics import AgvId
from vda_master.testing import DEMO_GRAPH, demo_graph_with_zones, zone
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.runtime3 import VehicleRuntimeV3

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress
    from vda_vehicle.service import VehicleService

pytestmark = pytest.mark.integration

#: A strip across the demo ladder at x = 10: both rails' nodes 2 and 6 and the rung between.
STRIP = [[9.0, -1.0], [11.0, -1.0], [11.0, 9.0], [9.0, 9.0]]
STRIP_ZONE = [GraphVertex(x=x, y=y) for x, y in STRIP]
DOOR = zone("door", "RELEASE", STRIP, releaseLossBehavior="STOP")
GRAPH = demo_graph_with_zones(DOOR)
#: The simulated 1.2 m × 0.8 m body's circumscribed radius: its contour is in the zone when its
#: reference point is this close.
BODY_R = math.hypot(1.2, 0.8) / 2


@pytest.fixture
def graph_file(tmp_path: Path) -> Path:
    raw = json.loads(DEMO_GRAPH.read_text(encoding="utf-8"))
    path = tmp_path / "door.json"
    path.write_text(json.dumps({**raw, "zones": [DOOR]}), encoding="utf-8")
    return path


async def test_a_robot_that_asks_and_a_vehicle_that_cannot_share_a_release_zone(
    embedded_broker: BrokerAddress, unique_interface_name: str, graph_file: Path
) -> None:
    """r1 (3.0, RELEASE in its supportedZones) drives the lower rail 1 → 2 → 10 and back, r2
    (2.0) the upper rail 8 → 6 → 5 and back, at the same time: each crosses the strip 8 m
    from the other. Master control gives the zone to one at a time; r1 asks before it enters
    and enters only GRANTED, and drops its request once out. Their contours are never in the
    zone together, and every order finishes."""
    interface_v3 = f"{unique_interface_name}-v3"
    async with (
        running_master(
            embedded_broker, unique_interface_name, graph=GRAPH, interface_name_v3=interface_v3
        ) as master,
        simulated_vehicle(
            embedded_broker, interface_v3, vda_version="3.0.0", graph=graph_file, start_node="1"
        ) as robot,
        simulated_vehicle(
            embedded_broker,
            unique_interface_name,
            vda_version="2.0.0",
            graph=graph_file,
            serial_number="r2",
            start_node="8",
        ) as vehicle,
        api_client(master) as client,
    ):
        zone_set_id = master.service.zone_sets["demo"].zone_set_id
        await wait_until(
            lambda: master.service.zone_set_status(_r("1"), zone_set_id) == "ENABLED", timeout=10
        )
        await wait_until(lambda: all(master.service.availability_of(_r(s)) is None for s in "12"))
        waits = []
        async with _one_at_a_time(robot, vehicle) as seen:
            for legs in ((("r1", "10"), ("r2", "5")), (("r1", "1"), ("r2", "8"))):
                ids = []
                for serial, destination in legs:
                    body = {"manufacturer": "acme", "serialNumber": serial}
                    created = await client.post(
                        "/orders", json={**body, "destination": destination}
                    )
                    assert created.status_code == 201, created.text
                    ids.append(created.json()["orderId"])
                for order_id in ids:
                    await wait_status(client, order_id, "FINISHED", timeout=40)
                    answer = await client.get(f"/orders/{order_id}/events")
                    assert answer.status_code == 200, answer.text
                    history = answer.json()
                    waits += [e for e in history if e["event"] == "waiting"]
        assert seen.granted_before_entry
        assert waits  # side by side at the start: one of them waited for the other
        assert all(w["nodeId"] in {"1", "8", "10", "5"} for w in waits)  # outside the zone
        assert seen.inside == {"r1", "r2"}  # both crossed
        zones = (await client.get("/zones")).json()
        assert zones[0]["heldBy"] in {None, "acme/r1", "acme/r2"}
        assert zones[0]["requests"] == {}  # r1 is out: its request is gone


def _r(number: str) -> AgvId:
    return AgvId("acme", f"r{number}")


def _granted(runtime: VehicleRuntime) -> bool:
    """The 3.0 robot holds a GRANTED request for the zone."""
    assert isinstance(runtime, VehicleRuntimeV3)
    return any(
        request.zone.zone.zone_id == "door" and request.status is RequestStatus.GRANTED
        for request in runtime.requests.held
    )


class _Seen:
    def __init__(self) -> None:
        self.inside: set[str] = set()
        self.granted_before_entry = True


@asynccontextmanager
async def _one_at_a_time(*services: VehicleService) -> AsyncIterator[_Seen]:
    """Samples both vehicles every 10 ms; fails if their contours were ever in the zone at
    the same time, or if the 3.0 robot was in it without a GRANTED request."""
    seen = _Seen()
    together = False
    was_inside: set[str] = set()

    async def watch() -> None:
        nonlocal together, was_inside
        while True:
            now_inside = set()
            for service in services:
                for runtime in service.runtimes:
                    pose = runtime.state.pose
                    serial = runtime.agv.serial_number
                    if point_near(STRIP_ZONE, (pose.x, pose.y), BODY_R):
                        now_inside.add(serial)
                        entering = serial not in was_inside
                        if entering and serial == "r1" and not _granted(runtime):
                            seen.granted_before_entry = False
            together = together or len(now_inside) > 1
            seen.inside |= now_inside
            was_inside = now_inside
            await asyncio.sleep(0.01)

    watcher = asyncio.create_task(watch())
    try:
        yield seen
    finally:
        watcher.cancel()
    assert not together
