"""VDA 5050 3.0 orders, instant actions and zone sets at the vehicle's edge, pure.

The vehicle's core (order_executor, instant, translator) is version-neutral and works on the
2.x models. A 3.0 vehicle translates at its edges: this module decides a 3.0 order with the 3.0
error types of Figure 8 and Table 9 (reusing the core's checks one by one), maps an accepted
3.0 order onto the core's order model (edge end nodes from the sequenceIds, T18; the ellipse
deviation as its larger half-axis, with the ellipse itself checked for the start node, T31),
and maps 3.0 instant actions (``initializePosition``, ``cancelOrder`` with ``orderId``).

Errors are kept in ``VehicleState.errors`` as core error objects carrying the 3.0 type; the
3.0 reporter gives them their Table 9 level (:mod:`vda_vehicle.v3_report`).
Section numbers (§) and rule ids (Tnn, docs/vda5050-3.md) are those of the 3.0.0 text.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from datetime import datetime
from typing import Final

from vda5050.models import (
    Action,
    ActionScope,
    ActionStatus,
    BlockingType,
    ControlPoint,
    Corridor,
    Edge,
    Error,
    ErrorLevel,
    ErrorReference,
    InstantActions,
    Node,
    NodePosition,
    Order,
    Trajectory,
    v3,
)
from vda5050.models.order import CorridorRefPoint
from vda5050.nurbs import curve_of, path_from, sample, uniform_knots
from vda5050.polygons import Point
from vda5050.validation3 import check_order
from vda_vehicle.actions import moved, record_of, replace_record
from vda_vehicle.capabilities import Capabilities, optional_fields_used
from vda_vehicle.faults import with_errors
from vda_vehicle.instant import begin_cancel
from vda_vehicle.model import ActionRecord, VehicleState, has_order_to_cancel
from vda_vehicle.order_executor import (
    Accept,
    Check,
    Decision,
    Ignore,
    Reject,
    actions_supported,
    fields_supported,
    maps_known,
    not_busy,
    operating_mode_allows,
    orientations_reachable,
    physically_possible,
    start_reachable,
    stitches,
    trajectories_followable,
    within_limits,
)
from vda_vehicle.trajectories import unclamped
from vda_vehicle.v3_requests import EdgeZones
from vda_vehicle.v3_zones import ReleaseZone, ZoneSets, blocked_zone, speed_limit

E = v3.ErrorType
#: Optional 3.0 order fields this vehicle acts on, as factsheet ``optionalParameters`` paths
#: (T21, T83). Descriptors are free text for people and always accepted.
V3_SUPPORTED_FIELDS: Final = frozenset(
    {
        "order.orderDescription",
        "order.nodes.nodeDescriptor",
        "order.nodes.nodePosition",
        "order.nodes.nodePosition.theta",
        "order.nodes.nodePosition.allowedDeviationXY",
        "order.nodes.nodePosition.allowedDeviationTheta",
        "order.nodes.actions.actionDescriptor",
        "order.nodes.actions.actionParameters",
        "order.edges.edgeDescriptor",
        "order.edges.maximumSpeed",
        "order.edges.maximumMobileRobotHeight",
        "order.edges.orientation",
        "order.edges.orientationType",
        "order.edges.maximumRotationSpeed",
        "order.edges.length",
        "order.edges.trajectory",
        "order.edges.corridor",  # accepted, never used to deviate (trajectories.py)
        "order.edges.actions.actionDescriptor",
        "order.edges.actions.actionParameters",
        "order.nodes.actions.retriable",
        "order.edges.actions.retriable",
    }
)
#: The simulated stack navigates by coordinates: every node needs its position.
V3_REQUIRED_FIELDS: Final = frozenset({"order.nodes.nodePosition"})
#: 3.0 names of predefined actions whose 2.x name the core's catalog uses (T59).
V3_ACTION_NAMES: Final = {"initPosition": "initializePosition"}
_CORE_ACTION_NAMES: Final = {name3: name2 for name2, name3 in V3_ACTION_NAMES.items()}
CANCEL_ORDER: Final = "cancelOrder"
#: 3.0 instant action (T57) handled at the edge: forget the ended instant action states.
CLEAR_INSTANT_ACTIONS: Final = "clearInstantActions"
#: 3.0 hibernation (T06), handled at the edge by :class:`vda_vehicle.runtime3.VehicleRuntimeV3`.
START_HIBERNATION: Final = "startHibernation"
STOP_HIBERNATION: Final = "stopHibernation"
#: 3.0 zone set actions (§6.2.3.1, T87), handled at the edge; parameter ``zoneSetId``.
ENABLE_ZONE_SET: Final = "enableZoneSet"
DELETE_ZONE_SET: Final = "deleteZoneSet"
#: 3.0 retry actions (§6.2.3.1, T53), handled at the edge; parameter ``actionId``.
RETRY: Final = "retry"
SKIP_RETRY: Final = "skipRetry"
#: 3.0 coordinated shutdown (§6.2.3.1, T07), handled at the edge by the 3.0 runtime.
SHUTDOWN: Final = "shutdown"


# -- orders -------------------------------------------------------------------------------------


def decide_order_v3(
    state: VehicleState,
    order: v3.Order,
    caps: Capabilities,
    *,
    last: v3.Order | None,
    zones: ZoneSets = (),
) -> Decision:
    """3.0 Figure 8 on a decoded 3.0 order; ``last`` is the last accepted order message,
    ``zones`` the zone sets held (an enabled BLOCKED zone on the way: NO_ROUTE_TO_TARGET).

    Structure first (T17-T20), then for an update the id checks of steps 6-8 (T33-T35), then
    what the vehicle can do (T21-T26, T38), then step 3-5 for a new order (T29-T31) or the
    stitching check for an update (T36).
    """
    is_update = bool(state.order_id) and order.order_id == state.order_id
    structural = check_order(order, first_sequence_id=None if is_update else 0)
    if structural:
        return Reject(tuple(stored(error) for error in structural))
    core = to_core_order(order)
    if is_update:
        early = _update_ids(state, order, core, last)
        if early is not None:
            return early
    for check, error_type in _content_checks(order, zones):
        errors = check(state, core, caps)
        if errors:
            return Reject(tuple(errors) if error_type is None else retyped(errors, error_type))
    if is_update:
        errors = stitches(state, core, caps)
        return Reject(retyped(errors, E.VALIDATION_FAILURE)) if errors else Accept("update")
    return _new_order(state, order, core, caps)


def _update_ids(
    state: VehicleState, order: v3.Order, core: Order, last: v3.Order | None
) -> Decision | None:
    """Steps 6-8 for the same orderId: outdated (T33), after a cancel (T34), same id (T35)."""
    if order.order_update_id < state.order_update_id:
        text = f"orderUpdateId {order.order_update_id} is older than {state.order_update_id}"
        return Reject((_order_error(core, E.OUTDATED_ORDER_UPDATE, text),))
    if state.order_cancelled:
        text = f"order {order.order_id!r} was cancelled; a new order needs a new orderId"
        return Reject((_order_error(core, E.ORDER_UPDATE_FOLLOWING_CANCEL, text),))
    if order.order_update_id == state.order_update_id:
        if last is not None and same_content(last, order):
            return Ignore()
        text = f"orderUpdateId {order.order_update_id} was already received with other content"
        return Reject((_order_error(core, E.SAME_ORDER_UPDATE_ID, text),))
    return None


def _new_order(state: VehicleState, order: v3.Order, core: Order, caps: Capabilities) -> Decision:
    """Steps 3-5: another order active (T29), orderUpdateId not 0 (T30), start node (T31)."""
    errors = not_busy(state, core, caps)
    if errors:
        return Reject(retyped(errors, E.OTHER_ORDER_ACTIVE))
    if order.order_update_id != 0:
        text = f"a new order starts with orderUpdateId 0, not {order.order_update_id}"
        return Reject((_order_error(core, E.VALIDATION_FAILURE, text),))
    errors = start_reachable(state, core, caps)
    if errors or not _inside_ellipse(state, order.nodes[0]):
        first = order.nodes[0]
        text = f"the first node {first.node_id!r} is not where the robot stands"
        return Reject(
            (_order_error(core, E.START_NODE_OUT_OF_RANGE, text, ("nodeId", first.node_id)),)
        )
    return Accept("new")


def _content_checks(order: v3.Order, zones: ZoneSets) -> Iterator[tuple[Check, E | None]]:
    """What the vehicle can do with the order, each check with its 3.0 error type (None: the
    check types its errors itself)."""
    yield within_limits, E.INSUFFICIENT_MEMORY  # T23: beyond the declared protocolLimits
    yield _fatal_error_active, E.MOBILE_ROBOT_NOT_AVAILABLE  # T38
    yield operating_mode_allows, E.MOBILE_ROBOT_NOT_AVAILABLE  # T26
    yield _unsupported_fields_of(order), E.UNSUPPORTED_PARAMETER  # T21
    yield actions_supported, E.INVALID_ORDER_ACTION  # T22
    yield maps_known, E.UNKNOWN_MAP_ID  # T24
    yield _physically_possible_v3, None  # T25 NO_ROUTE_TO_TARGET, or VALIDATION_FAILURE
    yield _trajectories_v3(order), None  # VALIDATION_FAILURE, or NO_ROUTE_TO_TARGET
    yield orientations_reachable, E.NO_ROUTE_TO_TARGET  # an edge orientation it cannot hold
    yield _blocked_by_zones(order, zones), E.NO_ROUTE_TO_TARGET  # T89
    yield fields_supported, E.VALIDATION_FAILURE  # required nodePosition, height


def _fatal_error_active(state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
    """T38: with a FATAL error the robot takes neither new orders nor updates."""
    if not any(e.error_level is ErrorLevel.FATAL for e in state.errors):
        return []
    return [_order_error(order, E.MOBILE_ROBOT_NOT_AVAILABLE, "a FATAL error is active")]


def _physically_possible_v3(state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
    """Off every held map: NO_ROUTE_TO_TARGET (T25); a bad speed or length: VALIDATION_FAILURE."""
    return [
        error.model_copy(
            update={"error_type": E.NO_ROUTE_TO_TARGET}
            if error.error_type == "orderError"
            else {"error_type": E.VALIDATION_FAILURE}
        )
        for error in physically_possible(state, order, caps)
    ]


def _trajectories_v3(order3: v3.Order) -> Check:
    """§7.3 trajectory (T101): a given knotVector is clamped, and the core's checks
    (:func:`~vda_vehicle.order_executor.trajectories_followable`) hold; a curve that is no
    valid NURBS or misses its nodes is a VALIDATION_FAILURE, one of a degree the stack does not
    follow NO_ROUTE_TO_TARGET."""

    def check(state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
        errors = [
            error.model_copy(
                update={"error_type": E.NO_ROUTE_TO_TARGET}
                if error.error_type == "orderError"
                else {"error_type": E.VALIDATION_FAILURE}
            )
            for error in trajectories_followable(state, order, caps)
        ]
        if errors:
            return errors
        for edge in order3.edges:
            curve = edge.trajectory
            if curve is None or curve.knot_vector is None:
                continue
            problem = unclamped(curve.degree or 1, curve.knot_vector)
            if problem is not None:
                text = f"edge {edge.edge_id}'s trajectory: {problem}"
                refs = (("edgeId", edge.edge_id), ("field", "order.edges.trajectory"))
                errors.append(_order_error(order, E.VALIDATION_FAILURE, text, *refs))
        return errors

    return check


def _unsupported_fields_of(order3: v3.Order) -> Check:
    def check(_state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
        return [
            _order_error(
                order,
                E.UNSUPPORTED_PARAMETER,
                f"{path} ({where}) is not supported",
                ("field", path),
            )
            for path, where in unsupported_fields(order3)
        ]

    return check


def unsupported_fields(order: v3.Order) -> list[tuple[str, str]]:
    """T21: the optional fields of ``order`` this vehicle cannot act on, as (path, where)."""
    return [(p, w) for p, w in optional_fields_used(order) if p not in V3_SUPPORTED_FIELDS]


def _inside_ellipse(state: VehicleState, node: v3.Node) -> bool:
    """T31: the robot stands inside the node's allowedDeviationXY ellipse (§6.6.2.1). An
    absent or zero ellipse means the vehicle's own tolerance, which the core checked."""
    position = node.node_position
    if position is None or position.allowed_deviation_xy is None:
        return True
    ellipse = position.allowed_deviation_xy
    if ellipse.a == 0 and ellipse.b == 0:
        return True
    return ellipse.contains(state.pose.x - position.x, state.pose.y - position.y)


