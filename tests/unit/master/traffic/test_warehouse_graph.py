"""The shipped warehouse graph: loadable, the right size, one-lane aisles, two-way corridors."""

from __future__ import annotations

import json
from collections import Counter

from tests.unit.master.traffic.floors import warehouse_generator
from vda_master.traffic.conflicts import build_conflicts, edge, node
from vda_master.traffic.paths import build_roadmap, distances
from vda_master.traffic.testing import SIM_SAFETY_M, WAREHOUSE_GRAPH, warehouse_graph

GRAPH = warehouse_graph()  # load_graph: schema and semantic checks
CONFLICTS = build_conflicts(GRAPH, SIM_SAFETY_M)


def test_file_is_the_generator_output() -> None:
    """The committed graph is exactly what scripts/make_warehouse_graph.py produces."""
    module = warehouse_generator()
    assert json.loads(WAREHOUSE_GRAPH.read_text(encoding="utf-8")) == module.build()


def test_size_and_stations() -> None:
    """60–150 nodes with pick, drop, parking and charging stations, each named."""
    assert 60 <= len(GRAPH.nodes) <= 150
    types = Counter(n.station_type for n in GRAPH.nodes.values() if n.station_type)
    assert types == {"pick": 16, "drop": 4, "parking": 6, "charging": 3}
    assert all(n.station_name == n.node_id for n in GRAPH.nodes.values() if n.station_type)


def test_every_node_reaches_every_other() -> None:
    """The graph is strongly connected: any vehicle can be sent anywhere."""
    roads = build_roadmap(GRAPH)
    forward, _ = distances(roads, "SO0")
    backward, _ = distances(roads, "SO0", reverse=True)
    assert set(forward) == set(backward) == set(GRAPH.nodes)


def test_aisles_are_one_lane_and_corridors_two_parallel_lanes() -> None:
    """Aisle edges run both ways on one lane; the ring's lanes are one-way and 3 m apart, so a
    vehicle on the outer lane never conflicts with one on the inner lane."""
    assert CONFLICTS.is_one_lane("A2-A3")
    assert CONFLICTS.conflict(edge("A2-A3"), edge("A3-A2"))
    assert not CONFLICTS.is_one_lane("SO1-SO1m")
    assert "SO1m-SO1" not in GRAPH.edges
    assert not CONFLICTS.conflict(edge("SO1-SO1m"), edge("SI1m-SI1"))
    assert not CONFLICTS.conflict(edge("NI3-NI3m"), edge("NO3m-NO3"))


def test_no_two_nodes_are_closer_than_the_safety_distance() -> None:
    """Vehicles standing on any two different nodes are safely apart (parking included)."""
    close = [
        (a, b)
        for a in GRAPH.nodes
        for b in GRAPH.nodes
        if a < b and CONFLICTS.conflict(node(a), node(b))
    ]
    assert close == []


def test_every_aisle_has_a_passing_place_apart_from_both_ways_through() -> None:
    """In every aisle the way north goes round a passing place beside position 4, the way south
    straight on: a vehicle standing there conflicts with nothing of its aisle's way south nor
    of the next aisle, so vehicles meeting in an aisle pass there; the rest of the aisle is
    one lane."""
    for aisle in "ABCDEFGH":
        place = node(f"{aisle}p")
        assert f"{aisle}4" not in GRAPH.nodes
        assert not CONFLICTS.is_one_lane(f"{aisle}5-{aisle}3")
        assert not CONFLICTS.conflict(place, edge(f"{aisle}5-{aisle}3"))
        assert CONFLICTS.is_one_lane(f"{aisle}2-{aisle}3")
        assert CONFLICTS.is_one_lane(f"{aisle}5-{aisle}6")
    assert not CONFLICTS.conflict(node("Ap"), edge("B5-B3"))
    assert not CONFLICTS.conflict(node("Ap"), edge("B3-Bp"))
