"""Route requests and vehicle selection (§6.6.1; architecture §3.4 POST /orders)."""

from __future__ import annotations

import pytest

from vda5050.testing import make_state
from vda5050.topics import AgvId
from vda_master.fleet import VehicleView
from vda_master.planner import Target, choose_vehicle, route_for
from vda_master.routing import ProblemKind, Route, RouteProblem
from vda_master.testing import demo_graph


def _vehicle(serial: str, node: str | None) -> VehicleView:
    state = make_state(last_node_id=node or "", serial_number=serial)
    return VehicleView(AgvId("acme", serial), 0.0, 0.0, state=state)


def test_target_needs_exactly_one_of_destination_and_route() -> None:
    """A target with both or neither of destination and route is refused."""
    with pytest.raises(ValueError, match="exactly one"):
        Target()
    with pytest.raises(ValueError, match="exactly one"):
        Target(destination="10", route=("17",))


def test_route_for_destination_starts_at_the_vehicle() -> None:
    """A destination is reached by the shortest route from the vehicle's node."""
    route = route_for(demo_graph(), _vehicle("a", "7"), Target(destination="10"))
    assert isinstance(route, Route)
    assert route.edge_ids == ("17", "12", "11")


def test_route_for_vehicle_off_the_graph() -> None:
    """A vehicle that stands on no node gets no route."""
    problem = route_for(demo_graph(), _vehicle("a", None), Target(destination="10"))
    assert isinstance(problem, RouteProblem)
    assert problem.kind == ProblemKind.NO_POSITION


def test_closest_vehicle_is_chosen() -> None:
    """Of two vehicles the one with the shorter route to the destination is chosen."""
    far, near = _vehicle("far", "4"), _vehicle("near", "1")
    chosen = choose_vehicle(demo_graph(), [far, near], Target(destination="10"))
    assert chosen is not None
    assert chosen[0] is near


def test_explicit_route_picks_the_vehicle_at_its_start() -> None:
    """An explicit route without a vehicle goes to a vehicle standing where it starts."""
    elsewhere, there = _vehicle("x", "4"), _vehicle("y", "7")
    chosen = choose_vehicle(demo_graph(), [elsewhere, there], Target(route=("17", "12")))
    assert chosen is not None
    assert chosen[0] is there


def test_no_candidate_no_choice() -> None:
    """Without a vehicle that can reach the target there is no choice."""
    assert choose_vehicle(demo_graph(), [], Target(destination="10")) is None
