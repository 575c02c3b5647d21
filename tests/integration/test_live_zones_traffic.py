"""A zone added and lifted while ten simulated vehicles run transports under traffic control
on the warehouse (the co-simulation of benchmarks/traffic_sim.py: the real master and vehicle
services on a fake clock): nobody collides, nobody enters the closed area once it is closed,
every order ends, and the floor goes back to normal once the area is lifted."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from functools import partial

import pytest
from structlog.testing import capture_logs

from benchmarks.traffic_sim import WAREHOUSE
from vda5050.graph_file import GraphZone
from vda5050.polygons import inside
from vda_fleetsim.simulation import STEP_S, Simulation
from vda_master.dispatcher import OrderStatus
from vda_master.testing import zone

OUTCOMES = ("order.rerouted", "order.stopped")

pytestmark = pytest.mark.integration

ADDED_AT_S, LIFTED_AT_S, END_S = 120.0, 420.0, 540.0
#: A vehicle on an edge into the area when it closes stops at that edge's end.
GRACE_S = 10.0
HALF_SIDE_M = 0.8


def _square_round(x: float, y: float) -> GraphZone:
    h = HALF_SIDE_M
    corners = [[x - h, y - h], [x + h, y - h], [x + h, y + h], [x - h, y + h]]
    return GraphZone.model_validate(zone("spill", "BLOCKED", corners))


@pytest.mark.parametrize(("seed", "beyond_base"), [(1, 2), (3, 2), (7, 0)])
def test_a_spill_on_a_busy_way_closed_and_reopened_under_traffic(
    seed: int, beyond_base: int
) -> None:
    """Two simulated minutes in, an area closes round a node of a driving vehicle's route,
    ``beyond_base`` nodes beyond the end of its released base (0: its end, which the vehicle
    may drive to already; a lane or aisle node, not its destination): that order,
    and any other through there, goes round it or is stopped saying why; nobody collides,
    nobody who was outside enters the area while it is closed, no order fails for another
    reason, and the floor keeps working through it and after it is lifted."""
    sim = Simulation(WAREHOUSE, 10, seed=seed, latency_s=0.02, settings={"traffic_control": True})
    closed: dict[str, object] = {}
    entered: list[str] = []
    inside_at_close: set[str] = set()

    def close() -> None:
        order_id, node_id = _a_node_ahead_of_a_driving_vehicle(sim, beyond_base)
        node = sim.master.graph.nodes[node_id]
        spill = _square_round(node.x, node.y)
        closed.update(order=order_id, node=node_id, area=spill.vertices, at=sim.results.finished)
        with capture_logs() as logs:
            asyncio.run(sim.master.add_zone(spill))
        closed["outcomes"] = [e["event"] for e in logs if e["event"] in OUTCOMES]

    def watch(now: float) -> None:
        area = closed["area"]
        assert isinstance(area, list)
        for serial, runtime in sim.runtimes.items():
            pose = runtime.state.pose
            if not inside(area, (pose.x, pose.y)):
                continue
            if now < ADDED_AT_S + GRACE_S:
                inside_at_close.add(serial)
            elif serial not in inside_at_close:
                entered.append(f"{serial} at {now:.1f} s")

    def lift() -> None:
        asyncio.run(sim.master.remove_zone("spill"))
        closed["lifted_at"] = sim.results.finished

    steps: list[tuple[float, Callable[[], None]]] = [(ADDED_AT_S, close), (LIFTED_AT_S, lift)]
    count = int((LIFTED_AT_S - ADDED_AT_S) / STEP_S) - 1
    steps += [(ADDED_AT_S + (k + 1) * STEP_S, partial(watch, ADDED_AT_S + (k + 1) * STEP_S))
              for k in range(count)]  # fmt: skip
    sim.run(END_S, tuple(steps))

    assert closed["outcomes"]  # the chosen order at least was re-routed or stopped
    track = sim.master.tracks[str(closed["order"])]
    if track.status is OrderStatus.FINISHED:
        assert closed["node"] not in [n.node_id for n in track.plan.nodes]
    tracks = sim.master.tracks.values()
    failed = [t.reason for t in tracks if t.status is OrderStatus.FAILED]
    assert all("BLOCKED zone 'spill'" in reason for reason in failed), failed
    assert sim.separation.violations == 0
    assert entered == []
    assert sum(1 for t in tracks if not t.terminal) <= 10  # one running per vehicle at most
    finished_at_close, finished_at_lift = closed["at"], closed["lifted_at"]
    assert isinstance(finished_at_close, int)
    assert isinstance(finished_at_lift, int)
    assert finished_at_lift - finished_at_close > 20  # the floor kept working round it
    assert sim.results.finished - finished_at_lift > 5
    assert sim.master.graph.blocked_edges == {}


def _a_node_ahead_of_a_driving_vehicle(sim: Simulation, beyond_base: int) -> tuple[str, str]:
    """An active order and a node of its route ``beyond_base`` nodes beyond its released base
    that is not its destination nor the node before, no station, nor a node a vehicle stands
    on."""
    standing = {r.state.last_node_id for r in sim.runtimes.values()}
    for order_id in sorted(sim.master.active.values()):
        track = sim.master.tracks[order_id]
        route = track.plan.route
        ahead = track.released_end + beyond_base
        if route is None or not 0 < ahead < len(route.node_ids) - 2:
            continue
        node_id = route.node_ids[ahead]
        if node_id not in standing and sim.master.graph.nodes[node_id].station_type is None:
            return order_id, node_id
    pytest.fail("no driving vehicle with a way ahead to close")
