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


def test_target_needs_exactly_one_of_destination_route_and_station_type() -> None:
    """A target with none or two of destination, route and station type is refused."""
    with pytest.raises(ValueError, match="exactly one"):
        Target()
    with pytest.raises(ValueError, match="exactly one"):
        Target(destination="10", route=("17",))
    with pytest.raises(ValueError, match="exactly one"):
        Target(destination="10", station_type="drop")


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


def test_a_station_type_takes_the_nearest_station_of_that_type() -> None:
    """From node 7 the drop station 13 is 16 m away and 14 is 26 m: 13; from node 3, 14."""
    west, east = _vehicle("west", "7"), _vehicle("east", "3")
    route = route_for(demo_graph(), west, Target(station_type="drop"))
    assert isinstance(route, Route)
    assert route.destination == "13"
    assert route.length_m == pytest.approx(16.0)
    chosen = choose_vehicle(demo_graph(), [east], Target(station_type="drop"))
    assert chosen is not None
    assert chosen[1].node_ids == ("3", "21", "9", "8", "14")


def test_a_busy_station_is_passed_over_while_another_of_its_type_is_free() -> None:
    """A station another vehicle is bound for or stands on is left out when one of the type is
    free, however much nearer it is; when all are busy, the nearest is taken all the same."""
    west = _vehicle("west", "7")
    chosen = choose_vehicle(demo_graph(), [west], Target(station_type="drop"), busy={"13"})
    assert chosen is not None
    assert chosen[1].destination == "14"
    crowded = choose_vehicle(demo_graph(), [west], Target(station_type="drop"), busy={"13", "14"})
    assert crowded is not None
    assert crowded[1].destination == "13"


def test_the_vehicle_nearest_to_any_station_of_the_type_is_chosen() -> None:
    """Without a vehicle named, the pair (vehicle, station) with the shortest route wins."""
    far, near = _vehicle("far", "1"), _vehicle("near", "9")
    chosen = choose_vehicle(demo_graph(), [far, near], Target(station_type="drop"))
    assert chosen is not None
    assert (chosen[0].agv.serial_number, chosen[1].destination) == ("near", "14")
    assert chosen[1].length_m == pytest.approx(8.0)
