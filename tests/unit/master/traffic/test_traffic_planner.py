"""Time-aware routing: passages, safe-interval A*, earliest arrival (issue 9 §4)."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vda5050.topics import AgvId
from vda_master.routing import Route, shortest_route
from vda_master.traffic.conflicts import ConflictMap, build_conflicts, edge, node
from vda_master.traffic.passages import (
    Passage,
    PassageSettings,
    PassageTable,
    SpeedModel,
    estimate_timeline,
    passages_of,
)
from vda_master.traffic.paths import build_roadmap
from vda_master.traffic.planner import (
    Candidate,
    PlannedRoute,
    Spans,
    earliest_arrival,
    plan_route,
)
from vda_master.traffic.testing import SIM_SAFETY_M, agv, make_graph, route_through, warehouse_graph

ME, OTHER = agv("me"), agv("other")
SPEED = SpeedModel(1.0)
# Direct s → m → t is 6 m; the detour s → d1 → d2 → t is 12 m and keeps clear of m.
DETOUR = make_graph(
    {"s": (0, 0), "m": (3, 0), "t": (6, 0), "d1": (0, 4), "d2": (3, 4)},
    one_way=[("s", "m"), ("m", "t"), ("s", "d1"), ("d1", "d2"), ("d2", "t")],
)
ROADS = build_roadmap(DETOUR)
CONFLICTS = build_conflicts(DETOUR, SIM_SAFETY_M)


def _busy(*passages: Passage, vehicle: AgvId = OTHER) -> PassageTable:
    return PassageTable().with_vehicle(vehicle, passages)


def _plan(passages: PassageTable, *, dwell_s: float = 0.0) -> PlannedRoute:
    planned = plan_route(ROADS, CONFLICTS, passages, agv=ME, start="s", destination="t",
                         start_time=0.0, speed=SPEED, dwell_s=dwell_s)  # fmt: skip
    assert planned is not None
    return planned


def test_free_floor_gives_the_shortest_route_at_free_flow_time() -> None:
    """Without other vehicles the plan is the shortest route, arriving after length / speed."""
    planned = _plan(PassageTable())
    assert planned.route.node_ids == ("s", "m", "t")
    assert planned.arrival == pytest.approx(6.0)
    assert planned.waited_s == 0.0
    assert planned.avoids_traffic


def test_a_resource_reserved_at_arrival_time_is_avoided() -> None:
    """Node m is occupied for a long time around when the vehicle would get there: the plan takes
    the detour, which is faster than waiting."""
    planned = _plan(_busy(Passage(node("m"), 1.0, 60.0)))
    assert planned.route.node_ids == ("s", "d1", "d2", "t")
    assert planned.arrival == pytest.approx(12.0)


def test_waiting_is_chosen_when_it_is_faster() -> None:
    """Node m is occupied only briefly: the plan waits at s and still arrives before the detour
    would."""
    planned = _plan(_busy(Passage(node("m"), 1.0, 4.0)))
    assert planned.route.node_ids == ("s", "m", "t")
    assert planned.departure == pytest.approx(4.0)
    assert planned.arrival == pytest.approx(10.0)
    assert planned.waited_s == pytest.approx(4.0)


def test_own_passages_are_ignored() -> None:
    """A vehicle's own planned passages never block its plan."""
    planned = _plan(_busy(Passage(node("m"), 0.0, 60.0), vehicle=ME))
    assert planned.route.node_ids == ("s", "m", "t")


def test_destination_must_stay_free_for_the_dwell_time() -> None:
    """Another vehicle due at the destination soon after arrival pushes the plan past it."""
    planned = _plan(_busy(Passage(node("t"), 8.0, 20.0)), dwell_s=5.0)
    assert planned.arrival >= 20.0
    assert _plan(_busy(Passage(node("t"), 8.0, 20.0)), dwell_s=1.0).arrival == pytest.approx(6.0)


def test_no_plan_when_the_destination_is_taken_forever() -> None:
    """An idle vehicle standing on the destination for good leaves no traffic-free plan."""
    passages = _busy(Passage(node("t"), 0.0, math.inf))
    plan = plan_route(ROADS, CONFLICTS, passages, agv=ME, start="s", destination="t",
                      start_time=0.0, speed=SPEED)  # fmt: skip
    assert plan is None


# s → t directly through a one-lane stretch (s ⇄ a ⇄ t, 6 m), or round a one-way corridor
# (s → c1 → c2 → t, 14 m).
AISLE = make_graph(
    {"s": (0, 0), "a": (3, 0), "t": (6, 0), "c1": (0, 4), "c2": (6, 4)},
    two_way=[("s", "a"), ("a", "t")],
    one_way=[("s", "c1"), ("c1", "c2"), ("c2", "t")],
)


