"""The traffic controller fold: scenarios on the warehouse (its aisles one lane end to end) and a
random-fleet invariant."""

from __future__ import annotations

import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.unit.master.traffic.floors import one_lane_aisles_warehouse
from vda5050.topics import AgvId
from vda_master.graph import Graph, build_graph
from vda_master.routing import Route, shortest_route
from vda_master.traffic.conflicts import node
from vda_master.traffic.controller import AtNode, OnRoute, TrafficController
from vda_master.traffic.gate import is_last_before_exit, is_waiting_node, route_resources
from vda_master.traffic.passages import SpeedModel
from vda_master.traffic.planner import PlannedRoute
from vda_master.traffic.state import TrafficSettings, set_wait, woken
from vda_master.traffic.testing import (
    SIM_SAFETY_M,
    agv,
    bypass_graph,
    make_graph,
    route_through,
    warehouse_graph,
)
from vda_master.traffic.waits import BackOff, MoveToParking, Replan, Wait

R1, R2, R3 = agv("r1"), agv("r2"), agv("r3")
#: aisle A one lane end to end, as the aisles' stretches these tests follow need
WAREHOUSE = one_lane_aisles_warehouse()
# Head-on between m1 and m2; the way out is the bypass m2 → z → l or a spur.
BYPASS = bypass_graph()
BASE = TrafficController.for_graph(WAREHOUSE, SIM_SAFETY_M, TrafficSettings(max_wait_s=30.0))
NORTHBOUND = route_through(
    WAREHOUSE, "WO1", "SO0", "SO1", "SI1", "A1", "A2", "A3", "A4", "A5", "A6", "NI1", "NI1m", "NI2"
)
NI1 = NORTHBOUND.node_ids.index("NI1")
SOUTHBOUND = route_through(
    WAREHOUSE, "NO1m", "NO1", "NI1", "A6", "A5", "A4", "A3", "A2", "A1", "SI1", "SI0"
)


def _placed(controller: TrafficController, *where: tuple[AgvId, str]) -> TrafficController:
    for vehicle, node_id in where:
        controller, _ = controller.observe(vehicle, AtNode(node_id), 0.0)
    return controller


def _release(
    controller: TrafficController,
    vehicle: AgvId,
    route: Route,
    progress: int,
    now: float,
    *,
    window: int = 3,
) -> tuple[TrafficController, int]:
    granted = controller.vehicle(vehicle).granted_end if controller.vehicle(vehicle).route else 0
    controller, release = controller.request_release(
        vehicle, route, progress_index=progress, released_end=max(granted, progress),
        desired_end=progress + window, now=now,
    )  # fmt: skip
    return controller, release.end


def test_a_vehicle_standing_on_anothers_reservation_is_reported_not_reserved() -> None:
    """A vehicle appearing on a node another vehicle holds does not get it (the invariant
    wins); the snapshot reports the conflict, and it gets the node once that is free."""
    controller = _placed(BASE, (R1, "WO1"))
    controller, _ = _release(controller, R1, NORTHBOUND, 0, now=0.0)
    controller = _placed(controller, (R2, "A3"))
    assert controller.state.table.held_by(R2) == frozenset()
    row = next(v for v in controller.snapshot(1.0).vehicles if v.agv == R2)
    assert row.conflict == "node:A3 conflicts with node:A3 held by acme/r1"
    controller, _ = controller.observe(R1, OnRoute(NI1), 2.0)
    controller = _placed(controller, (R2, "A3"))
    assert controller.state.table.held_by(R2) == {node("A3")}
    assert next(v for v in controller.snapshot(3.0).vehicles if v.agv == R2).conflict is None


def test_idle_vehicles_hold_their_nodes() -> None:
    """An idle vehicle holds exactly the node it stands on, and follows it when it moves."""
    controller = _placed(BASE, (R1, "P1"))
    assert controller.state.table.held_by(R1) == {node("P1")}
    controller = _placed(controller, (R1, "P2"))
    assert controller.state.table.held_by(R1) == {node("P2")}


