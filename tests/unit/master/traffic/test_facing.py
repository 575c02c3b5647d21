"""A new route does not start straight into a cycle (``advice.facing``): a vehicle that has just
picked at an aisle's position 5 and is sent north, where another vehicle waits on position 6 to
come south past it, leaves south instead (the deadlock this avoided cost a back-off each)."""

from __future__ import annotations

from vda_master.routing import Route
from vda_master.traffic.controller import AtNode, OnRoute, TrafficController
from vda_master.traffic.testing import SIM_SAFETY_M, agv, route_through, warehouse_graph

PICKER, COMING = agv("picker"), agv("coming")
WAREHOUSE = warehouse_graph()
#: Into aisle B from the north inner lane, past the pick station B5, to the one at B2.
SOUTHWARDS = route_through(WAREHOUSE, "NI2", "B6", "B5", "B3", "B2")


def _floor() -> TrafficController:
    controller = TrafficController.for_graph(WAREHOUSE, SIM_SAFETY_M)
    controller, _ = controller.observe(PICKER, AtNode("B5"), 0.0)
    controller, _ = controller.observe(COMING, AtNode("NI2"), 0.0)
    return controller


def _request(controller: TrafficController, progress: int, now: float) -> TrafficController:
    record = controller.vehicle(COMING)
    granted = record.granted_end if record.route == SOUTHWARDS else 0
    controller, _ = controller.request_release(
        COMING, SOUTHWARDS, progress_index=progress, released_end=max(granted, progress),
        desired_end=progress + 3, now=now,
    )  # fmt: skip
    return controller


def _coming_waits_on_b6() -> TrafficController:
    """COMING is released onto B6 (the last node before B5, where the aisle's two ways part)
    and waits there for B5, where PICKER stands."""
    controller = _floor().assign(COMING, SOUTHWARDS, 0.0, new_order=True)
    controller = _request(controller, 0, 0.0)
    assert controller.vehicle(COMING).granted_end == 1  # B6
    controller, _ = controller.observe(COMING, OnRoute(1), 2.0)
    controller = _request(controller, 1, 2.0)
    wait = controller.vehicle(COMING).wait
    assert wait is not None
    assert wait.blockers == {PICKER}
    return controller


def _first_nodes(route: Route) -> tuple[str, ...]:
    return route.node_ids[:2]


def test_alone_the_picker_leaves_north_towards_the_north_bay() -> None:
    alone, _ = TrafficController.for_graph(WAREHOUSE, SIM_SAFETY_M).observe(
        PICKER, AtNode("B5"), 0.0
    )
    planned = alone.plan(PICKER, "B5", "DR2", 3.0)
    assert planned is not None
    assert _first_nodes(planned.route) == ("B5", "B6")


def test_with_a_vehicle_waiting_for_it_on_b6_the_picker_leaves_south() -> None:
    controller = _coming_waits_on_b6()
    planned = controller.plan(PICKER, "B5", "DR2", 3.0)
    assert planned is not None
    assert _first_nodes(planned.route) == ("B5", "B3")
    assert planned.route.destination == "DR2"
    # the way south is free: released at once, and COMING gets B5 once PICKER has left it
    controller = controller.assign(PICKER, planned.route, 3.0, new_order=True)
    controller, release = controller.request_release(
        PICKER, planned.route, progress_index=0, released_end=0, desired_end=3, now=3.0
    )
    assert release.end > 0
    controller, woken = controller.observe(PICKER, OnRoute(2), 5.0)
    assert woken == (COMING,)


def test_a_vehicle_about_to_come_counts_as_well() -> None:
    """COMING is released onto B6 but has not reached it yet: its next step needs B5 all the
    same, so the picker's route north would meet it head-on."""
    controller = _floor().assign(COMING, SOUTHWARDS, 0.0, new_order=True)
    controller = _request(controller, 0, 0.0)
    assert controller.vehicle(COMING).wait is None
    planned = controller.plan(PICKER, "B5", "DR2", 1.0)
    assert planned is not None
    assert _first_nodes(planned.route) == ("B5", "B3")
