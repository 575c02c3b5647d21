"""Order ⇄ navigation translation and the simulation tick ``advance`` (§6.10.2), pure.

Order → target route: the released edges from the entered edge on, up to the first node or edge
whose SOFT/HARD actions will make the vehicle stand, and never beyond the decision point (R55).
Edge reports → state: each COMPLETED edge is one node traversal, applied completely in one
update (R97): the incoming edgeState goes and its actions end, the nodeState goes, lastNodeId and
lastNodeSequenceId are set, the node's actions are triggered and the next edge is entered.
"""

from __future__ import annotations

import math
from dataclasses import replace

from vda5050.evolve import evolve
from vda5050.memo import IdentityMemo
from vda5050.models import Edge, EStop, Node
from vda_vehicle.actions import (
    end_edge_actions,
    motion_blocked,
    start_ready,
    step_actions,
    trigger_group,
)
from vda_vehicle.capabilities import Capabilities
from vda_vehicle.faults import (
    BATTERY_LOW,
    BATTERY_RESUME_MARGIN_PCT,
    battery_low,
    warning,
    with_errors,
)
from vda_vehicle.instant import finish_cancel
from vda_vehicle.model import STANDSTILL, Pose, RobotMode, VehicleState
from vda_vehicle.navigation import (
    EdgeExecution,
    EdgeReport,
    NavFeedback,
    NavigationStack,
    RouteEdge,
    TargetRoute,
    Waypoint,
    is_steady,
    translate,
)
from vda_vehicle.trajectories import path_of
from vda_vehicle.vehicle_status import finish_clearing

NAVIGATION_ERROR = "navigationError"
#: quiet_time stops this far before the next node (metres; see there).
_ARRIVAL_MARGIN_M = 1e-3
#: target_route keeps the edges starting within this much beyond a tick's reach (metres).
_REACH_SLACK_M = 1e-3
_DRIVING_MODES = (RobotMode.AUTOMATIC, RobotMode.SEMIAUTOMATIC)


def advance(
    state: VehicleState, dt: float, *, caps: Capabilities, stack: NavigationStack
) -> VehicleState:
    """One simulation tick of ``dt`` seconds: actions, edge entry, navigation, battery."""
    if _at_rest(state) and is_steady(stack):
        return state  # a real robot's stack is asked even at rest: it may be moved by hand
    before = state
    state = step_actions(state, dt, caps.catalog)
    if state.pending_mode is not None:
        state = finish_clearing(state, caps.catalog)
    state = enter_next_edge(state, caps)
    route = target_route(state, reach_m=caps.speed_max_mps * dt)
    feedback = stack.drive(state.pose, route, hold=must_hold(state), dt=dt)
    battery = _battery(state, feedback.distance_m, dt, caps)
    state = finish_cancel(apply_feedback(state, feedback, caps, battery_charge=battery))
    if battery < caps.battery_stop_pct or state.errors:
        state = battery_guard(state, caps)
    if state.charging and feedback.distance_m > 0:
        # The simulated vehicle charges on a spot (§6.8.2 startCharging), not on a charging
        # lane: driving off ends the charge, and the state says so (R77's charging flag).
        state = evolve(state, charging=False)
    new_base_request = wants_new_base(state, caps)
    if new_base_request != state.new_base_request:
        state = evolve(state, new_base_request=new_base_request)
    return state.bumped() if events_differ(before, state) else state