def test_head_on_in_an_aisle_the_second_vehicle_waits_then_passes() -> None:
    """r1 enters aisle A northbound; r2, coming south, waits at NO1m for r1 and is released
    into the aisle once r1 has left it."""
    controller = _placed(BASE, (R1, "WO1"), (R2, "NO1m"))
    controller, end = _release(controller, R1, NORTHBOUND, 0, now=1.0)
    assert NORTHBOUND.node_ids[end] == "A6"  # the exit's lane node follows once r1 is near
    controller, release = controller.request_release(
        R2, SOUTHBOUND, progress_index=0, released_end=0, desired_end=3, now=2.0
    )
    assert release.end == 0
    assert release.started_waiting
    assert release.wait is not None
    assert release.wait.blockers == {R1}
    controller, end = _release(controller, R1, NORTHBOUND, NORTHBOUND.node_ids.index("A4"), 4.0)
    assert end == NI1
    row = next(v for v in controller.snapshot(5.0).vehicles if v.agv == R2)
    assert row.waiting_for == (R1,)
    assert row.since == 2.0
    assert row.waited_s == 3.0
    assert row.pending_node_ids == SOUTHBOUND.node_ids[1:]

    controller, woken = controller.observe(R1, OnRoute(NI1), 10.0)
    assert woken == (R2,)
    controller, release = controller.request_release(
        R2, SOUTHBOUND, progress_index=0, released_end=0, desired_end=3, now=10.0
    )
    assert release.end == 0
    assert not release.started_waiting
    assert release.wait is not None
    assert release.wait.since == 2.0  # still the same wait

    controller, end = _release(controller, R1, NORTHBOUND, NI1, now=11.0)
    controller, woken = controller.observe(R1, OnRoute(end), 12.0)  # r1 beyond NI1, out
    assert woken == (R2,)
    controller, release = controller.request_release(
        R2, SOUTHBOUND, progress_index=0, released_end=0, desired_end=3, now=12.0
    )
    assert SOUTHBOUND.node_ids[release.end] == "A1"  # the aisle's last node before its exit
    assert release.wait is None
    assert controller.state.waiting == frozenset()


def test_progress_frees_what_the_vehicle_has_passed() -> None:
    """After passing nodes, a vehicle holds only its last node and the released base ahead."""
    controller = _placed(BASE, (R1, "WO1"))
    controller, end = _release(controller, R1, NORTHBOUND, 0, now=0.0)
    controller, _ = controller.observe(R1, OnRoute(4), 1.0)
    assert controller.state.table.held_by(R1) == set(route_resources(NORTHBOUND, 4, end))


def test_finish_leaves_the_vehicle_holding_its_last_node() -> None:
    """When the order ends the vehicle holds only the node it stands on, and waiters are told."""
    controller = _placed(BASE, (R1, "WO1"), (R2, "NO1m"))
    controller, end = _release(controller, R1, NORTHBOUND, 0, now=0.0)
    controller, _ = _release(controller, R2, SOUTHBOUND, 0, now=0.0)
    controller, woken = controller.observe(R1, OnRoute(end), 1.0)
    assert woken == (R2,)
    controller, woken = controller.finish(R1, 2.0)
    assert woken == ()  # it frees nothing more: it still stands on A6
    assert controller.state.table.held_by(R1) == {node("A6")}
    assert controller.vehicle(R1).route is None


def test_an_idle_vehicle_on_the_route_is_sent_to_parking() -> None:
    """An idle vehicle standing in aisle A is in r1's way: it is proposed a move to a free
    parking node, both at assignment and once r1 waits for it."""
    controller = _placed(BASE, (R1, "WO1"), (R3, "A3"))
    controller = controller.assign(R1, NORTHBOUND, 0.0)
    moves = controller.in_the_way(R1, 0.0)
    assert [(m.agv, m.node_id) for m in moves] == [(R3, "P1")]
    assert moves[0].route.node_ids[0] == "A3"
    controller, release = controller.request_release(
        R1, NORTHBOUND, progress_index=0, released_end=0, desired_end=3, now=1.0
    )
    assert NORTHBOUND.node_ids[release.end] == "SO0"  # the last node before the aisle's way in
    controller, _ = controller.observe(R1, OnRoute(release.end), 1.0)
    controller, release = controller.request_release(
        R1, NORTHBOUND, progress_index=1, released_end=1, desired_end=4, now=1.0
    )
    assert release.wait is not None
    assert release.wait.blockers == {R3}
    advice = controller.advice(1.0)
    assert [(m.agv, m.node_id) for m in advice.moves] == [(R3, "P1")]
    assert isinstance(advice.moves[0], MoveToParking)
    assert advice.deadlocks == ()