def same_content(a: v3.Order, b: v3.Order) -> bool:
    """T35: the same order message apart from its header."""
    header = {"header_id", "timestamp", "version", "manufacturer", "serial_number"}
    return a.model_dump(exclude=header) == b.model_dump(exclude=header)


def retriable_action_ids(order: v3.Order) -> frozenset[str]:
    """The actions with ``retriable: true``: a failure waits for retry/skipRetry (T52)."""
    actions = [a for node in order.nodes for a in node.actions]
    actions += [a for edge in order.edges for a in edge.actions]
    return frozenset(a.action_id for a in actions if a.is_retriable)


def single_action_ids(order: v3.Order) -> frozenset[str]:
    """The actions with blocking type SINGLE: they run alone while the vehicle drives (T48)."""
    actions = [a for node in order.nodes for a in node.actions]
    actions += [a for edge in order.edges for a in edge.actions]
    return frozenset(a.action_id for a in actions if a.blocking_type is v3.BlockingType.SINGLE)


def to_core_order(order: v3.Order) -> Order:
    """The core's view of a structurally valid 3.0 order (T17-T19 hold).

    Edge ``n`` joins the nodes ``n-1`` and ``n+1`` (T18); SINGLE becomes NONE here and its
    "alone" half is passed separately (:func:`single_action_ids`).
    """
    by_sequence = {node.sequence_id: node.node_id for node in order.nodes}
    return Order.model_construct(
        **order.header_fields(),
        order_id=order.order_id,
        order_update_id=order.order_update_id,
        nodes=[_core_node(node) for node in order.nodes],
        edges=[
            _core_edge(edge, by_sequence[edge.sequence_id - 1], by_sequence[edge.sequence_id + 1])
            for edge in order.edges
        ],
    )


