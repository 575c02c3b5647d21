"""Late orders go first (``traffic.priority``): a late waiting vehicle's claim holds back a
vehicle whose order is due later, never one it waits for, and only while it is late."""

from __future__ import annotations

from vda5050.topics import AgvId
from vda_master.routing import Route
from vda_master.traffic.conflicts import edge, node
from vda_master.traffic.controller import AtNode, OnRoute, Release, TrafficController
from vda_master.traffic.priority import due_time, is_late
from vda_master.traffic.state import TrafficSettings
from vda_master.traffic.testing import SIM_SAFETY_M, agv, make_graph, route_through

LATE, OTHER, BLOCKER = agv("late"), agv("other"), agv("blocker")
# A crossing: a west-east lane w - x - e and a south-north lane s - x - n - f, each one way.
CROSSING = make_graph(
    {"w": (0, 0), "x": (8, 0), "e": (16, 0), "s": (8, -8), "n": (8, 8), "f": (8, 16)},
    one_way=[("w", "x"), ("x", "e"), ("s", "x"), ("x", "n"), ("n", "f")],
)
EASTBOUND = route_through(CROSSING, "w", "x", "e")
NORTHBOUND = route_through(CROSSING, "s", "x", "n")
LEAVING = route_through(CROSSING, "x", "n", "f")
#: speed 1 m/s, 5 s dwell: the eastbound order's free-flow estimate is 16 + 5 = 21 s, so it is
#: late from 42 s on and due at 105 s.
BASE = TrafficController.for_graph(CROSSING, SIM_SAFETY_M, TrafficSettings(max_wait_s=300.0))


def _request(
    controller: TrafficController, vehicle: AgvId, route: Route, now: float
) -> tuple[TrafficController, Release]:
    """Ask for the whole of ``route`` (the same route: from where the vehicle is)."""
    record = controller.vehicle(vehicle)
    granted = record.granted_end if record.route == route else 0
    return controller.request_release(
        vehicle,
        route,
        progress_index=record.progress if record.route == route else 0,
        released_end=granted,
        desired_end=len(route.edge_ids),
        now=now,
    )


def _late_one_waits(now_blocker_leaves: float) -> TrafficController:
    """LATE's order starts at 0 and waits at w for x, where BLOCKER stands until
    ``now_blocker_leaves``, when BLOCKER drives on to f and frees x and n."""
    controller, _ = BASE.observe(BLOCKER, AtNode("x"), 0.0)
    controller = controller.assign(LATE, EASTBOUND, 0.0, new_order=True)
    controller, release = _request(controller, LATE, EASTBOUND, 0.0)
    assert release.wait is not None
    assert release.wait.blockers == frozenset({BLOCKER})
    controller = controller.assign(BLOCKER, LEAVING, now_blocker_leaves, new_order=True)
    controller, _ = _request(controller, BLOCKER, LEAVING, now_blocker_leaves)
    controller, woken = controller.observe(BLOCKER, OnRoute(2), now_blocker_leaves + 1)
    assert woken == (LATE,)
    return controller


def test_a_new_order_records_its_start_and_free_flow_estimate_and_a_replan_keeps_them() -> None:
    controller = BASE.assign(LATE, EASTBOUND, 3.0, new_order=True)
    record = controller.vehicle(LATE)
    assert (record.order_since, record.free_flow_s) == (3.0, 21.0)
    replanned = route_through(CROSSING, "w", "x", "n")
    controller, _ = _request(controller, LATE, replanned, 9.0)  # a re-plan: another route
    record = controller.vehicle(LATE)
    assert record.route == replanned
    assert (record.order_since, record.free_flow_s) == (3.0, 21.0)
    controller, _ = controller.finish(LATE, 20.0, AtNode("n"))
    assert (controller.vehicle(LATE).order_since, controller.vehicle(LATE).free_flow_s) == (
        None,
        None,
    )


def test_an_order_given_one_more_stop_is_due_against_both_legs() -> None:
    """Northbound s - x - n is 16 m (21 s with the dwell); one more stop n - f adds 8 m and
    the dwell (13 s): late at 2 x 34 s from the order's start, not at 2 x 21 s."""
    controller = BASE.assign(LATE, NORTHBOUND, 3.0, new_order=True)
    assert controller.vehicle(LATE).free_flow_s == 21.0
    controller = controller.add_leg(LATE, "n", "f", 30.0)
    record = controller.vehicle(LATE)
    assert (record.order_since, record.free_flow_s) == (3.0, 34.0)
    settings = controller.state.settings
    assert not is_late(record, settings, 3.0 + 2 * 21.0)
    assert is_late(record, settings, 3.0 + 2 * 34.0)
    assert due_time(record, settings) == 3.0 + settings.due_stretch * 34.0
    idle = BASE.add_leg(OTHER, "n", "f", 30.0)  # no order: nothing to extend
    assert idle.vehicle(OTHER).free_flow_s is None


def test_a_late_waiting_vehicle_is_not_overtaken_by_an_order_due_later() -> None:
    controller = _late_one_waits(now_blocker_leaves=50.0)
    controller = controller.assign(OTHER, NORTHBOUND, 45.0, new_order=True)
    controller, release = _request(controller, OTHER, NORTHBOUND, 52.0)
    assert release.end == 0
    assert release.blocked is not None
    assert release.blocked.claim
    assert release.blocked.refused.holder == LATE
    assert release.wait is not None
    assert release.wait.blockers == frozenset({LATE})
    assert node("x") not in controller.state.table.held_by(OTHER)
    # the late one goes on; once it has passed the crossing the other one gets it
    controller, release = _request(controller, LATE, EASTBOUND, 52.0)
    assert release.end == 2
    assert release.wait is None
    controller, woken = controller.observe(LATE, OnRoute(2), 60.0)
    assert woken == (OTHER,)
    controller, release = _request(controller, OTHER, NORTHBOUND, 60.0)
    assert release.end == 2
    assert release.wait is None


def test_a_vehicle_that_is_not_late_claims_nothing() -> None:
    controller = _late_one_waits(now_blocker_leaves=30.0)  # 30 s < 2 x 21 s: not late yet
    controller = controller.assign(OTHER, NORTHBOUND, 25.0, new_order=True)
    controller, release = _request(controller, OTHER, NORTHBOUND, 32.0)
    assert release.end == 2
    assert release.blocked is None
    assert {node("x"), edge("s-x")} <= controller.state.table.held_by(OTHER)


def test_an_order_due_earlier_goes_before_a_late_claim() -> None:
    controller = _late_one_waits(now_blocker_leaves=50.0)
    # OTHER's order started before LATE's: due earlier, so LATE's claim does not hold it back
    controller = controller.assign(OTHER, NORTHBOUND, -10.0, new_order=True)
    controller, release = _request(controller, OTHER, NORTHBOUND, 52.0)
    assert release.end == 2
    assert release.blocked is None


def test_a_claim_never_holds_back_a_vehicle_the_claimant_waits_for() -> None:
    """BLOCKER stands on the crossing that LATE claims and drives on through it: it must be
    released, or neither would ever move."""
    controller, _ = BASE.observe(BLOCKER, AtNode("x"), 0.0)
    controller = controller.assign(LATE, EASTBOUND, 0.0, new_order=True)
    controller, release = _request(controller, LATE, EASTBOUND, 0.0)
    assert release.wait is not None
    controller = controller.assign(BLOCKER, LEAVING, 60.0, new_order=True)
    controller, release = _request(controller, BLOCKER, LEAVING, 61.0)
    assert release.end == 2
    assert release.blocked is None