def test_two_idle_vehicles_in_the_way_are_sent_to_different_parking_nodes() -> None:
    """r2 and r3 stand idle in aisle A on r1's way: both are moved, each to its own parking
    node (both sent to the nearest one, the second would block the first there)."""
    controller = _placed(BASE, (R1, "WO1"), (R2, "A2"), (R3, "A4"))
    controller = controller.assign(R1, NORTHBOUND, 0.0)
    moves = controller.in_the_way(R1, 0.0)
    assert {m.agv for m in moves} == {R2, R3}
    assert len({m.node_id for m in moves}) == 2


def test_a_long_wait_gets_a_detour() -> None:
    """r2 waiting for r1 in aisle A longer than max_wait_s is proposed a route around it."""
    controller = _placed(BASE, (R1, "WO1"), (R2, "NO1m"))
    controller, _ = _release(
        controller, R1, NORTHBOUND, 0, now=0.0, window=len(NORTHBOUND.edge_ids)
    )
    # r1 has left the south lanes: the only way round aisle A goes west and along them
    controller, _ = controller.observe(R1, OnRoute(NORTHBOUND.node_ids.index("SI1")), 0.0)
    to_so2 = route_through(WAREHOUSE, *SOUTHBOUND.node_ids[:-1], "SO1", "SO1m", "SO2")
    controller, _ = _release(controller, R2, to_so2, 0, now=0.0)
    assert controller.advice(29.0).replans == ()
    replans = controller.advice(30.0).replans
    assert len(replans) == 1
    detour = replans[0]
    assert isinstance(detour, Replan)
    assert detour.agv == R2
    assert detour.route.node_ids[0] == "NO1m"
    assert detour.route.destination == "SO2"
    assert not {node(n) for n in detour.route.node_ids} & controller.state.table.held_by(R1)
    resolved = controller.record_resolution(detour, 30.0)
    assert resolved.advice(31.0).replans == ()  # under way: not proposed again at once
    assert resolved.snapshot(31.0).resolutions[0].kind == "replan"
    assert resolved.snapshot(31.0).deadlocks_resolved == 0


def test_a_detour_longer_than_the_wait_so_far_is_not_taken() -> None:
    """With max_wait_s = 5 s, r2 (1 m/s) is offered the way round aisle A only once it has
    waited as long as the detour's extra driving takes: before that, waiting is cheaper."""
    short_fuse = TrafficController.for_graph(WAREHOUSE, SIM_SAFETY_M, TrafficSettings(max_wait_s=5))
    controller = _placed(short_fuse, (R1, "WO1"), (R2, "NO1m"))
    controller, _ = _release(
        controller, R1, NORTHBOUND, 0, now=0.0, window=len(NORTHBOUND.edge_ids)
    )
    controller, _ = controller.observe(R1, OnRoute(NORTHBOUND.node_ids.index("SI1")), 0.0)
    to_so2 = route_through(WAREHOUSE, *SOUTHBOUND.node_ids[:-1], "SO1", "SO1m", "SO2")
    controller, _ = _release(controller, R2, to_so2, 0, now=0.0)
    assert controller.advice(5.0).replans == ()  # overdue, but the way round takes longer
    offered = controller.advice(1000.0).replans
    assert len(offered) == 1
    extra_s = offered[0].extra_m  # r2 drives 1 m/s: metres are seconds
    assert extra_s > 5.0
    assert controller.advice(extra_s - 0.5).replans == ()
    assert controller.advice(extra_s).replans == offered


