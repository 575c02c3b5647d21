"""The simulated navigation stack and its pure kinematics (issue item 4)."""

from __future__ import annotations

import math

import pytest

from vda5050.models import OrientationType
from vda_vehicle.model import Pose
from vda_vehicle.navigation import EdgeExecution, RouteEdge, SimulatedStack, Waypoint, step, wrap

STACK = SimulatedStack(speed_max_mps=2.0, angular_speed_max_radps=1.0)


def edge(x: float, y: float, theta: float | None = None, **kwargs: object) -> RouteEdge:
    return RouteEdge("e", 1, Waypoint("n", x, y, theta, "map"), **kwargs)  # type: ignore[arg-type]


def test_straight_line_at_speed_max() -> None:
    """The stack drives a straight line at speedMax when the edge sets no limit."""
    result = step(Pose(0, 0, 0, "map"), edge(10, 0), 2.0, 1.0, 1.0)
    assert (result.pose.x, result.pose.y, result.distance_m) == (2.0, 0.0, 2.0)
    assert result.motion.vx == 2.0
    assert not result.arrived


def test_speed_is_min_of_edge_max_speed_and_speed_max() -> None:
    """Speed is min(edge maxSpeed, speedMax)."""
    slow = STACK.drive(Pose(0, 0, 0, "map"), (edge(10, 0, max_speed=0.5),), hold=False, dt=1)
    assert slow.pose.x == pytest.approx(0.5)
    fast = STACK.drive(Pose(0, 0, 0, "map"), (edge(10, 0, max_speed=9.0),), hold=False, dt=1)
    assert fast.pose.x == pytest.approx(2.0)


def test_turns_before_driving_and_to_node_theta() -> None:
    """The vehicle turns to the edge heading, drives, then turns to the end node's theta."""
    start = Pose(0, 0, 0, "map")
    turning = step(start, edge(0, 2, theta=math.pi), 2.0, 1.0, 1.0)
    assert turning.pose.theta == pytest.approx(1.0)
    assert turning.motion.omega == 1.0
    assert (turning.pose.x, turning.pose.y) == (0, 0)
    done = step(start, edge(0, 2, theta=math.pi), 2.0, 1.0, 10.0)
    assert done.arrived
    assert done.pose.theta == pytest.approx(math.pi)
    assert done.used_s == pytest.approx(math.pi / 2 + 1.0 + math.pi / 2)


def test_global_orientation_on_omni_vehicle() -> None:
    """§6.6.6: with GLOBAL orientation the vehicle holds that heading while it drives sideways."""
    result = step(
        Pose(0, 0, math.pi / 2, "map"),
        edge(10, 0, orientation=math.pi / 2, orientation_type=OrientationType.GLOBAL),
        2.0,
        1.0,
        1.0,
    )
    assert result.pose.theta == pytest.approx(math.pi / 2)
    assert result.motion.vy == pytest.approx(-2.0)


def test_hold_means_standstill() -> None:
    """R73, R76: with hold the stack does not move and reports no motion."""
    feedback = STACK.drive(Pose(0, 0, 0, "map"), (edge(10, 0),), hold=True, dt=1)
    assert feedback.pose == Pose(0, 0, 0, "map")
    assert not feedback.motion.moving
    assert feedback.reports == ()


def test_completes_several_edges_in_one_long_step_and_stops_at_route_end() -> None:
    """The stack reports each edge COMPLETED in order and never drives past the route."""
    route = (
        RouteEdge("e1", 1, Waypoint("b", 2, 0, None, "map")),
        RouteEdge("e2", 3, Waypoint("c", 4, 0, None, "map")),
    )
    feedback = STACK.drive(Pose(0, 0, 0, "map"), route, hold=False, dt=100)
    assert [r.execution for r in feedback.reports] == [EdgeExecution.COMPLETED] * 2
    assert (feedback.pose.x, feedback.motion.moving) == (4, False)
    assert feedback.distance_m == pytest.approx(4)


def test_edge_onto_another_map_is_aborted() -> None:
    """ABORTED: the stack cannot drive onto another map's coordinates."""
    other = RouteEdge("e", 1, Waypoint("n", 5, 0, None, "floor2"))
    feedback = STACK.drive(Pose(0, 0, 0, "map"), (other,), hold=False, dt=1)
    assert [r.execution for r in feedback.reports] == [EdgeExecution.ABORTED]


def test_wrap_keeps_angles_in_range() -> None:
    """R102: orientations lie in [-pi, pi]."""
    for angle in (-7.0, -math.pi, 0.0, 3.0, 4.0, 10.0):
        assert -math.pi <= wrap(angle) <= math.pi