def _aisle_plan(one_lane_factor: float) -> PlannedRoute:
    roads = build_roadmap(AISLE, one_lane_factor=one_lane_factor)
    conflicts = build_conflicts(AISLE, SIM_SAFETY_M)
    planned = plan_route(roads, conflicts, PassageTable(), agv=ME, start="s", destination="t",
                         start_time=0.0, speed=SPEED)  # fmt: skip
    assert planned is not None
    return planned


def test_one_lane_cost_steers_the_route_but_times_stay_real() -> None:
    """The one-lane factor makes the planner prefer the corridor when the stretch costs more
    than the way round, and its timeline is real driving time either way (the passages others
    plan around are not stretched by the factor)."""
    through = _aisle_plan(2.0)  # 6 m x 2 = 12 < 14: still through the stretch
    assert through.route.node_ids == ("s", "a", "t")
    assert through.arrival == pytest.approx(6.0)
    around = _aisle_plan(3.0)  # 18 > 14: round the corridor
    assert around.route.node_ids == ("s", "c1", "c2", "t")
    assert around.arrival == pytest.approx(4.0 + 6.0 + 4.0)


def test_timeline_uses_speed_edge_limits_and_node_time() -> None:
    """Arrival times follow length / min(speed, maxSpeed) plus the time per node."""
    graph = make_graph({"a": (0, 0), "b": (10, 0), "c": (20, 0)}, one_way=[("a", "b"), ("b", "c")])
    raw = graph.edges["b-c"].model_copy(update={"max_speed": 0.5})
    graph = type(graph)(graph.map_id, graph.nodes, {**graph.edges, "b-c": raw}, graph.outgoing)
    route = route_through(graph, "a", "b", "c")
    timeline = estimate_timeline(
        build_roadmap(graph), route, SpeedModel(2.0, node_time_s=1.0), start_time=100.0
    )
    assert timeline == ((100.0, 100.0), (106.0, 106.0), (127.0, 127.0))


def test_passages_widen_with_uncertainty_and_hold_the_destination() -> None:
    """Each passage grows by the buffer plus drift × time ahead; the last node is held."""
    graph = make_graph({"a": (0, 0), "b": (10, 0), "c": (20, 0)}, one_way=[("a", "b"), ("b", "c")])
    route = route_through(graph, "a", "b", "c")
    timeline = ((0.0, 0.0), (10.0, 10.0), (20.0, 20.0))
    found = passages_of(route, timeline, PassageSettings(buffer_s=1.0, drift=0.1, hold_s=30.0))
    assert found == (
        Passage(node("a"), 0.0, 1.0),
        Passage(edge("a-b"), -1.0, 12.0),
        Passage(node("b"), 8.0, 12.0),
        Passage(edge("b-c"), 8.0, 23.0),
        Passage(node("c"), 17.0, 50.0),
    )


def test_passage_table_replaces_a_vehicles_passages() -> None:
    """Replacing a vehicle's passages drops its old ones and keeps the others'."""
    table = _busy(Passage(node("m"), 0.0, 5.0))
    table = table.with_vehicle(ME, [Passage(node("m"), 6.0, 7.0), Passage(node("t"), 1.0, 2.0)])
    table = table.with_vehicle(ME, [Passage(node("t"), 3.0, 4.0)])
    assert table.at(node("m")) == ((0.0, 5.0, OTHER),)
    assert table.at(node("t")) == ((3.0, 4.0, ME),)
    assert table.without(OTHER).at(node("m")) == ()


def test_shared_spans_ignore_only_the_asking_vehicles_own_passages() -> None:
    """One ``Spans`` serves several vehicles' searches in a request: whichever vehicle asks
    first, each sees every passage but its own, and a third vehicle sees all of them."""
    table = _busy(Passage(node("m"), 0.0, 5.0)).with_vehicle(ME, [Passage(node("m"), 10.0, 12.0)])
    table = table.with_vehicle(agv("gone"), [Passage(node("m"), -9.0, -1.0)])
    spans = Spans(CONFLICTS, table, since=0.0)
    third = agv("third")
    for asking, seen in ((ME, [0.0]), (OTHER, [10.0]), (third, [0.0, 10.0]), (ME, [0.0])):
        starts, _ = spans.blocked(node("m"), asking)
        assert starts == seen, asking
    assert spans.gaps("m", ME) == [(-math.inf, 0.0), (5.0, math.inf)]
    assert spans.gaps("m", third) == [(-math.inf, 0.0), (5.0, 10.0), (12.0, math.inf)]
    assert spans.gaps("m", OTHER) == [(-math.inf, 10.0), (12.0, math.inf)]


