"""Edge trajectories and corridors at the vehicle (§6.6.6 ``trajectory``, 2.1 §6.6.5
``corridor``; 3.0 §7.3, T101): taken when the curve is a NURBS that fits its nodes, driven
along the curve, corridors accepted and never used."""

from __future__ import annotations

import math
import statistics

import pytest

from tests.unit.vehicle.test_vehicle_v3 import Robot
from vda5050.models import (
    ControlPoint,
    Corridor,
    Edge,
    Error,
    Order,
    OrientationType,
    Trajectory,
    v3,
)
from vda5050.models.order import CorridorRefPoint
from vda5050.nurbs import build_curve, sample, uniform_knots
from vda5050.testing import make_order, make_order_v3
from vda_vehicle.config import VehicleSettings, capabilities
from vda_vehicle.factsheet import FactsheetTiming, build_factsheet
from vda_vehicle.model import Pose
from vda_vehicle.navigation import RouteEdge, SimulatedStack, Step, Waypoint, step, wrap
from vda_vehicle.order_executor import Accept, Reject, apply_order, decide_order
from vda_vehicle.testing import make_caps, make_stack, make_vehicle, reposition
from vda_vehicle.trajectories import path_of, unclamped
from vda_vehicle.translator import advance, quiet_time
from vda_vehicle.v3_inbound import to_core_order

CAPS = make_caps()
SPEED = CAPS.speed_max_mps
TURN = CAPS.angular_speed_max_radps
#: The test curve: a quarter circle of radius R from (0, 0) to (R, R) around (0, R),
#: counter-clockwise, as a rational degree 2 NURBS (middle weight sqrt(2) / 2).
R = 5.0
ARC_LENGTH = math.pi * R / 2
W = math.sqrt(2) / 2
START = Pose(0.0, 0.0, 0.0, "map")


def arc(*, start: tuple[float, float] = (0.0, 0.0), knots: list[float] | None = None) -> Trajectory:
    """The quarter circle, its first control point moved to ``start`` if given."""
    return Trajectory(
        degree=2,
        knot_vector=[0, 0, 0, 1, 1, 1] if knots is None else knots,
        control_points=[
            ControlPoint(x=start[0], y=start[1]),
            ControlPoint(x=R, y=0, weight=W),
            ControlPoint(x=R, y=R),
        ],
    )


def diagonal(count: int, degree: int = 1) -> Trajectory:
    """A straight curve from (0, 0) to (R, R) with ``count`` control points."""
    points = [ControlPoint(x=R * i / (count - 1), y=R * i / (count - 1)) for i in range(count)]
    knots = list(uniform_knots(degree, count))
    return Trajectory(degree=degree, knot_vector=knots, control_points=points)


def curved(trajectory: Trajectory | None = None, **edge: object) -> Order:
    """An order a (0, 0) -> b (R, R) along ``trajectory`` (default: the arc)."""
    order = make_order(["a", "b"], positions=[(0.0, 0.0), (R, R)])
    changed = order.edges[0].model_copy(update={"trajectory": trajectory or arc(), **edge})
    return order.model_copy(update={"edges": [Edge.model_validate(changed.model_dump())]})


def route_edge(theta: float | None = None, **kwargs: object) -> RouteEdge:
    """The stack's view of the arc edge (via the translator's path), ending on b."""
    order = curved()
    end = order.nodes[1].node_position
    assert end is not None
    path = path_of(order.edges[0], end)
    return RouteEdge("a-b", 1, Waypoint("b", R, R, theta, "map"), path=path, **kwargs)  # type: ignore[arg-type]


def off_arc(pose: Pose) -> float:
    return abs(math.hypot(pose.x, pose.y - R) - R)


def tangent(pose: Pose) -> float:
    """The arc's direction of travel at ``pose`` (counter-clockwise)."""
    return math.atan2(pose.y - R, pose.x) + math.pi / 2


def drive(edge: RouteEdge, dt: float, pose: Pose = START) -> list[Step]:
    """Every step of ``dt`` s until the edge is done."""
    steps: list[Step] = []
    while not steps or not steps[-1].arrived:
        steps.append(step(steps[-1].pose if steps else pose, edge, SPEED, TURN, dt))
        assert len(steps) < 10_000
    return steps


