"""The searches of traffic decisions give what a search over the whole map gives (issue 9 §3):
detours (A* towards the destination), the nearest node of a kind, and parking places for idle
vehicles (one search per idle vehicle, shared by every vehicle it stands in the way of)."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from vda5050.topics import AgvId
from vda_master.traffic.conflicts import Resource, build_conflicts, edge, node
from vda_master.traffic.paths import (
    build_roadmap,
    distances,
    nearest_first,
    path_to,
    route_avoiding,
)
from vda_master.traffic.reservations import ReservationTable
from vda_master.traffic.testing import SIM_SAFETY_M, agv, warehouse_graph
from vda_master.traffic.waits import ParkingSearch, propose_parking

GRAPH = warehouse_graph()
ROADS = build_roadmap(GRAPH, one_lane_factor=3.0)
CONFLICTS = build_conflicts(GRAPH, SIM_SAFETY_M)
NODES = sorted(GRAPH.nodes)
pick = st.sampled_from(NODES)


def _cost(route_edges: tuple[str, ...]) -> float:
    return sum(ROADS.cost[e] for e in route_edges)


@settings(max_examples=200, deadline=None)
@given(pick, pick, st.sets(pick, max_size=12))
def test_a_detour_is_as_cheap_as_the_cheapest_way_round(
    start: str, destination: str, blocked: set[str]
) -> None:
    """Avoiding what vehicles standing on random nodes hold (conflicts included), the detour
    costs what a search of the whole map finds, uses nothing avoided, and is missing exactly
    when there is no way round."""
    avoid = CONFLICTS.closure(node(n) for n in blocked if n != start)

    def allowed(edge_id: str, next_node: str) -> bool:
        return edge(edge_id) not in avoid and node(next_node) not in avoid

    reach, _ = distances(ROADS, start, allowed=allowed)
    route = route_avoiding(ROADS, start, destination, avoid)
    if destination not in reach:
        assert route is None
        return
    assert route is not None
    assert route.node_ids[0] == start
    assert route.node_ids[-1] == destination
    assert math.isclose(_cost(route.edge_ids), reach[destination], abs_tol=1e-9)
    assert not any(edge(e) in avoid for e in route.edge_ids)
    assert not any(node(n) in avoid for n in route.node_ids[1:])


@given(pick)
def test_nodes_come_nearest_first_and_equally_near_ones_by_id(origin: str) -> None:
    reach, _ = distances(ROADS, origin)
    via: dict[str, str] = {}
    ordered = list(nearest_first(ROADS, origin, via=via))
    assert ordered == sorted(reach, key=lambda n: (reach[n], n))
    far = ordered[-1]
    assert math.isclose(_cost(path_to(ROADS, origin, far, via).edge_ids), reach[far])


def _parking_by_definition(
    table: ReservationTable, agv_id: AgvId, at_node: str, way: frozenset[Resource], taken: set[str]
) -> str | None:
    """The nearest free parking node off the way and not taken, else the nearest such node
    without a stationType: every node of the map looked at, nearest first."""
    reach, _ = distances(ROADS, at_node)

    def usable(n: str) -> bool:
        return (
            n != at_node
            and n not in taken
            and node(n) not in way
            and table.is_free(agv_id, (node(n),))
        )

    ordered = sorted(reach, key=lambda n: (reach[n], n))
    parking = set(ROADS.station_nodes("parking"))
    found = next((n for n in ordered if n in parking and usable(n)), None)
    plain = (n for n in ordered if GRAPH.nodes[n].station_type is None and usable(n))
    return found if found is not None else next(plain, None)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(pick, min_size=1, max_size=40, unique=True),
    st.sets(pick, max_size=20),
    st.sets(pick, max_size=8),
)
def test_idle_vehicles_are_sent_where_a_look_at_the_whole_map_would_send_them(
    standing: list[str], way_nodes: set[str], taken: set[str]
) -> None:
    """Up to 40 vehicles stand on random nodes (parking ones filling up); each is sent, from
    one search shared by all, where looking at every node would send it."""
    table = ReservationTable(CONFLICTS)
    vehicles = [(agv(f"v{i:02}"), n) for i, n in enumerate(standing)]
    for vehicle, at_node in vehicles:
        claimed = table.claim(vehicle, [node(at_node)])
        if isinstance(claimed, ReservationTable):
            table = claimed
    way = CONFLICTS.closure(node(n) for n in way_nodes)
    search = ParkingSearch(ROADS, table)
    for vehicle, at_node in vehicles:
        for shared in (search, None):
            move = propose_parking(
                ROADS, table, vehicle, at_node, way=way, taken=taken, reason="t", search=shared
            )
            expected = _parking_by_definition(table, vehicle, at_node, way, taken)
            assert (move.node_id if move else None) == expected
            if move is not None:
                assert move.route.node_ids[0] == at_node
                assert move.route.node_ids[-1] == expected