def _core_node(node: v3.Node) -> Node:
    position = node.node_position
    core_position = None
    if position is not None:
        ellipse = position.allowed_deviation_xy
        core_position = NodePosition(
            x=position.x,
            y=position.y,
            theta=position.theta,
            allowed_deviation_xy=None if ellipse is None else max(ellipse.a, ellipse.b),
            allowed_deviation_theta=position.allowed_deviation_theta,
            map_id=position.map_id,
        )
    return Node(
        node_id=node.node_id,
        sequence_id=node.sequence_id,
        node_description=node.node_descriptor,
        released=node.released,
        node_position=core_position,
        actions=[core_action(action) for action in node.actions],
    )


def _core_edge(edge: v3.Edge, start: str, end: str) -> Edge:
    return Edge(
        edge_id=edge.edge_id,
        sequence_id=edge.sequence_id,
        edge_description=edge.edge_descriptor,
        released=edge.released,
        start_node_id=start,
        end_node_id=end,
        max_speed=edge.maximum_speed,
        max_height=edge.maximum_mobile_robot_height,
        orientation=edge.orientation,
        orientation_type=edge.orientation_type,
        max_rotation_speed=edge.maximum_rotation_speed,
        trajectory=_core_trajectory(edge.trajectory),
        length=edge.length,
        corridor=_core_corridor(edge.corridor),
        actions=[core_action(action) for action in edge.actions],
    )