def rejection(order: Order) -> Error:
    """The one error rejecting ``order``; it names the edge."""
    decision = decide_order(make_vehicle(), order, CAPS)
    assert isinstance(decision, Reject), decision
    (error,) = decision.errors
    refs = {r.reference_key: r.reference_value for r in error.error_references or []}
    assert refs["edgeId"] == "a-b"
    return error


# -- driving ---------------------------------------------------------------------------------


def test_the_stack_drives_the_arc_on_its_tangent_at_the_edge_speed() -> None:
    """Every step ends within 1 cm of the circle, heading on its tangent, driving forwards at
    the edge's speed and turning at about v / R; the distance is the arc's length."""
    steps = drive(route_edge(), 0.05)
    for result in steps:
        assert off_arc(result.pose) < 0.01
    for result in steps[:-1]:
        assert abs(wrap(result.pose.theta - tangent(result.pose))) < 0.05
        assert result.motion.vx == pytest.approx(SPEED)
        assert result.motion.vy == pytest.approx(0.0, abs=1e-9)
    omega = statistics.median(result.motion.omega for result in steps)
    assert omega == pytest.approx(SPEED / R, rel=0.01)
    end = steps[-1]
    assert (end.pose.x, end.pose.y, end.motion.moving) == (R, R, False)
    assert sum(result.distance_m for result in steps) == pytest.approx(ARC_LENGTH, rel=1e-3)


def test_with_orientation_pi_the_arc_is_driven_backwards() -> None:
    """§6.6.6: TANGENTIAL applies along the trajectory; pi is driving backwards. The vehicle
    turns on the spot on entering the edge, then steers without stopping again."""
    steps = drive(route_edge(orientation=math.pi), 0.05)
    turning = [result for result in steps if result.distance_m == 0 and not result.arrived]
    assert turning == steps[: len(turning)]
    assert len(turning) == pytest.approx(math.pi / TURN / 0.05, abs=2)
    for result in steps[len(turning) + 1 : -1]:
        assert abs(wrap(result.pose.theta - tangent(result.pose) - math.pi)) < 0.05
        assert result.motion.vx == pytest.approx(-SPEED)
    assert sum(result.distance_m for result in steps) == pytest.approx(ARC_LENGTH, rel=1e-3)


@pytest.mark.parametrize("dt", [0.05, 0.3, 1.7])
def test_any_step_ends_in_the_same_pose_at_the_same_time(dt: float) -> None:
    """The stack is steady (exact for any dt): small steps and one step over the whole edge
    end in the same pose (the end node's theta reached too), at the same time."""
    edge = route_edge(theta=math.pi)
    (whole,) = drive(edge, 1_000.0)
    steps = drive(edge, dt)
    assert steps[-1].pose == whole.pose == Pose(R, R, math.pi, "map")
    assert sum(result.used_s for result in steps) == pytest.approx(whole.used_s, abs=1e-9)
    assert sum(result.distance_m for result in steps) == pytest.approx(whole.distance_m)
    stack = SimulatedStack(SPEED, TURN)
    feedback = stack.drive(START, (edge,), hold=False, dt=1_000.0)
    assert (feedback.pose, feedback.distance_m) == (whole.pose, whole.distance_m)


def test_a_vehicle_on_a_curved_edge_stays_on_it_ticked_every_tick() -> None:
    """The translator hands the stack the sampled curve: the vehicle stays on the arc, reaches
    b, and drains the battery for the arc's length; no tick is skipped on the curve (the
    cruise arithmetic of quiet_time is a straight line's)."""
    state = apply_order(make_vehicle(), curved(), "new", CAPS)
    stack = make_stack(CAPS)
    while state.nodes:
        assert quiet_time(state) == 0.0
        state = advance(state, 0.05, caps=CAPS, stack=stack)
        assert off_arc(state.pose) < 0.01
    assert (state.last_node_id, state.pose.x, state.pose.y) == ("b", R, R)
    driven = (100.0 - state.battery_charge) / CAPS.battery_drain_pct_per_m
    assert driven == pytest.approx(ARC_LENGTH, rel=1e-3)