def test_a_new_route_from_the_waiting_node_replaces_the_old_one() -> None:
    """Requesting release on another route re-assigns it: the wait ends, the old route is gone."""
    controller = _placed(BASE, (R1, "WO1"), (R2, "NO1m"))
    controller, _ = _release(controller, R1, NORTHBOUND, 0, now=0.0)
    controller, _ = _release(controller, R2, SOUTHBOUND, 0, now=0.0)
    detour = shortest_route(WAREHOUSE, "NO1m", "NO0")
    assert isinstance(detour, Route)
    assert detour.node_ids == ("NO1m", "NO1", "NO0")  # passes the aisle crossing at NO1
    controller, release = controller.request_release(
        R2, detour, progress_index=0, released_end=0, desired_end=3, now=1.0
    )
    assert release.wait is None
    assert release.end == len(detour.edge_ids)  # released to its end, NO0
    assert controller.vehicle(R2).route == detour
    assert controller.state.waiters.get(R1) is None


# A one-way triangle with spurs: three vehicles each wanting the next one's corner.
TRIANGLE = make_graph(
    {"a": (0, 0), "b": (6, 0), "c": (3, 5.2), "pa": (-1.2, -1.6), "pb": (9, -2), "pc": (3, 8.8)},
    one_way=[("a", "b"), ("b", "c"), ("c", "a")],
    two_way=[("a", "pa"), ("b", "pb"), ("c", "pc")],
)


def test_three_vehicle_cycle_is_detected_and_resolved() -> None:
    """r1 → r2 → r3 → r1 wait for each other: one deadlock, resolved by backing r1 off; once
    recorded it counts as resolved and is not proposed again while under way."""
    controller = TrafficController.for_graph(TRIANGLE, SIM_SAFETY_M)
    trips = ((R1, ("a", "b", "c")), (R2, ("b", "c", "a")), (R3, ("c", "a", "b")))
    controller = _placed(controller, *((v, nodes[0]) for v, nodes in trips))
    for vehicle, nodes in trips:
        controller, end = _release(controller, vehicle, route_through(TRIANGLE, *nodes), 0, 1.0)
        assert end == 0
    deadlocks = controller.deadlocks(5.0)
    assert [d.vehicles for d in deadlocks] == [(R1, R2, R3)]
    proposal = deadlocks[0].proposal
    assert isinstance(proposal, BackOff)
    assert (proposal.agv, proposal.node_id, proposal.resume_to) == (R1, "pa", "c")
    resolved = controller.record_resolution(proposal, 5.0, deadlocks[0].vehicles)
    assert resolved.deadlocks(6.0) == ()
    snapshot = resolved.snapshot(6.0)
    assert snapshot.deadlocks_resolved == 1
    assert snapshot.as_json()["resolutions"] == [
        {"time": 5.0, "kind": "backOff", "vehicle": "acme/r1", "nodeId": "pa",
         "deadlock": ["acme/r1", "acme/r2", "acme/r3"], "reason": "deadlock"}
    ]  # fmt: skip
    backed, end = _release(resolved, R1, proposal.route, 0, 7.0)
    assert end == 1  # r1 drives back to pa
    backed, woken = backed.observe(R1, OnRoute(1), 8.0)
    assert woken == (R3,)
    backed, _ = backed.finish(R1, 8.5)
    _, end = _release(backed, R3, route_through(TRIANGLE, "c", "a", "b"), 0, 9.0)
    assert end == 1  # r3 moves on to a


def test_a_deadlock_is_not_resolved_towards_a_vehicle_waiting_for_it() -> None:
    """r1 and r2 meet head-on between l and r; r3, on z, waits for r2. The bypass over z would
    be r2's cheapest way out, but r2 would wait for r3 without moving (the mixed-fleet test's
    livelock): the controller backs r1 off instead."""
    graph = BYPASS
    trips = ((R1, ("m1", "m2", "r")), (R2, ("m2", "m1", "l")), (R3, ("z", "m2", "r")))
    controller = _placed(
        TrafficController.for_graph(graph, SIM_SAFETY_M), *((v, n[0]) for v, n in trips)
    )
    for vehicle, nodes in trips:
        controller, end = _release(controller, vehicle, route_through(graph, *nodes), 0, 1.0)
        assert end == 0
    waiting = controller.vehicle(R3).wait
    assert waiting is not None
    assert waiting.blockers == {R2}
    deadlocks = controller.deadlocks(2.0)
    assert [d.vehicles for d in deadlocks] == [(R1, R2)]
    proposal = deadlocks[0].proposal
    assert isinstance(proposal, BackOff)
    assert (proposal.agv, proposal.node_id) == (R1, "sl")