def _core_trajectory(trajectory: v3.Trajectory | None) -> Trajectory | None:
    """T101: 3.0's optional ``degree`` (1) and ``knotVector`` (uniform knots) filled in; the
    core's 2.x trajectory needs both."""
    if trajectory is None:
        return None
    degree = trajectory.degree or 1
    points = [ControlPoint(x=p.x, y=p.y, weight=p.weight) for p in trajectory.control_points]
    knots = trajectory.knot_vector
    if knots is None:
        knots = list(uniform_knots(degree, len(points)))
    return Trajectory(degree=degree, knot_vector=knots, control_points=points)


#: 3.0 corridorReferencePoint → 2.1 corridorRefPoint.
_CORRIDOR_REF_POINTS: Final = {
    v3.CorridorReferencePoint.KINEMATIC_CENTER: CorridorRefPoint.KINEMATICCENTER,
    v3.CorridorReferencePoint.CONTOUR: CorridorRefPoint.CONTOUR,
}


def _core_corridor(corridor: v3.Corridor | None) -> Corridor | None:
    """§7.3 corridor as the core's 2.1 one. ``releaseRequired`` and ``releaseLossBehavior``
    have no 2.x counterpart and need none: the vehicle never leaves its trajectory, so it never
    asks for an edgeRequest (T94)."""
    if corridor is None:
        return None
    reference = corridor.corridor_reference_point
    return Corridor(
        left_width=corridor.left_width,
        right_width=corridor.right_width,
        corridor_ref_point=None if reference is None else _CORRIDOR_REF_POINTS[reference],
    )