# -- order acceptance ------------------------------------------------------------------------


def test_an_order_along_a_trajectory_with_a_corridor_is_accepted() -> None:
    corridor = Corridor(
        left_width=0.5, right_width=0.5, corridor_ref_point=CorridorRefPoint.CONTOUR
    )
    assert decide_order(make_vehicle(), curved(corridor=corridor), CAPS) == Accept("new")


def test_a_trajectory_that_is_no_nurbs_is_a_validation_error_naming_the_edge() -> None:
    error = rejection(curved(arc(knots=[0, 0, 0, 1, 1])))
    assert error.error_type == "validationError"
    assert error.error_description == (
        "edge a-b's trajectory: knotVector has 5 knots; 3 control points of degree 2 need 6"
    )


def test_a_trajectory_away_from_its_nodes_is_rejected_beyond_their_deviation() -> None:
    """The start and end of the curve lie within the node's allowedDeviationXY, or the
    vehicle's own when it gives none."""
    away = curved(arc(start=(0.0, 2.0)))
    error = rejection(away)
    assert error.error_type == "validationError"
    assert error.error_description == (
        "edge a-b's trajectory starts 2.00 m from node a (allowed: 0.25 m)"
    )
    tolerant = reposition(away, 0, allowed_deviation_xy=2.5)
    assert decide_order(make_vehicle(), tolerant, CAPS) == Accept("new")
    moved = rejection(reposition(curved(), 1, y=R + 1.0))
    assert moved.error_description == (
        "edge a-b's trajectory ends 1.00 m from node b (allowed: 0.25 m)"
    )


def test_a_degree_the_stack_does_not_follow_is_an_order_error() -> None:
    error = rejection(curved(diagonal(7, degree=6)))
    assert error.error_type == "orderError"
    assert "has degree 6; this vehicle follows degrees 1 to 5" in (error.error_description or "")
    assert decide_order(make_vehicle(), curved(diagonal(6, degree=5)), CAPS) == Accept("new")


def test_trajectory_sizes_are_declared_and_enforced() -> None:
    """§6.15 maxArrayLens trajectory.knotVector and trajectory.controlPoints: declared in the
    factsheet, a longer trajectory is a validationError naming the limit (R36)."""
    timing = FactsheetTiming(
        min_state_interval_s=0.2, state_interval_s=30, visualization_interval_s=1
    )
    arrays = build_factsheet(CAPS, timing, version="2.1.0").protocol_limits.max_array_lens
    assert (arrays.trajectory_control_points, arrays.trajectory_knot_vector) == (256, 262)
    decision = decide_order(make_vehicle(), curved(diagonal(257)), CAPS)
    assert isinstance(decision, Reject)
    (error,) = decision.errors
    assert error.error_type == "validationError"
    assert error.error_description == (
        "trajectory.controlPoints holds 257 entries, over the limit of 256 (factsheet maxArrayLens)"
    )
    assert decide_order(make_vehicle(), curved(diagonal(256)), CAPS) == Accept("new")


def test_the_factsheet_declares_trajectories_and_corridors() -> None:
    """R112: both are SUPPORTED and say how far; 2.0 has no corridor: a 2.0 vehicle neither
    declares nor takes one (R32)."""
    timing = FactsheetTiming(
        min_state_interval_s=0.2, state_interval_s=30, visualization_interval_s=1
    )
    declared = {
        p.parameter: (p.support.value, p.description)
        for p in build_factsheet(
            CAPS, timing, version="2.1.0"
        ).protocol_features.optional_parameters
    }
    assert declared["order.edges.trajectory"] == (
        "SUPPORTED",
        "NURBS of degree 1 to 5, followed exactly",
    )
    assert declared["order.edges.corridor"][0] == "SUPPORTED"
    older = capabilities(VehicleSettings(vda_version="2.0.0"), None)
    listed = build_factsheet(older, timing, version="2.0.0").protocol_features.optional_parameters
    assert {p.parameter for p in listed} == set(CAPS.supported_fields) - {"order.edges.corridor"}
    corridor = Corridor(left_width=0.5, right_width=0.5)
    decision = decide_order(make_vehicle(), curved(corridor=corridor), older)
    assert isinstance(decision, Reject)
    assert "order.edges.corridor (edge a-b) is not supported" in {
        e.error_description for e in decision.errors
    }


