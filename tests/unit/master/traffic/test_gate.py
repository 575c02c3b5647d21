"""The release gate: bases extend only over free resources and never end inside a one-lane
stretch (issue 9 §2, §3)."""

from __future__ import annotations

from tests.unit.master.traffic.floors import one_lane_aisles_warehouse
from vda5050.topics import AgvId
from vda_master.routing import Route
from vda_master.traffic.conflicts import build_conflicts, edge, node
from vda_master.traffic.gate import (
    decide_release_end,
    is_waiting_node,
    next_waiting_index,
    route_resources,
)
from vda_master.traffic.reservations import ReservationTable
from vda_master.traffic.testing import SIM_SAFETY_M, agv, make_graph, route_through, warehouse_graph

R1, R2 = agv("r1"), agv("r2")
#: aisle A one lane end to end, as the aisles' stretches these tests follow need
WAREHOUSE = one_lane_aisles_warehouse()
#: the floor as shipped: its aisles have passing places
SHIPPED = warehouse_graph()
NORTHBOUND = route_through(
    WAREHOUSE, "WO1", "SO0", "SO1", "SI1", "A1", "A2", "A3", "A4", "A5", "A6", "NI1", "NI1m", "NI2"
)
SOUTHBOUND = route_through(
    WAREHOUSE, "NO1m", "NO1", "NI1", "A6", "A5", "A4", "A3", "A2", "A1", "SI1", "SI0"
)


def _holding(
    table: ReservationTable, vehicle: AgvId, route: Route, first: int, last: int
) -> ReservationTable:
    claimed = table.claim(vehicle, route_resources(route, first, last))
    assert isinstance(claimed, ReservationTable)
    return claimed


def test_a_one_lane_aisle_is_released_through_to_its_end_and_the_exit_when_near() -> None:
    """Entering aisle A, the base runs through the whole aisle, beyond the release window, to
    its last node; the lane node of the exit is released (and held) only once the vehicle is
    within the window of it, not for the whole way through the aisle."""
    table = ReservationTable(build_conflicts(WAREHOUSE, SIM_SAFETY_M))
    grant = decide_release_end(table, R1, NORTHBOUND, progress=0, released_end=0, desired_end=3)
    assert grant.blocked is None
    assert NORTHBOUND.node_ids[grant.end] == "A6"
    a4 = NORTHBOUND.node_ids.index("A4")
    grant = decide_release_end(
        table, R1, NORTHBOUND, progress=a4, released_end=grant.end, desired_end=a4 + 3
    )
    assert NORTHBOUND.node_ids[grant.end] == "NI1"


def test_head_on_the_second_vehicle_is_not_released_into_the_aisle() -> None:
    """With one vehicle in aisle A, one coming the other way is not released into it, and waits
    before the aisle's entry node, leaving that node free for the first one to leave by."""
    table = ReservationTable(build_conflicts(WAREHOUSE, SIM_SAFETY_M))
    table = _holding(table, R1, NORTHBOUND, 0, NORTHBOUND.node_ids.index("NI1"))
    grant = decide_release_end(table, R2, SOUTHBOUND, progress=0, released_end=0, desired_end=3)
    assert grant.end == 0
    assert grant.blocked is not None
    assert grant.blocked.refused.holder == R1
    assert grant.blocked.holders == {R1}
    assert grant.blocked.step_end == SOUTHBOUND.node_ids.index("A1")


def test_head_on_the_aisle_opens_once_the_first_vehicle_has_left() -> None:
    """Once the first vehicle holds only nodes beyond the aisle, the second one goes through."""
    table = ReservationTable(build_conflicts(WAREHOUSE, SIM_SAFETY_M))
    table = _holding(
        table, R1, NORTHBOUND, len(NORTHBOUND.node_ids) - 1, len(NORTHBOUND.node_ids) - 1
    )  # on NI2
    grant = decide_release_end(table, R2, SOUTHBOUND, progress=0, released_end=0, desired_end=3)
    assert grant.blocked is None
    assert SOUTHBOUND.node_ids[grant.end] == "A1"


def _lane(count: int) -> tuple[ReservationTable, Route]:
    positions = {f"x{i}": (3.0 * i, 0.0) for i in range(count)}
    graph = make_graph(positions, one_way=[(f"x{i}", f"x{i + 1}") for i in range(count - 1)])
    table = ReservationTable(build_conflicts(graph, SIM_SAFETY_M))
    return table, route_through(graph, *positions)