def core_action(action: v3.Action) -> Action:
    """A 3.0 action for the core: its 2.x catalog name, SINGLE as NONE (see above)."""
    blocking = (
        BlockingType.NONE
        if action.blocking_type is v3.BlockingType.SINGLE
        else BlockingType(action.blocking_type.value)
    )
    return Action(
        action_type=_CORE_ACTION_NAMES.get(action.action_type, action.action_type),
        action_id=action.action_id,
        action_description=action.action_descriptor,
        blocking_type=blocking,
        action_parameters=action.action_parameters,
    )


# -- instant actions ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class InstantSplit:
    """A 3.0 batch for the core, the actions refused before it (FAILED, with an error), the
    ``clearInstantActions`` of the batch (done at the edge, before the others) and a
    ``startHibernation`` (done at the edge, after the others)."""

    core: InstantActions
    refused: tuple[tuple[v3.InstantAction, Error], ...]
    clears: tuple[v3.InstantAction, ...] = ()
    hibernation: v3.InstantAction | None = None
    #: enableZoneSet / deleteZoneSet, retry / skipRetry, in batch order (done at the edge,
    #: before the others).
    edge_actions: tuple[v3.InstantAction, ...] = ()
    #: A ``shutdown`` (done at the edge, after everything else, T07).
    shutdown: v3.InstantAction | None = None


def split_instant_actions(state: VehicleState, message: v3.InstantActions) -> InstantSplit:
    """Map a 3.0 batch onto the core's instant actions.

    ``cancelOrder`` naming another ``orderId`` than the active one is refused here with
    NO_ORDER_TO_CANCEL (T46); its ``orderId`` is dropped once checked (T44). An action asking
    for ``retriable`` handling is refused with INVALID_INSTANT_ACTION (no retry support).
    """
    kept: list[Action] = []
    refused: list[tuple[v3.InstantAction, Error]] = []
    clears: list[v3.InstantAction] = []
    hibernation: v3.InstantAction | None = None
    shutdown: v3.InstantAction | None = None
    edge_actions: list[v3.InstantAction] = []
    for action in message.actions:
        if action.action_type in _EDGE_DONE and not action.is_retriable:
            edge_actions.append(action)
            continue
        if action.action_type == CLEAR_INSTANT_ACTIONS and not action.is_retriable:
            clears.append(action)
            continue
        if action.action_type == START_HIBERNATION and hibernation is None:
            hibernation = action
            continue
        if action.action_type == SHUTDOWN and shutdown is None and not action.is_retriable:
            shutdown = action
            continue
        if action.action_type == STOP_HIBERNATION:
            text = "stopHibernation received, but this vehicle is not hibernating"
            refused.append((action, _action_error(action, E.INVALID_INSTANT_ACTION, text)))
            continue
        if action.is_retriable:
            text = "retriable instant actions are not supported by this vehicle"
            refused.append((action, _action_error(action, E.INVALID_INSTANT_ACTION, text)))
            continue
        if action.action_type == CANCEL_ORDER:
            named = action.parameter("orderId")
            if named is not None and named != state.order_id:
                text = f"cancelOrder names order {named!r}, the active order is {state.order_id!r}"
                refused.append((action, _action_error(action, E.NO_ORDER_TO_CANCEL, text)))
                continue
            params = [p for p in action.action_parameters or () if p.key != "orderId"]
            kept.append(
                core_action(action.model_copy(update={"action_parameters": params or None}))
            )
            continue
        kept.append(core_action(action))
    core = InstantActions.model_construct(
        **message.header_fields(),
        actions=kept,
    )
    return InstantSplit(
        core, tuple(refused), tuple(clears), hibernation, tuple(edge_actions), shutdown
    )


_EDGE_DONE: Final = frozenset({ENABLE_ZONE_SET, DELETE_ZONE_SET, RETRY, SKIP_RETRY})