def test_a_vehicle_detoured_for_deadlocks_again_and_again_is_backed_off_instead() -> None:
    """A livelock guard: r2 is detoured out of its deadlock with r1 and re-planned back into it
    (whatever makes it turn), three times within a minute. The fourth time it backs off to z (it
    moves, the cycle ends); once the minute is over, a detour is proposed again."""
    trips = {R1: ("m1", "m2", "r"), R2: ("m2", "m1", "l")}
    controller = _placed(TrafficController.for_graph(BYPASS, SIM_SAFETY_M), (R1, "m1"), (R2, "m2"))
    for vehicle, nodes in trips.items():
        controller, end = _release(controller, vehicle, route_through(BYPASS, *nodes), 0, 1.0)
        assert end == 0

    def turn_back(controller: TrafficController, now: float) -> tuple[object, TrafficController]:
        deadlocks = controller.deadlocks(now)
        assert [d.vehicles for d in deadlocks] == [(R1, R2)]
        proposal = deadlocks[0].proposal
        assert proposal is not None
        controller = controller.record_resolution(proposal, now, deadlocks[0].vehicles)
        controller, _ = _release(controller, R2, proposal.route, 0, now + 0.1)
        controller, end = _release(controller, R2, route_through(BYPASS, *trips[R2]), 0, now + 0.5)
        assert end == 0  # waiting for r1 again: a new deadlock
        return proposal, controller

    for now in (2.0, 3.0, 4.0):
        proposal, controller = turn_back(controller, now)
        assert isinstance(proposal, Replan)
        assert (proposal.agv, proposal.route.node_ids, proposal.reason) == (
            R2, ("m2", "z", "l"), "deadlock"
        )  # fmt: skip
    proposal, _ = turn_back(controller, 5.0)
    assert isinstance(proposal, BackOff)
    assert (proposal.agv, proposal.node_id, proposal.resume_to) == (R2, "z", "l")
    assert "no further detour for acme/r2" in proposal.reason
    proposal, _ = turn_back(controller, 2.0 + 60.0)
    assert isinstance(proposal, Replan)
    assert proposal.agv == R2


def test_plan_and_choose_count_traffic() -> None:
    """With r1 planned through aisle A, a plan through the aisle the other way avoids meeting
    it; the vehicle expected first is chosen for a destination."""
    controller = _placed(BASE, (R1, "WO1"), (R2, "NO1m"), (R3, "P6"))
    controller = controller.assign(R1, NORTHBOUND, 0.0)
    planned = controller.plan(R2, "NO1", "SI0", 0.0)
    assert planned is not None
    assert planned.avoids_traffic
    free_flow = shortest_route(WAREHOUSE, "NO1", "SI0")
    assert isinstance(free_flow, Route)
    assert planned.arrival > free_flow.length_m / BASE.state.settings.speed.speed_mps
    chosen = controller.choose([(R3, "P6"), (R2, "NO1m")], ("A4",), 0.0)
    assert chosen is not None
    assert chosen[0] == R2
    faster = controller.with_speed(R3, SpeedModel(20.0))
    chosen = faster.choose([(R3, "P6"), (R2, "NO1m")], ("A4",), 0.0)
    assert chosen is not None
    assert chosen[0] == R3


# s → m → t is the cheapest way (6 m); s → d1 → d2 → t goes round m (12 m); u → m brings a
# vehicle to m, where it is expected to stay (the passages' hold at a destination).
ROUND = make_graph(
    {"s": (0, 0), "m": (3, 0), "t": (6, 0), "d1": (0, 4), "d2": (3, 4), "u": (3, -4)},
    one_way=[("s", "m"), ("m", "t"), ("s", "d1"), ("d1", "d2"), ("d2", "t"), ("u", "m")],
)


