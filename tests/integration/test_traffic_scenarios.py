"""Traffic control with simulated vehicles at high time lapse (issue 9): head-on in a one-lane
aisle, a crossing, following on one lane, an idle vehicle on the route, a three-vehicle cycle.
Every order finishes and no two vehicles ever come closer than the safety distance; with traffic
control off the same head-on meeting drives them through each other."""

from __future__ import annotations

import asyncio
import math
from typing import TYPE_CHECKING

import pytest

from tests.integration.traffic_rig import graph_document, running_fleet

if TYPE_CHECKING:
    from vda5050.broker import BrokerAddress

pytestmark = pytest.mark.integration

#: The simulated vehicles are 1.2 m × 0.8 m: √(1.2² + 0.8²) + 0.25 m (docs/traffic.md).
SAFETY_M = 1.69
#: Sampling lag: positions are sampled every 10 ms while vehicles move up to 7.5 m/s.
TOLERANCE_M = 0.1

AISLE = graph_document(
    {
        "WP1": (0.0, 3.0),
        "WP2": (0.0, -3.0),
        "W": (3.0, 0.0),
        "A1": (7.0, 0.0),
        "A2": (11.0, 0.0),
        "A3": (15.0, 0.0),
        "E": (19.0, 0.0),
        "EP1": (22.0, 3.0),
        "EP2": (22.0, -3.0),
    },
    two_way=(
        ("WP1", "W"),
        ("WP2", "W"),
        ("W", "A1"),
        ("A1", "A2"),
        ("A2", "A3"),
        ("A3", "E"),
        ("E", "EP1"),
        ("E", "EP2"),
    ),
)