def retry_action(state: VehicleState, action: v3.InstantAction) -> str | VehicleState:
    """T53: ``retry`` runs a RETRIABLE action again (its run phase anew), ``skipRetry`` ends it
    FAILED; the state after, or why not (the named action is not RETRIABLE)."""
    action_id = str(action.parameter("actionId") or "")
    target = record_of(state, action_id)
    if target is None or not target.is_retriable_now:
        return f"action {action_id!r} is not RETRIABLE"
    if action.action_type == SKIP_RETRY:
        done = moved(replace(target, awaiting_retry=False), ActionStatus.FAILED, remaining_s=0.0)
        return replace_record(state, done)
    again = replace(target, awaiting_retry=False, remaining_s=0.0, result=None)
    return replace_record(state, again)


def with_refused(
    state: VehicleState, refused: Sequence[tuple[v3.InstantAction, Error]], group: int
) -> VehicleState:
    """The refused instant actions as FAILED instant action states with their errors."""
    records = tuple(
        moved(
            ActionRecord(core_action(action), ActionScope.INSTANT, group, triggered=True),
            ActionStatus.FAILED,
            result=error.error_description,
        )
        for action, error in refused
    )
    errors = tuple(error for _, error in refused)
    return state.bumped(
        actions=(*state.actions, *records), errors=with_errors(state.errors, *errors)
    )


def with_cleared(
    state: VehicleState, clears: Sequence[v3.InstantAction], group: int
) -> VehicleState:
    """T57: ``clearInstantActions`` removes the FINISHED and FAILED instant action states (only
    those); each clear is reported FINISHED itself."""
    if not clears:
        return state
    kept = tuple(r for r in state.actions if not (r.scope is ActionScope.INSTANT and r.terminal))
    done = tuple(
        ActionRecord(
            core_action(action),
            ActionScope.INSTANT,
            group,
            status=ActionStatus.FINISHED,
            triggered=True,
            result="instant action states cleared",
        )
        for action in clears
    )
    return state.bumped(actions=(*kept, *done))


def begin_hibernation(
    state: VehicleState, action: v3.InstantAction, group: int, caps: Capabilities
) -> VehicleState:
    """T06, T61: ``startHibernation`` clears an active order as ``cancelOrder`` does (the
    vehicle stops on the next node, WAITING and interruptible actions FAIL) and is FINISHED once
    the vehicle stands with every order action ended; without an order it is FINISHED at once.
    A ``wakeUpTime`` that is not an ISO 8601 date-time with its offset makes the action FAIL
    (INVALID_INSTANT_ACTION); a valid one is kept by the runtime (:func:`wake_up_time`)."""
    record = ActionRecord(core_action(action), ActionScope.INSTANT, group, triggered=True)
    if isinstance(wake_up_time(action), str):
        text = f"wakeUpTime {action.parameter('wakeUpTime')!r} is not an ISO 8601 date-time"
        error = _action_error(action, E.INVALID_INSTANT_ACTION, f"{text} with its offset")
        return with_refused(state, [(action, error)], group)
    if has_order_to_cancel(state):
        return begin_cancel(state, record, caps).bumped()
    done = moved(moved(record, ActionStatus.RUNNING), ActionStatus.FINISHED, result="hibernating")
    return state.bumped(actions=(*state.actions, done))


def wake_up_time(action: v3.InstantAction) -> datetime | str | None:
    """T06: when a hibernating robot wakes itself (``startHibernation``'s optional
    ``wakeUpTime``, a date-time like every 3.0 timestamp); None without one, the text itself
    when it is not a date-time with its offset."""
    value = action.parameter("wakeUpTime")
    if value is None:
        return None
    text = str(value)
    try:
        when = datetime.fromisoformat(text)  # Python 3.11 reads a trailing Z as UTC
    except ValueError:
        return text
    return text if when.tzinfo is None else when


def shutdown_refusal(state: VehicleState) -> str | None:
    """T07: why the robot cannot shut down now (it must be idle, §6.6.8: no node or edge
    states, every order action ended), or None."""
    if state.nodes or state.edges:
        return f"the robot is not idle: order {state.order_id!r} has nodes left to drive"
    if any(not r.terminal and r.scope is not ActionScope.INSTANT for r in state.actions):
        return "the robot is not idle: an order action has not ended"
    return None


def finished_instant(
    state: VehicleState, action: v3.InstantAction, group: int, *, failed: str | None = None
) -> VehicleState:
    """An instant action done at the edge at once (``stopHibernation``, zone set actions):
    FINISHED, or FAILED with ``failed`` as its result."""
    record = moved(
        ActionRecord(core_action(action), ActionScope.INSTANT, group, triggered=True),
        ActionStatus.RUNNING,
    )
    done = (
        moved(record, ActionStatus.FAILED, result=failed)
        if failed is not None
        else moved(record, ActionStatus.FINISHED)
    )
    return state.bumped(actions=(*state.actions, done), next_group=group - 1)