def quiet_time(state: VehicleState, *, steady_stack: bool = True) -> float:
    """Simulated seconds ahead in which :func:`advance` can raise no §6.10 event, so a tick may
    be skipped and its time simulated later in one step (the kinematics are exact for any
    ``dt``); 0 when the next tick must run.

    At rest nothing changes on its own for the simulated stack; a real robot's stack is asked
    every tick even then, as the robot may be moved by hand (the state follows its pose; no
    node counts as traversed, §6.10.2). Cruising along the entered edge at a steady speed,
    with no action under way, nothing but the pose, the distance and the battery changes until
    the end node is reached (the stack's speed on an edge is constant; a node theta only
    delays the arrival). Everything else (a horizon that may call for newBaseRequest,
    charging, pause, cancel, a turn, an edge with a trajectory: its curve is not the straight
    line :func:`cruise_pose` and the arrival time assume) is stepped tick by tick. The cruise
    is predictable only for a stack that drives each edge at one speed and integrates any
    ``dt`` exactly (``steady_stack``, as the simulated one does); a real robot's stack is asked
    every tick.
    """
    if _at_rest(state):
        return math.inf if steady_stack else 0.0
    motion = state.motion
    if (
        not steady_stack
        or state.entered_edge is None
        or motion.omega
        or (state.edges and state.edges[0].trajectory is not None)
        or not state.nodes
        or state.charging
        or state.paused
        or state.cancel_action_id is not None
        or (not state.new_base_request and not state.nodes[-1].released)
        or any(r.triggered and not r.terminal for r in state.actions)
    ):
        return 0.0
    speed = math.hypot(motion.vx, motion.vy)
    end = state.nodes[0].node_position
    if speed <= 0 or end is None:
        return 0.0
    # A millimetre short: a tick that brings the vehicle to within EPSILON of the node (the
    # stack counts that as there) runs in full, even when it ends exactly at the arrival.
    left = math.hypot(end.x - state.pose.x, end.y - state.pose.y) - _ARRIVAL_MARGIN_M
    return max(0.0, left) / speed


def cruise_pose(state: VehicleState, dt: float) -> Pose:
    """Where a cruising vehicle is ``dt`` simulated seconds on (``dt`` within its
    :func:`quiet_time`, so never on an edge with a trajectory): straight on towards the entered
    edge's end node at its speed, heading kept, as :func:`advance` would put it (the stack's own
    ``translate``).
    At rest, or without a speed or an end node, the pose as it is."""
    pose, motion = state.pose, state.motion
    speed = math.hypot(motion.vx, motion.vy)
    end = state.nodes[0].node_position if state.nodes else None
    if dt <= 0 or speed <= 0 or end is None:
        return pose
    return translate(pose, end.x, end.y, speed, dt)[0]


def arrival_time(state: VehicleState, quiet_s: float) -> float:
    """Simulated seconds until a cruising vehicle reaches its edge's end node, from its
    :func:`quiet_time` ``quiet_s`` (positive and finite): the millimetre quiet_time stops short
    of the node, at the vehicle's speed."""
    return quiet_s + _ARRIVAL_MARGIN_M / math.hypot(state.motion.vx, state.motion.vy)


def _at_rest(state: VehicleState) -> bool:
    """Nothing can change: no order ahead, no unfinished action, not charging, standing."""
    return not state.nodes and standing_by(state)


def standing_by(state: VehicleState) -> bool:
    """Nothing advances with time: standing, not charging, no cancel under way, no action
    triggered and unfinished. Only a message (an order, its update, an instant action) sets
    such a vehicle going, and it does so from the moment it arrives."""
    return (
        not state.motion.moving
        and not state.charging
        and state.cancel_action_id is None
        and all(r.terminal or not r.triggered for r in state.actions)
    )


def events_differ(before: VehicleState, after: VehicleState) -> bool:
    """Whether a §6.10 event happened between the two states (R93): a state message is due.

    Order, update, last node, what is left of the order, driving, paused, charging, operating
    mode, loads, errors, newBaseRequest, or an action's status (or its retry flag) changed.
    Fields a tick left alone are the very same objects, so most comparisons are identities.
    """
    return (
        before.order_id != after.order_id
        or before.order_update_id != after.order_update_id
        or before.last_node_sequence_id != after.last_node_sequence_id
        or len(before.nodes) != len(after.nodes)
        or len(before.edges) != len(after.edges)
        or before.driving != after.driving
        or before.paused != after.paused
        or before.charging != after.charging
        or before.operating_mode != after.operating_mode
        or before.loads != after.loads
        or before.errors != after.errors
        or before.new_base_request != after.new_base_request
        or (before.actions is not after.actions and _action_events(before) != _action_events(after))
    )


def _action_events(state: VehicleState) -> list[tuple[object, bool]]:
    return [(record.status, record.awaiting_retry) for record in state.actions]


