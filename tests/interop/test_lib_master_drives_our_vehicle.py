"""A vda-5050-lib 1.4.0 MasterController drives our vehicle (``python -m vda_vehicle``, 2.0.0).

The library's master sends instant actions in its own 2.0 dialect (the array under the key
``instantActions``); our vehicle must understand it and still publish only schema-exact
messages, which the ``wire`` fixture checks against the official 2.0.0 schemas. Orders use the
nodes of ``graph.json``; the vehicle stands on n1 at (0, 0).
"""

from __future__ import annotations

import itertools
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.interop.node_lib import NodeRuntime
from tests.interop.peers import Event, LibMaster, Predicate, matching, running_lib_master
from tests.interop.services import graph_nodes, log_tail, map_id, running_our_vehicle
from tests.interop.wire import Side, schema_problems
from tests.mosquitto import Mosquitto
from tests.system.stack import Captured, ServiceProcess

pytestmark = pytest.mark.interop
OUR_SIDE = Side.VEHICLE
VEHICLE = {"manufacturer": "ours", "serialNumber": "vehicle_1"}
LOAD_PARAMETERS = [
    {"key": "stationType", "value": "floor"},
    {"key": "loadType", "value": "EPAL"},
]
#: 1.5 m/s × 10: an edge of 10 m takes 0.7 s, a pick or drop (1 s + 3 s) 0.4 s.
FAST = 10.0
#: 1.5 m/s × 2: an edge of 10 m takes 3.3 s, time enough to cancel in the middle of one.
SLOW = 2.0


@dataclass
class Rig:
    lib: LibMaster
    vehicle: ServiceProcess

    def vehicle_alive(self) -> None:
        if not self.vehicle.running:
            raise AssertionError("our vehicle exited" + log_tail(self.vehicle))

    async def wait(
        self,
        predicate: Predicate,
        timeout: float = 10.0,
        *,
        since: int = 0,
        fail_on: Predicate | None = None,
        what: str = "",
    ) -> Event:
        return await self.lib.peer.wait_for(
            predicate, timeout, since=since, fail_on=fail_on, what=what, check=self.vehicle_alive
        )

    async def run_order(self, order: dict[str, Any], timeout: float = 10.0) -> Event:
        """Assign ``order``; the library's order_processed event (AssertionError on an error)."""
        since = len(self.lib.peer.events)
        await self.lib.order(VEHICLE, order)
        order_id = order["orderId"]
        return await self.wait(
            matching("order_processed", orderId=order_id, error=None),
            timeout,
            since=since,
            fail_on=lambda e: e.get("orderId") == order_id and bool(e.get("error")),
            what=f"order {order_id} processed",
        )

    def states(self, since: int = 0) -> list[dict[str, Any]]:
        return [e["state"] for e in self.lib.peer.find(matching("state", agv=VEHICLE), since)]


@asynccontextmanager
async def rig_running(
    runtime: NodeRuntime,
    broker: Mosquitto,
    interface: str,
    logs: Path,
    *vehicle_flags: str,
    time_lapse: float,
) -> AsyncIterator[Rig]:
    """The library's master, then our vehicle, until the master has received its state."""
    async with (
        running_lib_master(runtime, broker_url=broker.address.url, interface_name=interface) as lib,
        running_our_vehicle(
            logs,
            *vehicle_flags,
            broker_url=broker.address.url,
            interface_name=interface,
            manufacturer=VEHICLE["manufacturer"],
            serial_number=VEHICLE["serialNumber"],
            time_lapse=time_lapse,
        ) as vehicle,
    ):
        rig = Rig(lib, vehicle)
        await rig.wait(
            matching("state", agv=VEHICLE),
            fail_on=matching("peer_error"),
            what="a state of our vehicle accepted by the library",
        )
        yield rig


def on_graph(start_node: str = "n1") -> tuple[str, ...]:
    return ("--graph", str(Path(__file__).with_name("graph.json")), "--start-node", start_node)


@pytest.fixture
async def rig(
    node_runtime: NodeRuntime,
    mosquitto: Mosquitto,
    unique_interface_name: str,
    wire: Captured,
    tmp_path: Path,
) -> AsyncIterator[Rig]:
    """The library's master and our vehicle on n1 of the interop graph (time lapse 10)."""
    async with rig_running(
        node_runtime, mosquitto, unique_interface_name, tmp_path, *on_graph(), time_lapse=FAST
    ) as running:
        yield running


def order_along(
    order_id: str, node_ids: list[str], actions: dict[str, list[dict[str, object]]] | None = None
) -> dict[str, Any]:
    """A fully released 2.0.0 order along ``node_ids`` (nodePosition on every node)."""
    actions = actions or {}
    nodes = [
        {
            "nodeId": node_id,
            "sequenceId": 2 * index,
            "released": True,
            "nodePosition": {
                "x": graph_nodes()[node_id][0],
                "y": graph_nodes()[node_id][1],
                "mapId": map_id(),
            },
            "actions": actions.get(node_id, []),
        }
        for index, node_id in enumerate(node_ids)
    ]
    edges = [
        {
            "edgeId": f"e{start[1:]}{end[1:]}",
            "sequenceId": 2 * index + 1,
            "released": True,
            "startNodeId": start,
            "endNodeId": end,
            "actions": [],
        }
        for index, (start, end) in enumerate(itertools.pairwise(node_ids))
    ]
    return {"orderId": order_id, "orderUpdateId": 0, "nodes": nodes, "edges": edges}