def keep_ended_instant_states(before: VehicleState, after: VehicleState) -> VehicleState:
    """T57: a new order replaces the order's action states, but ended instant action states
    stay until ``clearInstantActions`` (the core, as 2.x allows, drops them)."""
    kept = {r.action_id for r in after.actions}
    ended = tuple(
        r
        for r in before.actions
        if r.scope is ActionScope.INSTANT and r.terminal and r.action_id not in kept
    )
    return replace(after, actions=(*ended, *after.actions)) if ended else after


def retype_new_errors(before: tuple[Error, ...], after: tuple[Error, ...]) -> tuple[Error, ...]:
    """Errors the core added for an instant batch: a refused action (the core's actionError) is
    INVALID_INSTANT_ACTION (Table 9)."""
    old = set(map(id, before))
    return tuple(
        e.model_copy(update={"error_type": E.INVALID_INSTANT_ACTION})
        if id(e) not in old and e.error_type == "actionError"
        else e
        for e in after
    )


# -- zones (v3_zones) ---------------------------------------------------------------------------


def _segments(order: v3.Order) -> Iterator[tuple[v3.Edge, str, tuple[Point, ...]]]:
    """Each edge with its map and the way it is driven between its nodes (T18): its
    trajectory's polyline, else the straight segment."""
    by_sequence = {node.sequence_id: node for node in order.nodes}
    for edge in order.edges:
        start = by_sequence[edge.sequence_id - 1].node_position
        end = by_sequence[edge.sequence_id + 1].node_position
        if start is not None and end is not None:
            way = _way(edge.trajectory, (start.x, start.y), (end.x, end.y))
            yield edge, start.map_id, way


def _way(
    trajectory: Trajectory | v3.Trajectory | None, start: Point, end: Point, *, here: bool = False
) -> tuple[Point, ...]:
    """The points an edge is driven through from ``start`` (its start node, or with ``here``
    where the vehicle stands on it) to its end node: the trajectory sampled, else the straight
    line. A trajectory that is no NURBS (refused on acceptance) counts as the straight line."""
    if trajectory is None:
        return (start, end)
    curve = curve_of(trajectory)
    if isinstance(curve, str):
        return (start, end)
    sampled = (*sample(curve)[:-1], end)
    return path_from(sampled, start) if here else (start, *sampled[1:])


