"""Our master control (``python -m vda_master``) drives two vda-5050-lib 1.4.0 virtual AGVs.

The AGVs speak VDA 5050 2.0.0 and publish no factsheet; they stand on nodes of ``graph.json``
(agv_1 on n1 at (0, 0), agv_2 on n4 at (20, 10)). Everything both sides publish is checked
against the official 2.0.0 schemas by the ``wire`` fixture: our master's orders and instant
actions must be exact.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.interop.node_lib import NodeRuntime
from tests.interop.peers import Event, Peer, matching, running_agvs
from tests.interop.services import (
    OurMaster,
    distance_to_nearest_node,
    graph_nodes,
    pose_at,
    running_our_master,
)
from tests.interop.wire import Side
from tests.mosquitto import Mosquitto
from tests.system.stack import Captured

pytestmark = pytest.mark.interop
OUR_SIDE = Side.MASTER
MANUFACTURER = "vdalib"
POSES = {"agv_1": pose_at("n1"), "agv_2": pose_at("n4")}
#: Pick and drop parameters the virtual AGV insists on: stationType "floor…", loadType "EPAL".
LOAD_PARAMETERS = [
    {"key": "stationType", "value": "floor"},
    {"key": "loadType", "value": "EPAL"},
]
#: 2 m/s × 10: an edge of 10 m takes 0.5 s, a pick or drop (1 s + 5 s) 0.6 s.
FAST = {"timeLapse": 10, "tickRate": 10}
#: 2 m/s × 3: an edge of 10 m takes 1.7 s, time enough to cancel in the middle of one.
SLOW = {"timeLapse": 3, "tickRate": 10}
AVAILABLE_WITHIN_S = 5.0


@dataclass
class Fleet:
    agvs: Peer
    master: OurMaster

    async def finish(self, order_id: str, timeout: float = 15.0) -> dict[str, Any]:
        """Wait for FINISHED; a failure also quotes what the AGVs reported as errors."""
        return await self.expect(order_id, "FINISHED", timeout)

    async def expect(self, order_id: str, status: str, timeout: float = 15.0) -> dict[str, Any]:
        try:
            return await self.master.wait_order(order_id, status, timeout)
        except AssertionError as exc:
            errors = [e["error"] for e in self.agvs.find(matching("error_reported"))]
            raise AssertionError(f"{exc}\n--- errors the AGVs reported: {errors}") from None

    def last_state(self, serial: str) -> dict[str, Any]:
        states = self.agvs.find(matching("state", serialNumber=serial))
        assert states, f"{serial} published no state"
        return dict(states[-1]["state"])

    async def settled(
        self, serial: str, node_id: str, *, loads: int | None = None, since: int = 0
    ) -> dict[str, Any]:
        """The AGV's first state from ``since`` on that has it standing still on ``node_id``
        (carrying ``loads`` loads, when given); the master may report FINISHED a moment before
        the peer's line about the same state is read."""

        def settled_there(event: Event) -> bool:
            if event.get("event") != "state" or event.get("serialNumber") != serial:
                return False
            state = event["state"]
            return at_node(state, node_id) and (
                loads is None or len(state.get("loads") or []) == loads
            )

        event = await self.agvs.wait_for(
            settled_there, 3.0, since=since, what=f"{serial} standing on {node_id}"
        )
        return dict(event["state"])

    def nodes_reached(self, serial: str, since: int = 0) -> list[str]:
        return [
            e["nodeId"]
            for e in self.agvs.find(matching("node_reached", serialNumber=serial), since)
        ]


@asynccontextmanager
async def fleet_running(
    runtime: NodeRuntime, broker: Mosquitto, interface: str, logs: Path, **options: object
) -> AsyncIterator[Fleet]:
    """The two virtual AGVs, then our master, until both AGVs are available."""
    async with (
        running_agvs(
            runtime,
            broker_url=broker.address.url,
            interface_name=interface,
            manufacturer=MANUFACTURER,
            poses=POSES,
            **options,
        ) as agvs,
        running_our_master(logs, broker_url=broker.address.url, interface_name=interface) as master,
    ):
        await master.wait_available(POSES, timeout=10.0)
        yield Fleet(agvs, master)


@pytest.fixture
async def fleet(
    node_runtime: NodeRuntime,
    mosquitto: Mosquitto,
    unique_interface_name: str,
    wire: Captured,
    tmp_path: Path,
) -> AsyncIterator[Fleet]:
    """Both AGVs (time lapse 10) and our master, both AGVs available."""
    async with fleet_running(
        node_runtime, mosquitto, unique_interface_name, tmp_path, **FAST
    ) as running:
        yield running