def test_a_differential_drive_holds_a_global_orientation_only_on_a_straight_trajectory() -> None:
    """R34 along the curve: TANGENTIAL follows its tangent (forwards or backwards); GLOBAL
    cannot be held on a curve, but on a straight trajectory along its direction."""
    diff = make_caps(kinematic="DIFF")
    backwards = curved(orientation=math.pi)
    assert decide_order(make_vehicle(), backwards, diff) == Accept("new")
    fixed = curved(orientation=math.pi / 4, orientation_type=OrientationType.GLOBAL)
    decision = decide_order(make_vehicle(), fixed, diff)
    assert isinstance(decision, Reject)
    assert "cannot be held by a differential-drive vehicle" in (
        decision.errors[0].error_description or ""
    )
    straight = curved(diagonal(3), orientation=math.pi / 4, orientation_type=OrientationType.GLOBAL)
    assert decide_order(make_vehicle(), straight, diff) == Accept("new")


# -- 3.0 -------------------------------------------------------------------------------------


def arc_v3(knots: list[float] | None = None) -> v3.Trajectory:
    """The quarter circle without knotVector: 3.0's default uniform knots are the arc's."""
    return v3.Trajectory(
        degree=2,
        knot_vector=knots,
        control_points=[
            v3.ControlPoint(x=0.0, y=0.0),
            v3.ControlPoint(x=R, y=0.0, weight=W),
            v3.ControlPoint(x=R, y=R),
        ],
    )


def curved_v3(trajectory: v3.Trajectory, **edge: object) -> v3.Order:
    order = make_order_v3(["a", "b"], positions=[(0.0, 0.0), (R, R)])
    update = {"trajectory": trajectory, **edge}
    return order.model_copy(update={"edges": [order.edges[0].model_copy(update=update)]})


def test_a_3_0_order_with_a_trajectory_without_knots_is_accepted_and_driven() -> None:
    """T101: degree and knotVector default; a corridor with releaseRequired is taken (the
    vehicle never leaves the trajectory, so it never needs an edgeRequest, T94)."""
    robot = Robot()
    corridor = v3.Corridor(left_width=0.5, right_width=0.5, release_required=True)
    robot.order(curved_v3(arc_v3(), corridor=corridor))
    state = robot.state()
    assert (state["orderId"], state["errors"]) == ("order-1", [])
    for _ in range(10):
        robot.run(0.4)
        assert off_arc(robot.runtime.state.pose) < 0.01
    robot.run(ARC_LENGTH / SPEED)
    state = robot.state()
    position = state["mobileRobotPosition"]
    assert (state["lastNodeId"], position["x"], position["y"]) == ("b", R, R)


def test_3_0_trajectories_and_corridors_map_onto_the_core_edge() -> None:
    """Defaults filled in (the core's 2.x trajectory needs both); KINEMATIC_CENTER is 2.1's
    KINEMATICCENTER; releaseRequired and releaseLossBehavior have no 2.x field."""
    line = v3.Trajectory(control_points=[v3.ControlPoint(x=0, y=0), v3.ControlPoint(x=R, y=R)])
    corridor = v3.Corridor(
        left_width=1.0,
        right_width=2.0,
        corridor_reference_point=v3.CorridorReferencePoint.KINEMATIC_CENTER,
        release_required=True,
        release_loss_behavior=v3.CorridorReleaseLossBehavior.RETURN,
    )
    edge = to_core_order(curved_v3(line, corridor=corridor)).edges[0]
    assert edge.trajectory == Trajectory(
        degree=1,
        knot_vector=[0.0, 0.0, 1.0, 1.0],
        control_points=[ControlPoint(x=0, y=0), ControlPoint(x=R, y=R)],
    )
    assert edge.corridor == Corridor(
        left_width=1.0, right_width=2.0, corridor_ref_point=CorridorRefPoint.KINEMATICCENTER
    )
    contour = corridor.model_copy(
        update={"corridor_reference_point": v3.CorridorReferencePoint.CONTOUR}
    )
    edge = to_core_order(curved_v3(line, corridor=contour)).edges[0]
    assert edge.corridor is not None
    assert edge.corridor.corridor_ref_point is CorridorRefPoint.CONTOUR