async def test_head_on_in_a_one_lane_aisle(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Two vehicles ordered through the aisle from both ends: one enters, the other waits
    outside until the aisle is free; both finish, never closer than the safety distance."""
    starts = {"r1": "WP1", "r2": "EP2"}
    async with running_fleet(embedded_broker, unique_interface_name, AISLE, starts) as fleet:
        east = await fleet.order("r1", "EP1")
        west = await fleet.order("r2", "WP2")
        await fleet.wait_finished(east, west)
        waited = (await fleet.client.get("/traffic")).json()
    assert (fleet.node_of("r1"), fleet.node_of("r2")) == ("EP1", "WP2")
    assert fleet.separation.minimum_m >= SAFETY_M - TOLERANCE_M, fleet.separation
    assert waited["enabled"] is True
    assert waited["safetyDistanceM"] == pytest.approx(SAFETY_M, abs=0.01)


async def test_without_traffic_control_they_meet_head_on(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """The same meeting with traffic control off: the separation monitor sees them pass
    through each other (what the scenario above prevents)."""
    starts = {"r1": "WP1", "r2": "EP2"}
    async with running_fleet(
        embedded_broker, unique_interface_name, AISLE, starts, traffic_control=False
    ) as fleet:
        east = await fleet.order("r1", "EP1")
        west = await fleet.order("r2", "WP2")
        await fleet.wait_finished(east, west)
    assert fleet.separation.minimum_m < 1.0


async def test_crossing(embedded_broker: BrokerAddress, unique_interface_name: str) -> None:
    """Two vehicles whose routes cross at X: one crosses first, both finish, apart."""
    document = graph_document(
        {"N": (0.0, 9.0), "S": (0.0, -9.0), "W": (-9.0, 0.0), "E": (9.0, 0.0), "X": (0.0, 0.0)},
        two_way=(("N", "X"), ("X", "S"), ("W", "X"), ("X", "E")),
    )
    starts = {"r1": "N", "r2": "W"}
    async with running_fleet(embedded_broker, unique_interface_name, document, starts) as fleet:
        south = await fleet.order("r1", "S")
        east = await fleet.order("r2", "E")
        await fleet.wait_finished(south, east)
    assert fleet.separation.minimum_m >= SAFETY_M - TOLERANCE_M, fleet.separation


async def test_following_on_one_lane(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Two vehicles one behind the other on a one-way lane: the follower keeps its distance."""
    lane = {f"L{i}": (4.0 * i, 0.0) for i in range(7)}
    document = graph_document(lane, one_way=tuple((f"L{i}", f"L{i + 1}") for i in range(6)))
    starts = {"r1": "L1", "r2": "L0"}
    async with running_fleet(embedded_broker, unique_interface_name, document, starts) as fleet:
        leader = await fleet.order("r1", "L6")
        follower = await fleet.order("r2", "L5")
        await fleet.wait_finished(leader, follower)
    assert fleet.separation.minimum_m >= SAFETY_M - TOLERANCE_M, fleet.separation


#: A line A-B-C-D, the only way through, with a parking node P off B.
ONE_WAY_THROUGH = graph_document(
    {"A": (0.0, 0.0), "B": (5.0, 0.0), "C": (10.0, 0.0), "D": (15.0, 0.0), "P": (5.0, 5.0)},
    two_way=(("A", "B"), ("B", "C"), ("C", "D"), ("B", "P")),
    stations={"P": "parking"},
)


async def test_idle_vehicle_on_the_route_is_sent_to_parking(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """r2 stands idle on r1's route: master control sends it to the parking node by an order of
    its own, and r1 passes."""
    starts = {"r1": "A", "r2": "C"}
    async with running_fleet(
        embedded_broker, unique_interface_name, ONE_WAY_THROUGH, starts
    ) as fleet:
        through = await fleet.order("r1", "D")
        meanwhile = {"manufacturer": "acme", "serialNumber": "r2", "destination": "A"}
        busy = await fleet.client.post("/orders", json=meanwhile)
        await fleet.wait_finished(through)
        orders = (await fleet.client.get("/orders", params={"serialNumber": "r2"})).json()
    assert fleet.node_of("r2") == "P"
    assert orders[0]["note"].startswith("traffic:")
    # An order for r2 while it is on its way says where it goes, why, and when to ask again.
    assert busy.status_code == 409
    assert busy.json()["detail"] == (
        "vehicle acme/r2 is not available: master control is moving it to node 'P' (in the way "
        f"of acme/r1, order {orders[0]['orderId']!r}); it takes orders again once it is there"
    )
    assert fleet.separation.minimum_m >= SAFETY_M - TOLERANCE_M, fleet.separation


async def test_a_vehicle_out_of_service_on_the_route_is_not_moved_until_put_back(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """The same floor, r2 out of service on r1's only way: master control does not move it, r1
    waits for it before C; put back in service, r2 is sent to parking and r1 passes."""
    starts = {"r1": "A", "r2": "C"}
    async with running_fleet(
        embedded_broker, unique_interface_name, ONE_WAY_THROUGH, starts
    ) as fleet:
        r2 = "/vehicles/acme/r2"
        taken = await fleet.client.patch(r2, json={"inService": False, "note": "lidar"})
        assert taken.status_code == 200, taken.text
        through = await fleet.order("r1", "D")

        async def r1_waits_for_r2() -> bool:
            traffic = (await fleet.client.get("/traffic")).json()
            return any(v["waitingFor"] == ["acme/r2"] for v in traffic["vehicles"])

        async with asyncio.timeout(20):
            while not await r1_waits_for_r2():
                await asyncio.sleep(0.05)
        await asyncio.sleep(1.0)  # ten simulated seconds: ample time to send r2 away
        orders = (await fleet.client.get("/orders", params={"serialNumber": "r2"})).json()
        assert orders == []
        assert fleet.node_of("r2") == "C"
        assert (await fleet.status(through))["status"] != "FINISHED"

        back = await fleet.client.patch(r2, json={"inService": True})
        assert back.status_code == 200, back.text
        await fleet.wait_finished(through)
        orders = (await fleet.client.get("/orders", params={"serialNumber": "r2"})).json()
    assert fleet.node_of("r2") == "P"
    assert [o["note"].startswith("traffic:") for o in orders] == [True]
    assert fleet.separation.minimum_m >= SAFETY_M - TOLERANCE_M, fleet.separation


def _roundabout() -> dict[str, object]:
    """A one-way triangle ring R1→R2→R3→R1; at each ring node an entry spur S (in), an exit
    spur T (out) and a parking bay P (out and back), 5 m outwards."""
    ring = {"R1": (0.0, 0.0), "R2": (10.0, 0.0), "R3": (5.0, 8.66)}
    centre = (5.0, 2.887)
    positions = dict(ring)
    one_way = [("R1", "R2"), ("R2", "R3"), ("R3", "R1")]
    for name, (x, y) in ring.items():
        base = math.atan2(y - centre[1], x - centre[0])
        index = name[1]
        for spur, turn in (("S", -0.7), ("T", 0.0), ("P", 0.7)):
            angle = base + turn
            positions[f"{spur}{index}"] = (x + 5 * math.cos(angle), y + 5 * math.sin(angle))
        one_way += [(f"S{index}", name), (name, f"T{index}"), (name, f"P{index}")]
        one_way.append((f"P{index}", name))
    stations = {f"P{i}": "parking" for i in "123"}
    return graph_document(positions, one_way=tuple(one_way), stations=stations)


async def test_three_vehicle_cycle_is_resolved(
    embedded_broker: BrokerAddress, unique_interface_name: str
) -> None:
    """Three vehicles enter a one-way ring at once, each bound for the exit after the next ring
    node, which the next vehicle holds (a one-node release window makes each claim only its
    next node): they wait for each other in a cycle. Master control detects the deadlock, backs
    one vehicle off into its parking bay, and all three finish."""
    starts = {"v1": "S1", "v2": "S2", "v3": "S3"}
    async with running_fleet(
        embedded_broker, unique_interface_name, _roundabout(), starts, release_window_nodes=1
    ) as fleet:
        orders = [
            await fleet.order("v1", "T2"),
            await fleet.order("v2", "T3"),
            await fleet.order("v3", "T1"),
        ]
        await fleet.wait_finished(*orders, timeout=60)
        traffic = (await fleet.client.get("/traffic")).json()
    assert traffic["deadlocksResolved"] >= 1, traffic
    assert (fleet.node_of("v1"), fleet.node_of("v2"), fleet.node_of("v3")) == ("T2", "T3", "T1")
    assert fleet.separation.minimum_m >= SAFETY_M - TOLERANCE_M, fleet.separation