def load_action(action_type: str, action_id: str) -> dict[str, object]:
    return {
        "actionId": action_id,
        "actionType": action_type,
        "blockingType": "HARD",
        "actionParameters": LOAD_PARAMETERS,
    }


def instant_action_failed(action_id: str) -> Callable[[Event], bool]:
    def failed(event: Event) -> bool:
        if event.get("actionId") != action_id:
            return False
        return event["event"] == "instant_action_error" or event.get("actionStatus") == "FAILED"

    return failed


async def test_factsheet_and_state_requests_in_the_library_dialect_finish(
    rig: Rig, wire: Captured
) -> None:
    """factsheetRequest and stateRequest sent under the key ``instantActions`` both FINISH and
    a factsheet arrives that the library accepts."""
    since = len(rig.lib.peer.events)
    sent = await rig.lib.instant_actions(
        VEHICLE,
        [
            {"actionId": "fs-1", "actionType": "factsheetRequest", "blockingType": "NONE"},
            {"actionId": "sr-1", "actionType": "stateRequest", "blockingType": "NONE"},
        ],
    )
    assert "actions" not in sent["message"]  # the library's dialect, as the peer findings say
    for action_id in ("fs-1", "sr-1"):
        await rig.wait(
            matching("instant_action_state", actionId=action_id, actionStatus="FINISHED"),
            since=since,
            fail_on=instant_action_failed(action_id),
            what=f"instant action {action_id} FINISHED",
        )
    factsheet = await rig.wait(
        matching("factsheet", agv=VEHICLE),
        since=since,
        fail_on=matching("peer_error"),
        what="a factsheet after factsheetRequest",
    )
    assert factsheet["factsheet"]["version"] == "2.0.0"
    deviations = [p for p in schema_problems(wire) if p.topic.endswith("/instantActions")]
    assert deviations, "the library's instantActions were expected to break the 2.0.0 schema"
    assert all("'actions' is a required property" in p.text for p in deviations)


async def test_order_with_pick_and_drop_finishes(rig: Rig) -> None:
    """n1 → n2 (pick) → n3 (drop): both actions FINISHED, the order processed without error."""
    since = len(rig.lib.peer.events)
    order = order_along(
        "lib-order-1",
        ["n1", "n2", "n3"],
        {"n2": [load_action("pick", "pick-1")], "n3": [load_action("drop", "drop-1")]},
    )
    processed = await rig.run_order(order)
    assert not processed["byCancelation"]
    ended = {
        e["actionId"]: e["actionStatus"]
        for e in rig.lib.peer.find(matching("order_action_state", orderId="lib-order-1"), since)
    }
    assert ended == {"pick-1": "FINISHED", "drop-1": "FINISHED"}
    assert any(len(s.get("loads") or []) == 1 for s in rig.states(since))  # from n2 to n3
    last = processed["state"]
    assert last["lastNodeId"] == "n3"
    assert not last.get("loads")


async def test_cancel_in_the_library_dialect_ends_the_order(
    node_runtime: NodeRuntime,
    mosquitto: Mosquitto,
    unique_interface_name: str,
    wire: Captured,
    tmp_path: Path,
) -> None:
    """cancelOrder (under ``instantActions``) while driving n2 → n3 FINISHES and the library
    reports the order processed by cancellation."""
    async with rig_running(
        node_runtime, mosquitto, unique_interface_name, tmp_path, *on_graph(), time_lapse=SLOW
    ) as rig:
        since = len(rig.lib.peer.events)
        await rig.lib.order(VEHICLE, order_along("lib-order-2", ["n1", "n2", "n3", "n4"]))
        await rig.wait(
            matching("node_traversed", orderId="lib-order-2", nodeId="n2"),
            15.0,
            since=since,
            fail_on=lambda e: e.get("event") == "order_processed",
            what="node n2 traversed",
        )
        await rig.lib.cancel(VEHICLE, "cancel-1")
        await rig.wait(
            matching("instant_action_state", actionId="cancel-1", actionStatus="FINISHED"),
            since=since,
            fail_on=instant_action_failed("cancel-1"),
            what="cancelOrder FINISHED",
        )
        processed = await rig.wait(
            matching("order_processed", orderId="lib-order-2"), since=since, what="order ended"
        )
        assert processed["byCancelation"], processed
        assert processed["error"] is None
        last = processed["state"]
        assert not last["driving"]
        assert not last["nodeStates"]
        assert not last["edgeStates"]


async def test_vehicle_without_graph_takes_orders_on_the_map_named_by_map_id(
    node_runtime: NodeRuntime,
    mosquitto: Mosquitto,
    unique_interface_name: str,
    wire: Captured,
    tmp_path: Path,
) -> None:
    """``--map-id interop`` without a graph: the vehicle at (0, 0) takes the library's order on
    that map (n1 at (0, 0) → n2) and finishes it."""
    async with rig_running(
        node_runtime,
        mosquitto,
        unique_interface_name,
        tmp_path,
        "--map-id",
        map_id(),
        time_lapse=FAST,
    ) as rig:
        first = rig.states()[-1]
        assert first["agvPosition"]["mapId"] == map_id()
        processed = await rig.run_order(order_along("lib-order-3", ["n1", "n2"]))
        assert processed["state"]["lastNodeId"] == "n2"
        assert processed["state"]["agvPosition"]["x"] == pytest.approx(10.0, abs=0.3)