def test_a_3_0_knot_vector_must_be_clamped() -> None:
    """3.0 §7.3: first and last knot degree + 1 times, inner ones at most degree times; else
    VALIDATION_FAILURE. A bad curve is one too, a degree the stack does not follow
    NO_ROUTE_TO_TARGET."""
    assert unclamped(2, [0, 0, 0, 1, 1, 1]) is None
    assert unclamped(1, [0, 0.1, 0.5, 0.9, 1]) == (
        "the first and last knots must each appear degree + 1 = 2 times"
    )
    assert unclamped(2, [0, 0, 0, 0.5, 0.5, 0.5, 1, 1, 1]) == (
        "no inner knot may appear more than degree = 2 times"
    )
    robot = Robot()
    # Unclamped, yet from node to node: a degree 1 curve passes its control points.
    line = v3.Trajectory(
        degree=1,
        knot_vector=[0, 0.1, 0.5, 0.9, 1],
        control_points=[
            v3.ControlPoint(x=0, y=0),
            v3.ControlPoint(x=R, y=0),
            v3.ControlPoint(x=R, y=R),
        ],
    )
    robot.order(curved_v3(line))
    [error] = robot.state()["errors"]
    assert (error["errorType"], error["errorDescription"]) == (
        "VALIDATION_FAILURE",
        "edge a-b's trajectory: the first and last knots must each appear degree + 1 = 2 times",
    )
    robot.order(curved_v3(arc_v3(knots=[0, 0, 1, 1])))
    assert robot.errors()[-1] == ("VALIDATION_FAILURE", "WARNING")
    assert robot.state()["orderId"] == ""


def _tight(radius: float, **kwargs: object) -> RouteEdge:
    """The stack's view of a quarter circle of ``radius`` from (0, 0) to (radius, radius)."""
    curve = build_curve(
        2, [0, 0, 0, 1, 1, 1], [(0.0, 0.0, None), (radius, 0.0, W), (radius, radius, None)]
    )
    assert not isinstance(curve, str)
    path = (*sample(curve)[1:-1], (radius, radius))
    end = Waypoint("b", radius, radius, None, "map")
    return RouteEdge("a-b", 1, end, path=path, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(("max_rotation", "top"), [(None, TURN * 1.0), (0.5, 0.5)])
def test_a_tight_curve_is_driven_no_faster_than_the_vehicle_may_turn(
    max_rotation: float | None, top: float
) -> None:
    """Radius 1 m: omega = v / r must stay within the angular speed (the vehicle's, or the
    edge's maxRotationSpeed), so the speed on the curve is at most that times r."""
    stack = SimulatedStack(SPEED, TURN)
    edge = _tight(1.0, max_rotation_speed=max_rotation)
    assert top < SPEED  # the cap, not the edge speed, decides
    pose, seconds, speeds, omegas = START, 0.0, [], []
    while True:
        feedback = stack.drive(pose, (edge,), hold=False, dt=0.05)
        pose, seconds = feedback.pose, seconds + 0.05
        if not feedback.motion.moving:
            break
        speeds.append(math.hypot(feedback.motion.vx, feedback.motion.vy))
        omegas.append(abs(feedback.motion.omega))
    assert max(omegas) <= top / 1.0 + 1e-9  # the turn rate is never exceeded
    assert max(speeds) <= top * 1.02  # legs of a sampled arc differ in length by about 1 %
    assert statistics.median(speeds) == pytest.approx(top, rel=0.02)
    assert seconds == pytest.approx((math.pi / 2) / top, rel=0.05)
