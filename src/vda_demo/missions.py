"""What the demo asks of the fleet: missions as sequences of ``POST /orders`` bodies (pure)."""

from __future__ import annotations

import random
from dataclasses import dataclass, field

from pydantic import JsonValue

JsonObject = dict[str, JsonValue]

MANUFACTURER = "vda-sim"
#: The reference mission (issue 5): robot_0 drives 7 -(17)-> 1 -(12)-> 2 -(11)-> 10.
REFERENCE_ROUTE = ("17", "12", "11")


@dataclass
class Mission:
    """Orders one robot runs one after another; each must finish before the next is sent."""

    serial_number: str
    title: str
    steps: list[JsonObject]
    step: int = 0
    order_ids: list[str] = field(default_factory=list)

    @property
    def done(self) -> bool:
        return self.step >= len(self.steps)

    def next_body(self) -> JsonObject:
        """The ``POST /orders`` body of the current step, addressed to this robot."""
        return {
            "manufacturer": MANUFACTURER,
            "serialNumber": self.serial_number,
            **self.steps[self.step],
        }


def station_action(action_type: str) -> JsonObject:
    """A pick or drop at the destination; the master adds stationType/stationName."""
    return {
        "actionType": action_type,
        "blockingType": "HARD",
        "actionParameters": [{"key": "loadType", "value": "EPAL"}],
    }


def reference_mission() -> Mission:
    """robot_0 to node 10 via edges 17, 12, 11 (nodes 7, 1, 2, 10)."""
    return Mission("robot_0", "reference route 7 → 1 → 2 → 10", [{"route": list(REFERENCE_ROUTE)}])


def transport_mission(serial_number: str, pick_node: str, drop_node: str) -> Mission:
    """One order with two stops: drive to ``pick_node`` and pick, then to ``drop_node`` and
    drop (docs/master.md, *Orders with several stops*)."""
    stops: list[JsonValue] = [
        {"destination": pick_node, "actions": [station_action("pick")]},
        {"destination": drop_node, "actions": [station_action("drop")]},
    ]
    return Mission(serial_number, f"transport {pick_node} → {drop_node}", [{"stops": stops}])


#: The demo fleet on the warehouse: robot → its start node (north parking row).
ROBOT_STARTS = {"robot_0": "P1", "robot_1": "P2", "robot_2": "P3", "robot_3": "P4"}


def demo_missions() -> list[Mission]:
    """Four crossing transports on the warehouse: each robot picks in an aisle on the far side
    of the others and drops at a bay across the warehouse, so routes cross and aisles are
    shared."""
    return [
        transport_mission("robot_0", "H5", "DR1"),
        transport_mission("robot_1", "G2", "DR2"),
        transport_mission("robot_2", "B5", "DR4"),
        transport_mission("robot_3", "A2", "DR3"),
    ]


@dataclass(frozen=True, slots=True)
class Stations:
    """Node ids of the graph's pick and drop stations (chargers are master control's:
    docs/master.md, *Charging*)."""

    pick: tuple[str, ...]
    drop: tuple[str, ...]


def stations_of(graph: JsonObject) -> Stations:
    """Read station node ids from a graph file's JSON."""
    found: dict[str, list[str]] = {"pick": [], "drop": []}
    nodes = graph.get("nodes")
    for node in nodes if isinstance(nodes, list) else []:
        if isinstance(node, dict) and node.get("stationType") in found:
            found[str(node["stationType"])].append(str(node["nodeId"]))
    return Stations(tuple(found["pick"]), tuple(found["drop"]))


def next_mission(serial_number: str, stations: Stations, rng: random.Random) -> Mission:
    """A random transport for an idle robot in ``--forever`` mode (a low battery is master
    control's business: it sends the robot to charge between two transports)."""
    return transport_mission(serial_number, rng.choice(stations.pick), rng.choice(stations.drop))
