"""The navigation-stack seam and the simulated stack (architecture §1, issue item 4).

The translator hands the stack a *target route*: the released edges the vehicle may drive now,
each with its end node's position. The stack answers with its pose, its speeds and one
execution report per edge it worked on: MOVING, COMPLETED or ABORTED. A real robot plugs in its
own :class:`NavigationStack`; nothing above this module changes. What the robot does on its own
(an operator switching it to MANUAL, an emergency stop) its stack reports whenever it changes,
through :meth:`vda_vehicle.runtime.VehicleRuntime.on_stack_status`
(:mod:`vda_vehicle.vehicle_status`).

The simulated stack is an omnidirectional vehicle: it turns to the edge's heading, drives a
straight line to the end node at min(edge maxSpeed, speedMax), then turns to the node's theta if
one is given. Along an edge's trajectory it drives the sampled curve (:attr:`RouteEdge.path`):
it turns on the spot to the first leg's heading, then steers from vertex to vertex at the
edge's speed, slower where the curve bends faster than it may turn (omega = v / r at most
its angular speed, or the edge's maxRotationSpeed). Acceleration is taken as instantaneous.
Its kinematics are pure functions of (pose, target, speed, dt), so the simulated stack is
itself pure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import ClassVar, Final, Protocol

from vda5050.models import OrientationType
from vda5050.nurbs import Point
from vda_vehicle.model import STANDSTILL, Motion, Pose

#: Closer than this (m, rad) counts as there.
EPSILON: Final = 1e-6
#: A pose this close to a leg of a path (m) is on it (rounding of the steps along it).
_ON_PATH_M: Final = 1e-6


@dataclass(frozen=True, slots=True)
class Waypoint:
    """Where an edge ends: the end node's position, and theta if the node sets one."""

    node_id: str
    x: float
    y: float
    theta: float | None
    map_id: str


@dataclass(frozen=True, slots=True)
class RouteEdge:
    """One edge of the target route; speeds in m/s and rad/s, None = no limit."""

    edge_id: str
    sequence_id: int
    end: Waypoint
    max_speed: float | None = None
    orientation: float | None = None
    orientation_type: OrientationType | None = None
    max_rotation_speed: float | None = None
    #: The edge's trajectory (§6.6.6) as a polyline: its points after the start, the last one
    #: the end node's position. None: the straight line to the end node.
    path: tuple[Point, ...] | None = None


TargetRoute = tuple[RouteEdge, ...]


class EdgeExecution(StrEnum):
    MOVING = "MOVING"
    COMPLETED = "COMPLETED"
    ABORTED = "ABORTED"


@dataclass(frozen=True, slots=True)
class EdgeReport:
    edge_id: str
    sequence_id: int
    execution: EdgeExecution


@dataclass(frozen=True, slots=True)
class NavFeedback:
    """One step's outcome. ``distance_m`` is driven in total, ``distance_on_edge_m`` since the
    last COMPLETED edge (for distanceSinceLastNode)."""

    pose: Pose
    motion: Motion
    reports: tuple[EdgeReport, ...] = ()
    distance_m: float = 0.0
    distance_on_edge_m: float = 0.0


class NavigationStack(Protocol):
    """What the vehicle needs from a navigation stack."""

    def drive(self, pose: Pose, route: TargetRoute, *, hold: bool, dt: float) -> NavFeedback:
        """Work on ``route`` for ``dt`` seconds from ``pose`` (a real stack reports its own pose).

        With ``hold`` the vehicle must stand still (pause, blocking action, cancel). The stack
        never drives beyond the last edge of ``route``. With no ``route`` (the vehicle has
        nothing to drive) it is still asked for its pose, so that a robot driven by hand or
        pushed aside is reported where it is (§6.10.6 agvPosition, §6.13).
        """
        ...


def is_steady(stack: NavigationStack) -> bool:
    """Whether ``stack`` drives each edge at one speed, integrates any ``dt`` exactly and never
    moves on its own (the simulated stack): its vehicle's ticks can be skipped while nothing can
    happen (:func:`vda_vehicle.translator.quiet_time`). Any other stack is asked every tick."""
    return bool(getattr(stack, "steady", False))