def _blocked_by_zones(order3: v3.Order, zones: ZoneSets) -> Check:
    """T89: an order that would drive through an enabled BLOCKED zone cannot be driven."""

    def check(_state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
        errors = []
        for edge, map_id, way in _segments(order3):
            zone = blocked_zone(zones, map_id, way)
            if zone is not None:
                text = f"edge {edge.edge_id!r} runs through BLOCKED zone {zone.zone_id!r}"
                refs = (("edgeId", edge.edge_id), ("zoneId", zone.zone_id))
                errors.append(_order_error(order, E.NO_ROUTE_TO_TARGET, text, *refs))
        return errors

    return check


def zone_capped(order: Order, order3: v3.Order, zones: ZoneSets) -> Order:
    """T89: every edge touching an enabled SPEED_LIMIT zone is driven at most at its limit."""
    limits = {
        edge.sequence_id: limit
        for edge, map_id, way in _segments(order3)
        if (limit := speed_limit(zones, map_id, way)) is not None
    }
    if not limits:
        return order
    edges = [
        edge.model_copy(update={"max_speed": _lower(edge.max_speed, limits[edge.sequence_id])})
        if edge.sequence_id in limits
        else edge
        for edge in order.edges
    ]
    return order.model_copy(update={"edges": edges})


def capped_held_edges(state: VehicleState, zones: ZoneSets) -> VehicleState:
    """A zone set enabled during an order limits the edges still ahead (from where the vehicle
    stands for the edge it is on)."""
    positions = {
        n.node_id: (n.node_position.x, n.node_position.y)
        for n in state.nodes
        if n.node_position is not None
    }
    here = (state.pose.x, state.pose.y)
    edges = []
    for index, edge in enumerate(state.edges):
        start = here if index == 0 else positions.get(edge.start_node_id)
        end = positions.get(edge.end_node_id)
        limit = None
        if start is not None and end is not None:
            way = _way(edge.trajectory, start, end, here=index == 0)
            limit = speed_limit(zones, state.pose.map_id, way)
        edges.append(
            edge
            if limit is None
            else edge.model_copy(update={"max_speed": _lower(edge.max_speed, limit)})
        )
    return state.bumped(edges=tuple(edges))


def blocked_ahead(state: VehicleState, zones: ZoneSets) -> tuple[Edge, str] | None:
    """T89 for a zone set enabled during an order: the first edge still ahead that enters an
    enabled BLOCKED zone (from where the vehicle stands for the edge it is on), with the
    zone's id; None when the way ahead is clear."""
    positions = {
        n.node_id: (n.node_position.x, n.node_position.y)
        for n in state.nodes
        if n.node_position is not None
    }
    here = (state.pose.x, state.pose.y)
    for index, edge in enumerate(state.edges):
        start = here if index == 0 else positions.get(edge.start_node_id)
        end = positions.get(edge.end_node_id)
        if start is None or end is None:
            continue
        zone = blocked_zone(
            zones, state.pose.map_id, _way(edge.trajectory, start, end, here=index == 0)
        )
        if zone is not None:
            return edge, zone.zone_id
    return None


def release_zones_ahead(
    state: VehicleState, zones: Sequence[ReleaseZone], reach: float
) -> tuple[EdgeZones, ...]:
    """T91: the edges of the released base still ahead whose way (from where the vehicle
    stands for the edge it is on) the body, ``reach`` round its reference point, drives into
    one of ``zones`` (the enabled RELEASE zones; §6.4.1.1: contour-based), in driving order,
    each with the zones it reaches."""
    if not zones:
        return ()
    positions = {n.node_id: n.node_position for n in state.nodes if n.node_position is not None}
    here = (state.pose.x, state.pose.y)
    found: list[EdgeZones] = []
    for index, edge in enumerate(state.edges):
        if not edge.released:
            break  # the horizon: asked for once it is released
        end = positions.get(edge.end_node_id)
        begin = None if index == 0 else positions.get(edge.start_node_id)
        if end is None or (index > 0 and begin is None):
            continue
        start = here if begin is None else (begin.x, begin.y)
        way = _way(edge.trajectory, start, (end.x, end.y), here=index == 0)
        reached = tuple(z for z in zones if z.map_id == end.map_id and z.reached(way, reach))
        if reached:
            found.append(EdgeZones(edge.edge_id, edge.sequence_id, edge.end_node_id, reached))
    return tuple(found)


def _lower(current: float | None, limit: float) -> float:
    return limit if current is None else min(current, limit)


# -- errors ---------------------------------------------------------------------------------------


def stored(error: v3.Error) -> Error:
    """A 3.0 error as the core keeps it: the 3.0 type, WARNING unless FATAL (the 3.0 reporter
    restores the Table 9 level from the type)."""
    return Error(
        error_type=error.error_type,
        error_references=error.error_references,
        error_description=error.error_description,
        error_level=ErrorLevel.FATAL
        if error.error_level is v3.ErrorLevel.FATAL
        else ErrorLevel.WARNING,
    )


def retyped(errors: Sequence[Error], error_type: str) -> tuple[Error, ...]:
    return tuple(error.model_copy(update={"error_type": error_type}) for error in errors)


def _order_error(order: Order, error_type: str, text: str, *extra: tuple[str, str]) -> Error:
    pairs = [
        ("headerId", str(order.header_id)),
        ("topic", "order"),
        ("orderId", order.order_id),
        ("orderUpdateId", str(order.order_update_id)),
        *extra,
    ]
    return Error(
        error_type=error_type,
        error_level=ErrorLevel.WARNING,
        error_description=text,
        error_references=[ErrorReference(reference_key=k, reference_value=v) for k, v in pairs],
    )


def _action_error(action: v3.InstantAction, error_type: str, text: str) -> Error:
    pairs = [("actionId", action.action_id), ("actionType", action.action_type)]
    return Error(
        error_type=error_type,
        error_level=ErrorLevel.WARNING,
        error_description=text,
        error_references=[ErrorReference(reference_key=k, reference_value=v) for k, v in pairs],
    )