def _round_plan(margin_s: float, *, other_to_m: bool, time_lapse: float = 1.0) -> PlannedRoute:
    """r2's plan from s to t, with r1 driving to m (where it is expected to stay) if
    ``other_to_m``; durations in simulated seconds, the vehicles (default speed) simulated
    ``time_lapse`` times faster than the controller's clock."""
    settings = TrafficSettings(detour_margin_s=margin_s).at_time_lapse(time_lapse)
    controller = TrafficController.for_graph(ROUND, SIM_SAFETY_M, settings)
    controller = _placed(controller, (R1, "u"), (R2, "s"))
    if other_to_m:
        controller = controller.assign(R1, route_through(ROUND, "u", "m"), 0.0)
    planned = controller.plan(R2, "s", "t", 0.0)
    assert planned is not None
    return planned


def test_a_detour_is_taken_only_when_it_arrives_the_margin_earlier() -> None:
    """r1 is expected to stand on m for about half a minute: r2 goes round it when that
    arrives earlier than waiting on the cheapest route (by at least the margin), else it keeps
    to the cheapest route and waits; on a free floor it never goes round."""
    assert _round_plan(0.0, other_to_m=False).route.node_ids == ("s", "m", "t")
    assert _round_plan(0.0, other_to_m=True).route.node_ids == ("s", "d1", "d2", "t")
    assert _round_plan(10.0, other_to_m=True).route.node_ids == ("s", "d1", "d2", "t")
    assert _round_plan(60.0, other_to_m=True).route.node_ids == ("s", "m", "t")


@pytest.mark.parametrize("margin_s", [0.0, 60.0])
def test_a_time_lapsed_fleet_is_planned_as_in_real_time(margin_s: float) -> None:
    """A fleet simulated ten times faster than the master's clock gets the same route, its
    waits and arrival ten times shorter on that clock: the expected stay at m, the margins
    and the detour margin shrink with the speeds (config ``time_lapse``). Unscaled, r1's
    30 s stay at m would count ten times longer than the simulation keeps it."""
    real = _round_plan(margin_s, other_to_m=True)
    fast = _round_plan(margin_s, other_to_m=True, time_lapse=10.0)
    assert fast.route.node_ids == real.route.node_ids
    assert fast.arrival == pytest.approx(real.arrival / 10)
    assert fast.waited_s == pytest.approx(real.waited_s / 10)


def test_time_lapse_scales_durations_and_edge_speed_limits() -> None:
    """Durations divide, speeds multiply; relative to the lapse the settings were given for."""
    settings = TrafficSettings(max_wait_s=30.0, detour_margin_s=5.0).at_time_lapse(10.0)
    assert settings.max_wait_s == pytest.approx(3.0)
    assert settings.detour_margin_s == pytest.approx(0.5)
    assert settings.dwell_s == pytest.approx(0.5)
    assert settings.detour_repeat_window_s == pytest.approx(6.0)
    assert settings.passages.hold_s == pytest.approx(3.0)
    assert settings.passages.buffer_s == pytest.approx(0.1)
    assert settings.passages.drift == pytest.approx(0.1)  # a share of the time, not a time
    assert settings.speed.speed_mps == pytest.approx(10.0)
    assert settings.at_time_lapse(20.0).max_wait_s == pytest.approx(1.5)
    assert TrafficSettings().at_time_lapse(1.0) == TrafficSettings()
    limited = build_graph(
        {
            "mapId": "test",
            "nodes": [{"nodeId": "a", "x": 0, "y": 0}, {"nodeId": "b", "x": 4, "y": 0}],
            "edges": [{"edgeId": "a-b", "startNodeId": "a", "endNodeId": "b", "maxSpeed": 0.5}],
        },
        source="test",
    )
    controller = TrafficController.for_graph(limited, SIM_SAFETY_M, settings)
    assert controller.state.roads.max_speed["a-b"] == pytest.approx(5.0)
    with pytest.raises(ValueError, match="time_lapse must be positive"):
        TrafficSettings().at_time_lapse(0.0)