def test_earliest_arrival_prefers_the_nearer_vehicle_on_a_free_floor() -> None:
    """Without traffic the nearest candidate wins."""
    near = Candidate(agv("near"), "m", 0.0, SPEED)
    far = Candidate(agv("far"), "s", 0.0, SPEED)
    best = earliest_arrival(ROADS, CONFLICTS, PassageTable(), [far, near], ("t",))
    assert best is not None
    assert best[0] == near
    assert best[1].arrival == pytest.approx(3.0)


def test_earliest_arrival_counts_traffic() -> None:
    """A nearer candidate whose way is blocked for long loses to a farther one that is free."""
    near = Candidate(agv("near"), "m", 0.0, SPEED)
    far = Candidate(agv("far"), "d2", 0.0, SPEED)
    passages = _busy(Passage(node("m"), 0.0, 30.0))
    best = earliest_arrival(ROADS, CONFLICTS, passages, [near, far], ("t",))
    assert best is not None
    assert best[0] == far
    assert best[1].arrival == pytest.approx(5.0)


def test_earliest_arrival_picks_the_destination_reached_first() -> None:
    """Given several destinations (the stations of a type), the one reached first wins: the
    nearer on a free floor, a farther one when the nearer is taken for long."""
    me = Candidate(ME, "s", 0.0, SPEED)
    free = earliest_arrival(ROADS, CONFLICTS, PassageTable(), [me], ("d2", "t"))
    assert free is not None
    assert free[1].route.destination == "t"
    assert free[1].arrival == pytest.approx(6.0)
    taken = _busy(Passage(node("t"), 0.0, 30.0))
    best = earliest_arrival(ROADS, CONFLICTS, taken, [me], ("t", "d2"))
    assert best is not None
    assert best[1].route.destination == "d2"
    assert best[1].arrival == pytest.approx(7.0)


def test_earliest_arrival_breaks_ties_by_vehicle_id() -> None:
    """Two candidates arriving at the same time: the lower id is chosen."""
    one = Candidate(agv("b"), "s", 0.0, SPEED)
    two = Candidate(agv("a"), "s", 0.0, SPEED)
    best = earliest_arrival(ROADS, CONFLICTS, PassageTable(), [one, two], ("t",))
    assert best is not None
    assert best[0] == two


# -- prioritized planning on the warehouse: every plan keeps clear of the earlier ones ---------

WAREHOUSE = warehouse_graph()
W_ROADS = build_roadmap(WAREHOUSE)
W_CONFLICTS = build_conflicts(WAREHOUSE, SIM_SAFETY_M)
W_NODES = sorted(WAREHOUSE.nodes)


def _overlaps(
    conflicts: ConflictMap, mine: tuple[Passage, ...], table: PassageTable
) -> list[object]:
    return [
        (p, other, entry)
        for p in mine
        for other in conflicts[p.resource]
        for entry in table.at(other)
        if entry[0] < p.end and entry[1] > p.start
    ]


@settings(max_examples=25, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(
    st.lists(st.tuples(st.sampled_from(W_NODES), st.sampled_from(W_NODES)), min_size=2, max_size=6)
)
def test_prioritized_plans_never_overlap_earlier_passages(trips: list[tuple[str, str]]) -> None:
    """Vehicles planned one after the other on the warehouse never plan to occupy conflicting
    resources at overlapping times (exact timelines, without the uncertainty margins)."""
    exact = PassageSettings(buffer_s=0.0, drift=0.0, hold_s=5.0)
    table = PassageTable()
    for index, (start, destination) in enumerate(trips):
        vehicle = agv(f"v{index}")
        planned = plan_route(W_ROADS, W_CONFLICTS, table, agv=vehicle, start=start,
                             destination=destination, start_time=0.0, speed=SpeedModel(1.5),
                             dwell_s=5.0)  # fmt: skip
        if planned is None:
            continue
        mine = passages_of(planned.route, planned.timeline, exact)
        # The start node is occupied from 0 by construction; others may only pass it before.
        mine = tuple(p for p in mine if not (p.resource == node(start) and p.start == 0.0))
        assert _overlaps(W_CONFLICTS, mine, table) == []
        free_flow = shortest_route(WAREHOUSE, start, destination)
        assert isinstance(free_flow, Route)
        assert planned.arrival >= free_flow.length_m / 1.5 - 1e-9
        table = table.with_vehicle(vehicle, passages_of(planned.route, planned.timeline, exact))