def test_following_on_one_lane_stops_one_node_behind_the_leader() -> None:
    """A follower on a one-way lane is released up to the node just behind what the leader holds."""
    table, lane = _lane(8)
    table = _holding(table, R1, lane, 3, 5)
    grant = decide_release_end(table, R2, lane, progress=0, released_end=0, desired_end=5)
    assert grant.end == 2
    assert grant.blocked is not None
    assert grant.blocked.refused.wanted == edge("x2-x3")
    assert grant.blocked.refused.held == node("x3")


def test_release_stops_at_the_desired_end_and_never_shrinks() -> None:
    """On a free lane the base grows to the desired end; a smaller desired end keeps it."""
    table, lane = _lane(8)
    assert decide_release_end(table, R1, lane, progress=0, released_end=0, desired_end=3).end == 3
    assert decide_release_end(table, R1, lane, progress=1, released_end=4, desired_end=2).end == 4
    assert decide_release_end(table, R1, lane, progress=0, released_end=0, desired_end=99).end == 7


def test_a_crossing_is_taken_by_one_vehicle_at_a_time() -> None:
    """At a crossing held by one vehicle, the other is released only up to the node before it."""
    graph = make_graph(
        {"w": (0, 6), "w1": (3, 6), "x": (6, 6), "e": (9, 6), "s": (6, 0), "s1": (6, 3),
         "n": (6, 9)},
        one_way=[("w", "w1"), ("w1", "x"), ("x", "e"), ("s", "s1"), ("s1", "x"), ("x", "n")],
    )  # fmt: skip
    table = ReservationTable(build_conflicts(graph, SIM_SAFETY_M))
    east = route_through(graph, "w", "w1", "x", "e")
    north = route_through(graph, "s", "s1", "x", "n")
    table = _holding(table, R1, east, 1, 3)
    grant = decide_release_end(table, R2, north, progress=0, released_end=0, desired_end=3)
    assert grant.end == 1
    assert grant.blocked is not None
    assert grant.blocked.refused.wanted == edge("s1-x")


def test_waiting_nodes_are_where_the_route_does_not_continue_one_lane() -> None:
    """Inside aisle A and on the crossings to it no node is a waiting node; the lane nodes
    before and after are."""
    conflicts = build_conflicts(WAREHOUSE, SIM_SAFETY_M)
    waiting = [
        NORTHBOUND.node_ids[i]
        for i in range(len(NORTHBOUND.node_ids))
        if is_waiting_node(conflicts, NORTHBOUND, i)
    ]
    assert waiting == ["WO1", "SO0", "NI1", "NI1m", "NI2"]
    assert next_waiting_index(conflicts, NORTHBOUND, 2) == NORTHBOUND.node_ids.index("NI1")


def test_route_resources_alternate_nodes_and_edges() -> None:
    """Resources of a route stretch: node, edge, node, … in driving order."""
    _, lane = _lane(4)
    assert route_resources(lane, 1, 2) == [node("x1"), edge("x1-x2"), node("x2")]
    assert route_resources(lane, 3, 3) == [node("x3")]


def test_leaving_an_aisle_onto_a_taken_lane_node_waits_at_the_aisles_end() -> None:
    """Only the lane node at the aisle's exit is taken: the vehicle is released through the
    aisle to its last node and waits there, instead of holding the lane node before the aisle
    (and every vehicle on the lane behind it) for the whole way through."""
    table = ReservationTable(build_conflicts(WAREHOUSE, SIM_SAFETY_M))
    table = _holding(table, R2, route_through(WAREHOUSE, "NI1"), 0, 0)
    everything = len(NORTHBOUND.edge_ids)
    grant = decide_release_end(
        table, R1, NORTHBOUND, progress=0, released_end=0, desired_end=everything
    )
    assert NORTHBOUND.node_ids[grant.end] == "A6"
    assert grant.blocked is not None
    assert grant.blocked.holders == {R2}
    assert NORTHBOUND.node_ids[grant.blocked.step_end] == "NI1"


def test_a_vehicle_waiting_at_an_aisles_end_keeps_the_opposing_one_out() -> None:
    """The vehicle waiting on A6 for the exit stands inside the aisle (it holds nothing else):
    one coming the other way is not released onto the exit, nor into the aisle."""
    table = ReservationTable(build_conflicts(WAREHOUSE, SIM_SAFETY_M))
    at_a6 = NORTHBOUND.node_ids.index("A6")
    table = _holding(table, R1, NORTHBOUND, at_a6, at_a6)
    grant = decide_release_end(table, R2, SOUTHBOUND, progress=0, released_end=0, desired_end=3)
    assert grant.end == 0
    assert grant.blocked is not None
    assert grant.blocked.holders == {R1}


