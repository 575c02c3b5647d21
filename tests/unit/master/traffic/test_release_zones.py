"""RELEASE zones in traffic control: one vehicle at a time, entered only when the way through
and out is free (3.0 §6.4.1.1; docs/traffic.md, Release zones)."""

from __future__ import annotations

from vda_master.graph import Graph, build_graph
from vda_master.traffic.conflicts import build_conflicts, edge, node
from vda_master.traffic.controller import OnRoute, TrafficController
from vda_master.traffic.gate import decide_release_end, route_resources
from vda_master.traffic.reservations import ReservationTable
from vda_master.traffic.testing import SIM_SAFETY_M, agv, route_through

R1, R2 = agv("r1"), agv("r2")


def _floor(*, release: bool = True) -> Graph:
    """An east-bound lane W0 … E3 along y = 0 whose middle (x 3 … 13: W1, C, E1) is a RELEASE
    zone, and a north-bound lane S0 … N2 crossing it at C."""
    positions = {
        "W0": (0, 0), "W1": (4, 0), "C": (8, 0), "E1": (12, 0), "E2": (16, 0), "E3": (20, 0),
        "S0": (8, -8), "S1": (8, -4), "N1": (8, 4), "N2": (8, 8),
    }  # fmt: skip
    pairs = [("W0", "W1"), ("W1", "C"), ("C", "E1"), ("E1", "E2"), ("E2", "E3")]
    pairs += [("S0", "S1"), ("S1", "C"), ("C", "N1"), ("N1", "N2")]
    zones = [
        {
            "zoneId": "strip",
            "zoneType": "RELEASE",
            "vertices": [
                {"x": 3, "y": -1},
                {"x": 13, "y": -1},
                {"x": 13, "y": 1},
                {"x": 3, "y": 1},
            ],
        }
    ]
    document = {
        "mapId": "test",
        "nodes": [{"nodeId": n, "x": x, "y": y} for n, (x, y) in positions.items()],
        "edges": [{"edgeId": f"{a}-{b}", "startNodeId": a, "endNodeId": b} for a, b in pairs],
        "zones": zones if release else [],
    }
    return build_graph(document, source="test")


def test_what_reaches_into_a_release_zone_all_conflicts() -> None:
    """Nodes 8 m apart in the zone conflict (no geometry would make them), and so do the edges
    that lead in and the crossing lane's edges within a body's reach; what lies further than
    half the safety distance away does not."""
    graph = _floor()
    conflicts = build_conflicts(graph.unzoned(), SIM_SAFETY_M, graph.release_zones)
    group = conflicts.release_zones["strip"]
    assert {node("W1"), node("C"), node("E1"), edge("W0-W1"), edge("S1-C")} <= group
    assert node("W0") not in group  # 3 m from the zone: farther than 1.69 / 2
    assert node("S1") not in group
    assert conflicts.conflict(node("W1"), node("E1"))
    assert not build_conflicts(graph.unzoned(), SIM_SAFETY_M).conflict(node("W1"), node("E1"))
    assert conflicts.release_nodes == frozenset({"W1", "C", "E1"})


def test_the_base_goes_through_the_zone_and_out_or_stops_before_it() -> None:
    """A base never ends inside the zone: released into it, it runs through to the first node
    past it; a route that ends inside may end there."""
    graph = _floor()
    table = ReservationTable(build_conflicts(graph.unzoned(), SIM_SAFETY_M, graph.release_zones))
    east = route_through(graph, "W0", "W1", "C", "E1", "E2", "E3")
    grant = decide_release_end(table, R1, east, progress=0, released_end=0, desired_end=1)
    assert east.node_ids[grant.end] == "E2"
    into = route_through(graph, "W0", "W1", "C")
    grant = decide_release_end(table, R1, into, progress=0, released_end=0, desired_end=1)
    assert into.node_ids[grant.end] == "C"


def test_a_second_vehicle_waits_before_the_zone_until_the_first_is_out() -> None:
    """While R1's base runs through the zone, R2 on the crossing lane is held at S1, outside
    the zone; the zone names R1 as its holder. Once R1 has left it, R2 goes through."""
    graph = _floor()
    controller = TrafficController.for_graph(graph, SIM_SAFETY_M)
    east = route_through(graph, "W0", "W1", "C", "E1", "E2", "E3")
    north = route_through(graph, "S0", "S1", "C", "N1", "N2")
    controller = controller.assign(R1, east, 0.0)
    controller = controller.assign(R2, north, 0.0)
    controller, first = controller.request_release(
        R1, east, progress_index=0, released_end=0, desired_end=1, now=0.0
    )
    assert east.node_ids[first.end] == "E2"
    assert controller.release_zone_holders("strip") == frozenset({R1})
    controller, second = controller.request_release(
        R2, north, progress_index=0, released_end=0, desired_end=3, now=0.0
    )
    assert north.node_ids[second.end] == "S1"
    assert second.blocked is not None
    assert second.blocked.holders == frozenset({R1})

    e2 = east.node_ids.index("E2")
    controller, _ = controller.observe(R1, OnRoute(e2), 10.0)
    assert controller.release_zone_holders("strip") == frozenset()
    controller, second = controller.request_release(
        R2, north, progress_index=1, released_end=1, desired_end=2, now=10.0
    )
    assert north.node_ids[second.end] == "N1"  # through the zone and out, not onto C
    assert controller.release_zone_holders("strip") == frozenset({R2})


def test_without_the_zone_the_same_floor_lets_both_go() -> None:
    """The check the tests above rest on: the two lanes cross at C only, so without the zone
    R1 waiting at W1 and R2 passing C northwards at the same time is fine geometry-wise."""
    graph = _floor(release=False)
    table = ReservationTable(build_conflicts(graph.unzoned(), SIM_SAFETY_M))
    east = route_through(graph, "W0", "W1")
    claimed = table.claim(R1, route_resources(east, 0, 1))
    assert isinstance(claimed, ReservationTable)
    north = route_through(graph, "S1", "C", "N1")
    assert claimed.is_free(R2, route_resources(north, 0, 2))