def test_snapshot_json_has_the_api_shape() -> None:
    """The GET /traffic document names holdings, pending nodes and waits in camelCase."""
    controller = _placed(BASE, (R1, "SO0"))
    document = controller.snapshot(0.0).as_json()
    assert document == {
        "safetyDistanceM": SIM_SAFETY_M,
        "vehicles": [
            {"manufacturer": "acme", "serialNumber": "r1", "nodeId": "SO0", "holds": ["node:SO0"],
             "pendingNodeIds": [], "waitingFor": [], "waitingAt": None, "waitingSince": None,
             "waitedS": None, "conflict": None}
        ],
        "deadlocksResolved": 0,
        "resolutions": [],
    }  # fmt: skip


# -- random fleets: the invariant and the waiting-node rule hold after every call ------------


# The west end of the warehouse (aisles A and B and the corridors around them), so that the
# vehicles meet often.
def _west_end(graph: Graph) -> list[str]:
    """Aisles A and B and the corridors' nodes beside them."""
    return sorted(
        n
        for n in graph.nodes
        if n[0] in "AB" or (n[:2] in {"SO", "SI", "NI", "NO"} and n[2] in "0123")
    )


NODES = _west_end(WAREHOUSE)
#: The shipped floor: its aisles have passing places.
SHIPPED = warehouse_graph()
SHIPPED_BASE = TrafficController.for_graph(SHIPPED, SIM_SAFETY_M, TrafficSettings(max_wait_s=30.0))
SHIPPED_NODES = _west_end(SHIPPED)
FLEET = [agv(f"v{i}") for i in range(5)]
START = ["SO0", "NO2", "A3", "B5", "SI3"]


def _check(controller: TrafficController) -> None:
    state = controller.state
    held = list(state.table.vehicles())
    for i, (first, mine) in enumerate(held):
        for second, theirs in held[i + 1 :]:
            clash = [(a, b) for a in mine for b in theirs if state.conflicts.conflict(a, b)]
            assert clash == [], (first, second)
    for vehicle in FLEET:
        record = controller.vehicle(vehicle)
        if record.route is not None and record.unplaced is None:
            expected = route_resources(record.route, record.progress, record.granted_end)
            assert state.table.held_by(vehicle) == set(expected)
            end = record.granted_end
            assert (
                end == record.progress
                or is_waiting_node(state.conflicts, record.route, end)
                or is_last_before_exit(state.conflicts, record.route, end)
            )


def _apply(controller: TrafficController, now: float) -> tuple[TrafficController, dict[AgvId, str]]:
    """Carry out the advice as the master shell would: the proposal of each deadlock, then
    over-long waits and parking moves; back-offs resume to their destination later."""
    advice = controller.advice(now)
    resume: dict[AgvId, str] = {}
    busy: set[AgvId] = set()
    for deadlock in advice.deadlocks:
        busy.update(deadlock.vehicles)
        if deadlock.proposal is not None:
            controller = controller.record_resolution(deadlock.proposal, now, deadlock.vehicles)
            controller = _start(controller, deadlock.proposal, now)
            if isinstance(deadlock.proposal, BackOff):
                resume[deadlock.proposal.agv] = deadlock.proposal.resume_to
    for proposal in (*advice.replans, *advice.moves):
        if proposal.agv not in busy:
            controller = _start(controller.record_resolution(proposal, now), proposal, now)
    return controller, resume


def _start(
    controller: TrafficController, proposal: Replan | BackOff | MoveToParking, now: float
) -> TrafficController:
    controller, _ = controller.request_release(
        proposal.agv, proposal.route, progress_index=0, released_end=0, desired_end=3, now=now
    )
    return controller