# -- pure kinematics ----------------------------------------------------------------------------


def wrap(angle: float) -> float:
    """``angle`` in [-pi, pi]."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


@dataclass(frozen=True, slots=True)
class Step:
    """Result of :func:`step`: new pose, time used, distance driven, and whether it arrived."""

    pose: Pose
    used_s: float
    distance_m: float
    arrived: bool
    motion: Motion


def edge_heading(pose: Pose, edge: RouteEdge) -> float:
    """The heading to hold on the edge (§6.6.6 orientation, orientationType TANGENTIAL default)."""
    return oriented(edge, math.atan2(edge.end.y - pose.y, edge.end.x - pose.x))


def oriented(edge: RouteEdge, travel: float) -> float:
    """The heading to hold while travelling in direction ``travel`` on ``edge`` (§6.6.6: along
    a trajectory, TANGENTIAL is relative to its tangent)."""
    if edge.orientation is None:
        return travel
    if edge.orientation_type is OrientationType.GLOBAL:
        return edge.orientation
    return wrap(travel + edge.orientation)


def rotate(pose: Pose, goal: float, rate: float, dt: float) -> tuple[Pose, float, float]:
    """Turn towards ``goal`` at ``rate`` rad/s for up to ``dt`` s: (pose, time used, omega)."""
    if pose.theta == goal:  # holding the heading: most ticks of a driving vehicle
        return pose, 0.0, 0.0
    delta = wrap(goal - pose.theta)
    if abs(delta) <= EPSILON:
        return Pose(pose.x, pose.y, goal, pose.map_id), 0.0, 0.0
    needed = abs(delta) / rate
    used = min(needed, dt)
    omega = math.copysign(rate, delta)
    theta = goal if used == needed else wrap(pose.theta + omega * used)
    return Pose(pose.x, pose.y, theta, pose.map_id), used, omega


def translate(pose: Pose, x: float, y: float, speed: float, dt: float) -> tuple[Pose, float, float]:
    """Drive straight towards (x, y) at ``speed`` for up to ``dt`` s: (pose, time, distance)."""
    distance = pose.distance_to(x, y)
    if speed <= 0:
        return pose, dt, 0.0
    if distance <= EPSILON:
        return Pose(x, y, pose.theta, pose.map_id), 0.0, 0.0
    used = min(distance / speed, dt)
    if used * speed >= distance:
        return Pose(x, y, pose.theta, pose.map_id), used, distance
    fraction = used * speed / distance
    moved = Pose(
        pose.x + (x - pose.x) * fraction, pose.y + (y - pose.y) * fraction, pose.theta, pose.map_id
    )
    return moved, used, used * speed


def step(pose: Pose, edge: RouteEdge, speed: float, turn_rate: float, dt: float) -> Step:
    """Follow ``edge`` for up to ``dt`` s: turn to its heading, drive, turn to the end theta.
    Along its ``path`` if it has one (:func:`_follow`)."""
    if edge.path:
        return _follow(pose, edge, edge.path, speed, turn_rate=turn_rate, dt=dt)
    used = 0.0
    if pose.distance_to(edge.end.x, edge.end.y) > EPSILON:
        pose, spent, omega = rotate(pose, edge_heading(pose, edge), turn_rate, dt)
        used += spent
        if used >= dt and omega:
            return Step(pose, used, 0.0, arrived=False, motion=Motion(omega=omega))
        travel = math.atan2(edge.end.y - pose.y, edge.end.x - pose.x)
        pose, spent, distance = translate(pose, edge.end.x, edge.end.y, speed, dt - used)
        used += spent
        if pose.distance_to(edge.end.x, edge.end.y) > EPSILON:
            return Step(pose, used, distance, arrived=False, motion=_drive(speed, travel, pose))
    else:
        distance = 0.0
    return _at_end(pose, edge, turn_rate, dt, used=used, distance=distance)


def _at_end(
    pose: Pose, edge: RouteEdge, turn_rate: float, dt: float, *, used: float, distance: float
) -> Step:
    """On the end node after ``used`` s: turn to its theta if it sets one, then arrived."""
    if edge.end.theta is not None:
        pose, spent, omega = rotate(pose, edge.end.theta, turn_rate, dt - used)
        used += spent
        if abs(wrap(edge.end.theta - pose.theta)) > EPSILON:
            return Step(pose, used, distance, arrived=False, motion=Motion(omega=omega))
    arrived = Pose(edge.end.x, edge.end.y, pose.theta, edge.end.map_id)
    return Step(arrived, used, distance, arrived=True, motion=STANDSTILL)


def _follow(
    pose: Pose,
    edge: RouteEdge,
    path: tuple[Point, ...],
    speed: float,
    *,
    turn_rate: float,
    dt: float,
) -> Step:
    """:func:`step` along ``path``: on entering the edge (the first leg, from where the vehicle
    stands to ``path[0]``) turn on the spot to its heading; then drive from vertex to vertex at
    ``speed``, the heading following each leg (§6.6.6: the orientation applies along the
    trajectory) without stopping to turn, as a vehicle steering along the curve does; on a leg
    that bends faster than ``turn_rate`` allows at ``speed``, slower (:func:`_bend`). The pose
    stays on the path, so the next step finds its leg again (:func:`_leg_at`)."""
    leg = _leg_at(pose, path)
    used = distance = 0.0
    if leg == 0 and pose.distance_to(*path[0]) > EPSILON:
        travel = math.atan2(path[0][1] - pose.y, path[0][0] - pose.x)
        pose, used, omega = rotate(pose, oriented(edge, travel), turn_rate, dt)
        if used >= dt and omega:
            return Step(pose, used, 0.0, arrived=False, motion=Motion(omega=omega))
    for index in range(leg, len(path)):
        x, y = path[index]
        if pose.distance_to(x, y) <= EPSILON:
            pose = Pose(x, y, pose.theta, pose.map_id)
            continue
        travel = _leg_direction(pose, path, index)
        heading = oriented(edge, travel)
        if heading != pose.theta:
            pose = Pose(pose.x, pose.y, heading, pose.map_id)
        turn, length = _bend(path, index, travel)
        if edge.orientation is not None and edge.orientation_type is OrientationType.GLOBAL:
            turn = 0.0  # the heading holds: the vehicle does not turn with the curve
        # The heading turns by ``turn`` along this leg: no faster than the turn rate allows.
        leg_speed = speed if not turn else min(speed, turn_rate * length / abs(turn))
        pose, spent, moved = translate(pose, x, y, leg_speed, dt - used)
        used += spent
        distance += moved
        if pose.distance_to(x, y) > EPSILON:
            omega = turn * leg_speed / length if length > EPSILON else 0.0
            return Step(
                pose, used, distance, arrived=False, motion=_drive(leg_speed, travel, pose, omega)
            )
    return _at_end(pose, edge, turn_rate, dt, used=used, distance=distance)


def _leg_at(pose: Pose, path: tuple[Point, ...]) -> int:
    """The leg of ``path`` the vehicle is on: ``i`` >= 1 for the segment ``path[i-1]`` to
    ``path[i]`` (the latest that holds the pose: on a path that crosses itself the vehicle
    never drives a loop twice), 0 for the first leg, from where it entered to ``path[0]`` (and
    for a pose off the path, which then drives to ``path[0]`` first)."""
    x, y = pose.x, pose.y
    for i in range(len(path) - 1, 0, -1):
        (ax, ay), (bx, by) = path[i - 1], path[i]
        if (
            min(ax, bx) - _ON_PATH_M <= x <= max(ax, bx) + _ON_PATH_M
            and min(ay, by) - _ON_PATH_M <= y <= max(ay, by) + _ON_PATH_M
            and abs((bx - ax) * (y - ay) - (by - ay) * (x - ax))
            <= _ON_PATH_M * math.hypot(bx - ax, by - ay)
        ):
            return i
    return 0


def _leg_direction(pose: Pose, path: tuple[Point, ...], index: int) -> float:
    """The direction of travel on leg ``index``: from its vertices, or on the first leg from
    the pose (where the vehicle entered the edge)."""
    ax, ay = path[index - 1] if index else (pose.x, pose.y)
    return math.atan2(path[index][1] - ay, path[index][0] - ax)


def _bend(path: tuple[Point, ...], index: int, travel: float) -> tuple[float, float]:
    """How far the direction of travel turns along leg ``index`` of ``path`` (rad) and the
    length that turn is spread over (m): the turn at the leg's end, into the next leg (on the
    last leg the turn at its start, from the leg before); over the leg's own length, or for the
    entry leg, whose start is not on the path, the next one's (a sampled curve's legs are about
    equally long). (0, 0) where there is no bend to see."""
    if index + 1 < len(path):
        (bx, by), (cx, cy) = path[index], path[index + 1]
        turn = wrap(math.atan2(cy - by, cx - bx) - travel)
        (ax, ay) = path[index - 1] if index else (bx, by)
        length = math.hypot(bx - ax, by - ay) if index else math.hypot(cx - bx, cy - by)
        return turn, length
    if index < 2:  # noqa: PLR2004 - the leg before starts off the path
        return 0.0, 0.0
    (ax, ay), (bx, by) = path[index - 2], path[index - 1]
    turn = wrap(travel - math.atan2(by - ay, bx - ax))
    (cx, cy) = path[index]
    return turn, math.hypot(cx - bx, cy - by)


def _drive(speed: float, travel: float, pose: Pose, omega: float = 0.0) -> Motion:
    """Velocity in the vehicle frame (§6.10.6): x forward, y to the left."""
    relative = wrap(travel - pose.theta)
    return Motion(vx=speed * math.cos(relative), vy=speed * math.sin(relative), omega=omega)


# -- the simulated stack ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SimulatedStack:
    """The default :class:`NavigationStack`: pure kinematics, no hidden state."""

    speed_max_mps: float
    angular_speed_max_radps: float
    #: One speed per edge, ``drive`` exact for any ``dt`` and no motion of its own at rest: a
    #: cruise along an edge can be simulated in one step, and a vehicle at rest not at all
    #: (translator.quiet_time, :func:`is_steady`). A stack without it is asked every tick.
    steady: ClassVar[bool] = True

    def drive(self, pose: Pose, route: TargetRoute, *, hold: bool, dt: float) -> NavFeedback:
        if hold or not route:
            return NavFeedback(pose, STANDSTILL)
        reports: list[EdgeReport] = []
        total = on_edge = 0.0
        remaining = dt
        for edge in route:
            if edge.end.map_id != pose.map_id and pose.distance_to(edge.end.x, edge.end.y) > 0:
                # The stack cannot drive onto another map's coordinates; elevators arrive at a
                # node with the same position (§6.6.6 nodePosition.mapId).
                reports.append(EdgeReport(edge.edge_id, edge.sequence_id, EdgeExecution.ABORTED))
                return NavFeedback(pose, STANDSTILL, tuple(reports), total, on_edge)
            result = step(pose, edge, self._speed(edge), self._turn_rate(edge), remaining)
            pose, remaining = result.pose, remaining - result.used_s
            total += result.distance_m
            on_edge += result.distance_m
            if not result.arrived:
                reports.append(EdgeReport(edge.edge_id, edge.sequence_id, EdgeExecution.MOVING))
                return NavFeedback(pose, result.motion, tuple(reports), total, on_edge)
            reports.append(EdgeReport(edge.edge_id, edge.sequence_id, EdgeExecution.COMPLETED))
            on_edge = 0.0
        return NavFeedback(pose, STANDSTILL, tuple(reports), total, on_edge)

    def _speed(self, edge: RouteEdge) -> float:
        if edge.max_speed is None:
            return self.speed_max_mps
        return min(edge.max_speed, self.speed_max_mps)

    def _turn_rate(self, edge: RouteEdge) -> float:
        if edge.max_rotation_speed is None:
            return self.angular_speed_max_radps
        return min(edge.max_rotation_speed, self.angular_speed_max_radps)