def test_no_wait_inside_an_aisle_short_of_a_taken_destination_or_on_its_first_node() -> None:
    """A destination inside the aisle that another vehicle stands on keeps the vehicle before
    the aisle (the one standing there may leave towards it); and with the exit right after the
    crossing's first node there is no last node inside the stretch to wait on."""
    table = ReservationTable(build_conflicts(WAREHOUSE, SIM_SAFETY_M))
    to_pick = route_through(WAREHOUSE, "WO1", "SO0", "SO1", "SI1", "A1", "A2")
    on_pick = _holding(table, R2, route_through(WAREHOUSE, "A2"), 0, 0)
    grant = decide_release_end(on_pick, R1, to_pick, progress=0, released_end=0, desired_end=5)
    assert to_pick.node_ids[grant.end] == "SO0"
    graph = make_graph(
        {"w": (0, 0), "a": (3, 0), "b": (6, 0), "c": (9, 0)},
        one_way=[("w", "a"), ("b", "c")],
        two_way=[("a", "b")],
    )
    short = route_through(graph, "w", "a", "b", "c")
    table = _holding(ReservationTable(build_conflicts(graph, SIM_SAFETY_M)), R2, short, 2, 2)
    grant = decide_release_end(table, R1, short, progress=0, released_end=0, desired_end=3)
    assert grant.end == 0


def test_leaving_an_aisle_across_a_lane_waits_before_the_crossing_not_on_it() -> None:
    """Leaving aisle A southwards for the outer lane crosses the inner lane at SI1. With the
    outer lane's SO1 taken, the vehicle waits on A1, inside the aisle, not on SI1, where it
    would stop the inner lane; and it holds SI1 and SO1 only once it is near them."""
    to_outer = route_through(WAREHOUSE, "A2", "A1", "SI1", "SO1", "SO1m", "SO2")
    table = ReservationTable(build_conflicts(WAREHOUSE, SIM_SAFETY_M))
    assert to_outer.node_ids[_end(table, to_outer, desired_end=1)] == "A1"
    assert to_outer.node_ids[_end(table, to_outer, desired_end=3)] == "SO1"
    taken = _holding(table, R2, route_through(WAREHOUSE, "SO1"), 0, 0)
    grant = decide_release_end(taken, R1, to_outer, progress=0, released_end=0, desired_end=5)
    assert to_outer.node_ids[grant.end] == "A1"
    assert grant.blocked is not None
    assert grant.blocked.holders == {R2}


def _end(table: ReservationTable, route: Route, *, desired_end: int) -> int:
    return decide_release_end(
        table, R1, route, progress=0, released_end=0, desired_end=desired_end
    ).end


def test_opposing_vehicles_pass_at_an_aisles_passing_place() -> None:
    """On the shipped floor a vehicle standing on aisle C's passing place does not keep one
    coming the other way out of the aisle: that one is released straight through; standing on
    the aisle's way (C5) instead, it does."""
    table = ReservationTable(build_conflicts(SHIPPED, SIM_SAFETY_M))
    southbound = route_through(
        SHIPPED, "NO3m", "NO3", "NI3", "C6", "C5", "C3", "C2", "C1", "SI3", "SI2m"
    )
    last = len(southbound.node_ids) - 1
    for stands, passes in (("Cp", True), ("C5", False)):
        held = _holding(table, R1, route_through(SHIPPED, stands), 0, 0)
        grant = decide_release_end(
            held, R2, southbound, progress=0, released_end=0, desired_end=last
        )
        assert (grant.end == last) is passes
        assert (grant.blocked is None) is passes


def test_an_aisles_passing_place_and_the_node_before_it_are_waiting_nodes() -> None:
    """Northwards through aisle C the one-lane stretches end where the passing place begins
    (C3) and on the passing place itself; the way south waits before it, on C5."""
    conflicts = build_conflicts(SHIPPED, SIM_SAFETY_M)
    northbound = route_through(SHIPPED, "SI3", "C1", "C2", "C3", "Cp", "C5", "C6", "NI3")
    southbound = route_through(SHIPPED, "NI3", "C6", "C5", "C3", "C2", "C1", "SI3")
    waits_north = [
        n for i, n in enumerate(northbound.node_ids) if is_waiting_node(conflicts, northbound, i)
    ]
    waits_south = [
        n for i, n in enumerate(southbound.node_ids) if is_waiting_node(conflicts, southbound, i)
    ]
    assert waits_north == ["C3", "Cp", "NI3"]
    assert waits_south == ["C5", "SI3"]