def agv(serial: str) -> dict[str, str]:
    return {"manufacturer": MANUFACTURER, "serialNumber": serial}


def at_node(state: dict[str, Any], node_id: str) -> bool:
    x, y = graph_nodes()[node_id]
    position = state.get("agvPosition") or {}
    near = abs(position.get("x", 1e9) - x) < 0.01 and abs(position.get("y", 1e9) - y) < 0.01
    return near and state.get("lastNodeId") == node_id and not state.get("driving")


async def test_agvs_that_connected_first_are_available_within_5_s_of_the_master_start(
    node_runtime: NodeRuntime,
    mosquitto: Mosquitto,
    unique_interface_name: str,
    wire: Captured,
    tmp_path: Path,
) -> None:
    """AGVs online before the master (their first state reached nobody, their heartbeat is
    30 s away) are listed available within 5 s of the master's start."""
    async with running_agvs(
        node_runtime,
        broker_url=mosquitto.address.url,
        interface_name=unique_interface_name,
        manufacturer=MANUFACTURER,
        poses=POSES,
        stateIntervalS=30,
        **FAST,
    ):
        await asyncio.sleep(0.3)  # their start-up states are gone before the master subscribes
        async with running_our_master(
            tmp_path, broker_url=mosquitto.address.url, interface_name=unique_interface_name
        ) as master:
            elapsed = await master.wait_available(POSES, timeout=AVAILABLE_WITHIN_S)
            vehicles = {v["serialNumber"]: v for v in await master.vehicles()}
    assert elapsed <= AVAILABLE_WITHIN_S
    assert {vehicles[s]["lastNodeId"] for s in POSES} == {"n1", "n4"}
    assert all(vehicles[s]["version"] == "2.0.0" for s in POSES)


async def test_shortest_path_orders_to_both_agvs_finish(fleet: Fleet) -> None:
    """Two destination orders run at once and each AGV ends on its destination node."""
    first = await fleet.master.order(**agv("agv_1"), destination="n3")
    second = await fleet.master.order(**agv("agv_2"), destination="n6")
    await fleet.finish(first["orderId"])
    await fleet.finish(second["orderId"])
    await fleet.settled("agv_1", "n3")
    await fleet.settled("agv_2", "n6")
    assert fleet.nodes_reached("agv_1")[-3:] == ["n1", "n2", "n3"]
    assert fleet.nodes_reached("agv_2")[-3:] == ["n4", "n5", "n6"]


async def test_explicit_route_is_driven_edge_by_edge(fleet: Fleet) -> None:
    """A route of edge ids (the long way round) is driven exactly as given."""
    created = await fleet.master.order(**agv("agv_1"), route=["e16", "e65", "e52"])
    await fleet.finish(created["orderId"])
    await fleet.settled("agv_1", "n2")
    assert fleet.nodes_reached("agv_1")[-4:] == ["n1", "n6", "n5", "n2"]


async def test_order_without_a_vehicle_goes_to_the_nearest_agv(fleet: Fleet) -> None:
    """No vehicle named: the master picks agv_2 (10 m from n3; agv_1 is 20 m away)."""
    created = await fleet.master.order(destination="n3")
    assert (created["manufacturer"], created["serialNumber"]) == (MANUFACTURER, "agv_2")
    await fleet.finish(created["orderId"])
    await fleet.settled("agv_2", "n3")


async def test_pick_then_drop_moves_a_load(fleet: Fleet) -> None:
    """A pick at n6 loads the AGV, a drop at n3 unloads it; both orders finish. The drop
    names no vehicle: master control sends it to the one that reports the load, agv_1 (30 m
    from n3), not agv_2 (10 m; docs/master.md, *Loads*)."""
    pick = await fleet.master.order(
        **agv("agv_1"),
        destination="n6",
        destinationActions=[{"actionType": "pick", "actionParameters": LOAD_PARAMETERS}],
    )
    await fleet.finish(pick["orderId"])
    picked = await fleet.settled("agv_1", "n6", loads=1)
    listed = {v["serialNumber"]: v for v in await fleet.master.vehicles()}
    assert listed["agv_1"]["loads"] == picked["loads"]  # GET /vehicles shows what it carries
    drop = await fleet.master.order(
        destination="n3",
        destinationActions=[{"actionType": "drop", "actionParameters": LOAD_PARAMETERS}],
    )
    assert drop["serialNumber"] == "agv_1"
    await fleet.finish(drop["orderId"])
    await fleet.settled("agv_1", "n3", loads=0)
    ended = {
        e["actionType"]: e["actionStatus"]
        for e in fleet.agvs.find(matching("action_state", serialNumber="agv_1"))
        if e["actionType"] in {"pick", "drop"}
    }
    assert ended == {"pick": "FINISHED", "drop": "FINISHED"}