def _drive(
    steps: list[tuple[int, str]], base: TrafficController = BASE, graph: Graph = WAREHOUSE
) -> dict[AgvId, int]:
    """Run ``steps`` (vehicle index, next destination) on the west end of the warehouse,
    checking the invariants after every call; returns the orders finished per vehicle."""
    controller = _placed(base, *zip(FLEET, START, strict=True))
    finished = dict.fromkeys(FLEET, 0)
    resume: dict[AgvId, str] = {}
    for now, (index, target) in enumerate(steps):
        if now % 20 == 0:
            controller, resumed = _apply(controller, float(now))
            resume |= resumed
            _check(controller)
        vehicle = FLEET[index]
        record = controller.vehicle(vehicle)
        if record.route is None:
            destination = resume.pop(vehicle, target)
            route = shortest_route(graph, record.node_id or START[index], destination)
            if isinstance(route, Route) and route.edge_ids:
                controller = controller.assign(vehicle, route, float(now))
        elif record.progress < record.granted_end:
            controller, _ = controller.observe(vehicle, OnRoute(record.progress + 1), float(now))
        elif record.progress == len(record.route.edge_ids):
            controller, _ = controller.finish(vehicle, float(now))
            finished[vehicle] += 1
        else:
            controller, _ = _release(controller, vehicle, record.route, record.progress, now)
        _check(controller)
    return finished


@settings(max_examples=25, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(st.lists(st.tuples(st.integers(0, 4), st.sampled_from(NODES)), min_size=20, max_size=100))
def test_random_fleet_operations_keep_the_invariant(steps: list[tuple[int, str]]) -> None:
    """Random assignments, releases, progress, finishes and resolutions of five vehicles on the
    warehouse never let two vehicles hold conflicting resources, and bases end only on waiting
    nodes."""
    _drive(steps)


def test_a_dense_random_fleet_keeps_finishing_orders() -> None:
    """Five vehicles with random trips around two one-lane aisles, with deadlocks resolved as
    advised, all keep finishing orders (no lasting deadlock)."""
    rng = random.Random(7)
    steps = [(rng.randrange(len(FLEET)), rng.choice(NODES)) for _ in range(1500)]
    finished = _drive(steps)
    assert min(finished.values()) >= 5, finished


@settings(max_examples=25, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 4), st.sampled_from(SHIPPED_NODES)), min_size=20, max_size=100
    )
)
def test_random_fleet_operations_keep_the_invariant_with_passing_places(
    steps: list[tuple[int, str]],
) -> None:
    """The same on the shipped floor, whose aisles have passing places."""
    _drive(steps, SHIPPED_BASE, SHIPPED)


def test_a_dense_random_fleet_keeps_finishing_orders_with_passing_places() -> None:
    """The same dense fleet on the shipped floor, whose aisles have passing places."""
    rng = random.Random(7)
    steps = [(rng.randrange(len(FLEET)), rng.choice(SHIPPED_NODES)) for _ in range(1500)]
    finished = _drive(steps, SHIPPED_BASE, SHIPPED)
    assert min(finished.values()) >= 5, finished


@pytest.mark.parametrize("position", [OnRoute(3), AtNode("A1")])
def test_positions_that_do_not_fit_the_vehicle_are_ignored(position: object) -> None:
    """Progress of a vehicle without a route, or a node of a routed one, changes nothing."""
    controller = _placed(BASE, (R1, "SO0"))
    routed = controller.assign(R2, NORTHBOUND, 0.0) if isinstance(position, AtNode) else None
    target = routed or controller
    vehicle = R2 if routed else R1
    after, woken = target.observe(vehicle, position, 1.0)  # type: ignore[arg-type]
    assert after is target
    assert woken == ()


def test_vehicles_waiting_for_one_that_frees_something_are_woken_longest_waiting_first() -> None:
    """First come, first served at freed resources: whoever has waited longest asks for its
    release first, whatever its name (co-simulation, K = 20: fewer orders over 5x and fewer
    deadlock resolutions than waking in name order)."""
    state = _placed(BASE, (R1, "SO0"), (R2, "NO1"), (R3, "NO1m")).state
    state = set_wait(state, R3, Wait(frozenset({R1}), node("A6"), "NO1m", since=1.0))
    state = set_wait(state, R2, Wait(frozenset({R1}), node("NI1"), "NO1", since=2.0))
    assert woken(state, R1, freed=True) == (R3, R2)
    assert woken(state, R1, freed=False) == ()