def must_hold(state: VehicleState) -> bool:
    """The vehicle may not move: paused (R76), a blocking action (R73), a cancel in progress
    (unless it finishes the edge it is on, R63), not localised, in a mode master control does
    not drive (§6.10.6 Table 1) or entering one (3.0 T64), stopped by its emergency stop
    (§6.10.6 safetyState), or by a low battery (:func:`battery_guard`)."""
    return (
        state.paused
        or state.pending_mode is not None
        or (bool(state.errors) and any(e.error_type == BATTERY_LOW for e in state.errors))
        or state.e_stop is not EStop.NONE
        or (state.cancel_action_id is not None and not state.nodes)
        or not state.position_initialized
        or state.operating_mode not in _DRIVING_MODES
        or motion_blocked(state)
    )


def enter_next_edge(state: VehicleState, caps: Capabilities) -> VehicleState:
    """§6.10.2 step 5: the next released edge is entered (its actions triggered) once no
    SOFT/HARD action holds the vehicle on the node (Figure 15), unless a zone ahead keeps the
    vehicle out of it (``hold_before``)."""
    if state.entered_edge is not None or not state.edges or must_hold(state):
        return state
    edge = state.edges[0]
    if not edge.released or (
        state.hold_before is not None and edge.sequence_id >= state.hold_before
    ):
        return state
    entered = trigger_group(evolve(state, entered_edge=edge.sequence_id), edge.sequence_id)
    return start_ready(entered, caps.catalog)


def target_route(state: VehicleState, reach_m: float = math.inf) -> TargetRoute:
    """The released edges the vehicle may drive now, from the entered edge on (R55), up to the
    one a zone holds it before (``hold_before``: none of it, when that is the entered edge).

    Edges beyond ``reach_m`` (straight-line, from the vehicle) are left out: the stack cannot
    get there within this tick anyway, and a short route keeps a tick cheap. The edge after a
    node the tick reaches exactly (a tick at a node's arrival time) is kept: the vehicle drives
    on through the node instead of standing on it until the next tick.
    """
    if state.entered_edge is None:
        return ()
    route: list[RouteEdge] = []
    x, y, covered = state.pose.x, state.pose.y, 0.0
    reach_m += _REACH_SLACK_M
    hold = state.hold_before
    for index, edge in enumerate(state.edges):
        if not edge.released or index >= len(state.nodes) or covered > reach_m:
            break
        if hold is not None and edge.sequence_id >= hold:
            break  # a zone ahead keeps the vehicle out (3.0): it stops before (or on) this edge
        if index > 0 and (_stops_at(state, state.nodes[index - 1]) or _blocks(state, edge)):
            break
        step = _route_edge(edge, state.nodes[index])
        route.append(step)
        covered += math.hypot(step.end.x - x, step.end.y - y)
        x, y = step.end.x, step.end.y
    return tuple(route)


def _stops_at(state: VehicleState, node: Node) -> bool:
    """A node with SOFT/HARD actions makes the vehicle stand when it gets there (§6.12)."""
    return _has_actions(state, node)


def _blocks(state: VehicleState, edge: Edge) -> bool:
    """An edge with SOFT/HARD actions is entered standing still (§6.12)."""
    return any(r.group == edge.sequence_id and r.blocking for r in state.actions)


def _has_actions(state: VehicleState, node: Node) -> bool:
    """The node's actions as held: a stitching node keeps its original ones (R51)."""
    return any(r.group == node.sequence_id and r.blocking for r in state.actions)


#: RouteEdges by (edge, end node) object: a driving vehicle needs the same one or two each tick.
_ROUTE_EDGES: IdentityMemo[RouteEdge] = IdentityMemo(limit=16_384)


def _route_edge(edge: Edge, end: Node) -> RouteEdge:
    """The stack's view of ``edge`` ending on ``end`` (the objects are immutable: one per pair)."""
    return _ROUTE_EDGES.get_pair(edge, end, lambda: _build_route_edge(edge, end))


def _build_route_edge(edge: Edge, end: Node) -> RouteEdge:
    position = end.node_position
    if position is None:  # rejected by decide_order (nodePosition is REQUIRED)
        msg = f"node {end.node_id!r} has no nodePosition"
        raise ValueError(msg)
    waypoint = Waypoint(end.node_id, position.x, position.y, position.theta, position.map_id)
    return RouteEdge(
        edge.edge_id,
        edge.sequence_id,
        waypoint,
        max_speed=edge.max_speed,
        orientation=edge.orientation,
        orientation_type=edge.orientation_type,
        max_rotation_speed=edge.max_rotation_speed,
        path=path_of(edge, position),
    )