async def test_cancel_mid_edge_then_a_follow_up_order_finishes(
    node_runtime: NodeRuntime,
    mosquitto: Mosquitto,
    unique_interface_name: str,
    wire: Captured,
    tmp_path: Path,
) -> None:
    """DELETE while the AGV drives n2 → n3: CANCELLED, it stops between the nodes (as
    vda-5050-lib does), and the next order to it is accepted and finishes without manual steps."""
    async with fleet_running(
        node_runtime, mosquitto, unique_interface_name, tmp_path, **SLOW
    ) as fleet:
        created = await fleet.master.order(**agv("agv_1"), destination="n3")
        await fleet.agvs.wait_for(
            lambda e: _driving_from(e, "agv_1", "n2"),
            10.0,
            fail_on=matching("error_reported", serialNumber="agv_1", topic="order"),
            what="agv_1 driving away from n2",
        )
        await asyncio.sleep(0.8)  # about half of edge n2 → n3
        cancelling = await fleet.master.cancel(created["orderId"])
        await fleet.expect(created["orderId"], "CANCELLED", timeout=10.0)
        cancelled = await fleet.agvs.wait_for(
            matching(
                "action_state", actionId=cancelling["cancelActionId"], actionStatus="FINISHED"
            ),
            3.0,
            what="cancelOrder FINISHED by agv_1",
        )
        stopped = fleet.last_state("agv_1")  # published with the cancelOrder's FINISHED
        assert cancelled["serialNumber"] == "agv_1"
        position = stopped["agvPosition"]
        assert not stopped["driving"]
        assert distance_to_nearest_node(position["x"], position["y"]) > 1.0, position
        since = len(fleet.agvs.events)
        follow_up = await fleet.master.order(**agv("agv_1"), destination="n1")
        await fleet.finish(follow_up["orderId"], timeout=20.0)
        await fleet.settled("agv_1", "n1", since=since)
        assert fleet.nodes_reached("agv_1", since)[-1] == "n1"


def _driving_from(event: Event, serial: str, node_id: str) -> bool:
    if event.get("event") != "state" or event.get("serialNumber") != serial:
        return False
    state = event["state"]
    return bool(state.get("driving")) and state.get("lastNodeId") == node_id


async def test_an_order_with_stops_meets_the_library_s_stitching_defect_and_says_so(
    fleet: Fleet,
) -> None:
    """``stops`` (docs/master.md, *Orders with several stops*): the AGV gets the way to n6 with
    the pick; once the pick is FINISHED, the way on to n3 with the drop follows by an order
    update whose stitching node is n6, with its actions as first sent (R58). vda-5050-lib
    1.4's AGV runs the stitching node's pick again (R51: it must not), which fails ("load
    already picked"), so the order ends FAILED with the AGV's words. Master control notices,
    refuses further orders with stops for that AGV (422, saying why); orders with one
    destination still go to it."""
    two_stops = [
        {
            "destination": "n6",
            "actions": [{"actionType": "pick", "actionParameters": LOAD_PARAMETERS}],
        },
        {
            "destination": "n3",
            "actions": [{"actionType": "drop", "actionParameters": LOAD_PARAMETERS}],
        },
    ]
    created = await fleet.master.order(**agv("agv_1"), stops=two_stops)
    assert created["destination"] == "n6"
    failed = await fleet.expect(created["orderId"], "FAILED")
    assert failed["orderUpdateId"] >= 1  # the drop was appended
    assert "load already picked" in failed["reason"]
    answer = await fleet.master.http.post(
        f"{fleet.master.api}/orders", json={**agv("agv_1"), "stops": two_stops}
    )
    assert answer.status_code == 422
    assert (
        "ran the actions of the node an order update starts at again (R51"
        in (answer.json()["detail"])
    )
    await fleet.master.wait_available(["agv_1"], timeout=10.0)  # it drove the rest itself
    single = await fleet.master.order(**agv("agv_1"), destination="n1")
    await fleet.finish(single["orderId"])
    await fleet.settled("agv_1", "n1")