def apply_feedback(
    state: VehicleState,
    feedback: NavFeedback,
    caps: Capabilities,
    *,
    battery_charge: float | None = None,
) -> VehicleState:
    """Turn the stack's edge reports into node traversals (§6.10.2); the tick's new
    ``battery_charge`` goes into the same copy (one copy per tick of a driving vehicle)."""
    distance = state.distance_since_last_node + feedback.distance_m
    charge = state.battery_charge if battery_charge is None else battery_charge
    if (
        feedback.pose is not state.pose
        or feedback.motion is not state.motion
        or distance != state.distance_since_last_node
        or charge != state.battery_charge
    ):
        state = evolve(
            state,
            pose=feedback.pose,
            motion=feedback.motion,
            distance_since_last_node=distance,
            battery_charge=charge,
        )
    for report in feedback.reports:
        if report.execution is EdgeExecution.COMPLETED:
            state = traverse(state, report, caps)
            state = evolve(state, distance_since_last_node=feedback.distance_on_edge_m)
        elif report.execution is EdgeExecution.ABORTED:
            state = _aborted(state, report)
    return state


def traverse(state: VehicleState, report: EdgeReport, caps: Capabilities) -> VehicleState:
    """R97: one completed edge = one node traversal, all of it in one state update."""
    if not state.edges or state.edges[0].sequence_id != report.sequence_id:
        return state  # a report for an edge the order no longer holds (cancelled meanwhile)
    node = state.nodes[0]
    state = end_edge_actions(state, report.sequence_id)
    state = evolve(
        state,
        nodes=state.nodes[1:],
        edges=state.edges[1:],
        entered_edge=None,
        last_node_id=node.node_id,
        last_node_sequence_id=node.sequence_id,
        distance_since_last_node=0.0,
    )
    state = start_ready(trigger_group(state, node.sequence_id), caps.catalog)
    return enter_next_edge(state, caps)


def _aborted(state: VehicleState, report: EdgeReport) -> VehicleState:
    error = warning(
        NAVIGATION_ERROR,
        f"the navigation stack aborted edge {report.edge_id}",
        [("edgeId", report.edge_id), ("sequenceId", str(report.sequence_id))],
    )
    if error in state.errors:
        return state
    return replace(state, errors=with_errors(state.errors, error), motion=STANDSTILL)


def _battery(state: VehicleState, distance: float, dt: float, caps: Capabilities) -> float:
    """Drains with distance, charges while charging (issue item 4); kept within [0, 100] %."""
    if distance == 0 and not state.charging:
        return state.battery_charge
    charge = state.battery_charge - distance * caps.battery_drain_pct_per_m
    if state.charging:
        charge += caps.charge_rate_pct_per_s * dt
    return min(100.0, max(0.0, charge))


def battery_guard(state: VehicleState, caps: Capabilities) -> VehicleState:
    """Under ``battery_stop_pct`` and not charging, the vehicle stops and reports the FATAL
    error batteryLowError (as vda-5050-lib's virtual AGV does); charged
    ``BATTERY_RESUME_MARGIN_PCT`` above the limit, the error goes and it may drive on. A
    cruise simulated in one step (:func:`quiet_time`) stops at its end, the next node."""
    low = next((e for e in state.errors if e.error_type == BATTERY_LOW), None)
    charge = state.battery_charge
    if low is None:
        if state.charging or charge >= caps.battery_stop_pct:
            return state
        return evolve(
            state, errors=with_errors(state.errors, battery_low(charge)), motion=STANDSTILL
        )
    if charge >= caps.battery_stop_pct + BATTERY_RESUME_MARGIN_PCT:
        return evolve(state, errors=tuple(e for e in state.errors if e is not low))
    return state


def wants_new_base(state: VehicleState, caps: Capabilities) -> bool:
    """§6.10.3, R107: true while a horizon waits and the base left is under the threshold.

    Without a horizon there is nothing to release, so the vehicle does not ask (digest §6.2).
    """
    if not state.nodes or state.nodes[-1].released:
        return False
    left, x, y = 0.0, state.pose.x, state.pose.y
    for node in state.nodes:
        if not node.released or node.node_position is None:
            break
        left += math.hypot(node.node_position.x - x, node.node_position.y - y)
        x, y = node.node_position.x, node.node_position.y
        if left >= caps.new_base_request_m:
            return False
    return True
