"""Order acceptance and application (§6.6.2 Figure 8, §6.6.4; digest §3.5), pure.

``decide_order`` walks a table of named checks and answers Accept, Reject or Ignore; it never
changes anything (R28). ``apply_order`` builds the state of an accepted order or update.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import Final, Literal

from vda5050.evolve import evolve
from vda5050.models import (
    Action,
    ActionScope,
    ActionStatus,
    Edge,
    Error,
    ErrorLevel,
    ErrorType,
    Node,
    Order,
)
from vda5050.validation import check_order
from vda_vehicle.actions import action_problem, load_type_problem, start_ready, trigger_group
from vda_vehicle.capabilities import REQUIRED_FIELDS, Capabilities, optional_fields_used
from vda_vehicle.faults import order_error
from vda_vehicle.kinematics import unreachable_orientations
from vda_vehicle.limits import order_limit_problems, physical_problems
from vda_vehicle.maps import enabled_map_ids
from vda_vehicle.model import ActionRecord, RobotMode, VehicleState, decision_point, is_busy
from vda_vehicle.trajectories import trajectory_problems
from vda_vehicle.translator import enter_next_edge

Mode = Literal["new", "update"]


@dataclass(frozen=True, slots=True)
class Accept:
    mode: Mode


@dataclass(frozen=True, slots=True)
class Reject:
    """The order is refused; ``errors`` go into ``state.errors`` as WARNINGs (§6.6.4)."""

    errors: tuple[Error, ...]


@dataclass(frozen=True, slots=True)
class Ignore:
    """Same orderId and orderUpdateId: a resend, discarded silently (R45)."""


Decision = Accept | Reject | Ignore
Check = Callable[[VehicleState, Order, Capabilities], list[Error]]


def decide_order(state: VehicleState, order: Order, caps: Capabilities) -> Decision:
    """Figure 8: decide what to do with an (already schema-valid) order message."""
    is_update = bool(state.order_id) and order.order_id == state.order_id
    if is_update and order.order_update_id < state.order_update_id:
        return Reject((_outdated(state, order),))
    if is_update and order.order_update_id == state.order_update_id:
        return Ignore()
    for check in UPDATE_CHECKS if is_update else NEW_ORDER_CHECKS:
        errors = check(state, order, caps)
        if errors:
            return Reject(tuple(errors))
    return Accept("update" if is_update else "new")


# -- checks, in Figure 8 order --------------------------------------------------------------


def valid_new_order(_state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
    """Step 1, R21-R27: a new order's sequenceIds start at 0 (§6.6.2)."""
    return check_order(order, first_sequence_id=0)


def valid_update(_state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
    """Step 1 for an update: numbering continues from the stitching node (checked below)."""
    return check_order(order)


#: The modes in which the vehicle takes an order (a 2.x vehicle is never INTERVENED).
_MODES_TAKING_ORDERS: Final = frozenset(
    {RobotMode.AUTOMATIC, RobotMode.SEMIAUTOMATIC, RobotMode.INTERVENED}
)


def operating_mode_allows(state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
    """§6.10.6 Table 1: only AUTOMATIC and SEMIAUTOMATIC take orders; 3.0's INTERVENED takes
    them for after the operator (Table 11; T26: otherwise MOBILE_ROBOT_NOT_AVAILABLE)."""
    if state.operating_mode in _MODES_TAKING_ORDERS:
        return []
    text = f"operatingMode {state.operating_mode} does not take orders"
    return [order_error(order, ErrorType.ORDER, text, ("operatingMode", state.operating_mode))]


def actions_supported(_state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
    """R31, R33, R83: every action is known, in a declared scope, with its parameters; a
    pick or drop names a ``loadType`` of the vehicle's load sets (factsheet ``loadSets``)."""
    errors: list[Error] = []
    for scope, element in _elements(order):
        for action in element.actions:
            problem = action_problem(caps.catalog.get(action.action_type), scope, action)
            problem = problem or load_type_problem(action, caps.load_types)
            if problem is not None:
                refs = (("actionId", action.action_id), ("actionType", action.action_type))
                errors.append(order_error(order, ErrorType.ORDER, problem, *refs))
    return errors


def fields_supported(_state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
    """R32, R115 (§6.1.1): an optional field the vehicle cannot act on rejects the order."""
    errors = [
        order_error(order, ErrorType.ORDER, f"{path} ({where}) is not supported", ("field", path))
        for path, where in optional_fields_used(order)
        if path not in caps.supported_fields
    ]
    errors.extend(
        order_error(order, ErrorType.ORDER, f"{path} is required", ("field", path), ("nodeId", n))
        for path in REQUIRED_FIELDS
        for n in (node.node_id for node in order.nodes if node.node_position is None)
    )
    errors.extend(
        order_error(
            order,
            ErrorType.ORDER,
            f"edge {edge.edge_id} maxHeight {edge.max_height} m is below the vehicle's "
            f"{caps.height_m} m",
            ("edgeId", edge.edge_id),
            ("field", "order.edges.maxHeight"),
        )
        for edge in order.edges
        if edge.max_height is not None and edge.max_height < caps.height_m
    )
    return errors


def maps_known(state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
    """R35 (§6.7.1): every mapId of the order must be a map the vehicle holds ENABLED
    (:mod:`vda_vehicle.maps`)."""
    unknown = sorted(
        {n.node_position.map_id for n in order.nodes if n.node_position} - enabled_map_ids(state)
    )
    return [
        order_error(order, ErrorType.ORDER, f"unknown mapId {map_id!r}", ("mapId", map_id))
        for map_id in unknown
    ]


def within_limits(_state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
    """R36 (§6.1.2, §6.15): beyond a declared protocol limit, the order is rejected with a
    validationError naming the limit. Checked first: counts before per-element work."""
    return [
        order_error(order, ErrorType.VALIDATION, problem)
        for problem in order_limit_problems(order, caps.limits)
    ]


def physically_possible(_state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
    """No positive speed, a negative length or height (validationError), or a node off every
    map the vehicle holds (orderError): no vehicle can drive that."""
    return [
        order_error(
            order,
            ErrorType.ORDER if problem.off_map else ErrorType.VALIDATION,
            problem.description,
            problem.reference,
        )
        for problem in physical_problems(order, caps.map_extents)
    ]


def trajectories_followable(_state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
    """§6.6.6 trajectory: a NURBS (else validationError) that starts and ends at its edge's
    nodes within their allowedDeviationXY (validationError), of a degree the stack follows
    (orderError); each error names the edge (:mod:`vda_vehicle.trajectories`)."""
    return [
        order_error(
            order,
            ErrorType.VALIDATION if problem.invalid else ErrorType.ORDER,
            problem.description,
            ("edgeId", problem.edge_id),
            ("field", "order.edges.trajectory"),
        )
        for problem in trajectory_problems(order, caps.deviation_xy_m)
    ]


def orientations_reachable(_state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
    """R34 (§6.6.6): an edge orientation the vehicle's drive cannot hold rejects the order
    (:mod:`vda_vehicle.kinematics`; never for an omnidirectional vehicle)."""
    return [
        order_error(order, ErrorType.ORDER, problem.description, ("edgeId", problem.edge_id))
        for problem in unreachable_orientations(order, caps.kinematic, caps.deviation_theta_rad)
    ]


def not_busy(state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
    """Step 3, R40, R41: no new orderId while busy (2.0 Figure 8: orderUpdateError)."""
    if not is_busy(state):
        return []
    text = f"order {state.order_id!r} is still running; a new order needs an idle vehicle"
    return [order_error(order, ErrorType.ORDER_UPDATE, text)]


def start_reachable(state: VehicleState, order: Order, caps: Capabilities) -> list[Error]:
    """Step 4, R37-R39: the vehicle stands on the first node or within its deviation.

    2.0 Figure 8 names this noRouteError, with the first node as reference (§11 item 6). The
    heading is only checked when the node gives both theta and allowedDeviationTheta.
    """
    first = order.nodes[0]
    if _reaches(state, first, caps):
        return []
    text = f"the first node {first.node_id!r} is not where the vehicle stands"
    return [order_error(order, ErrorType.NO_ROUTE, text, ("nodeId", first.node_id))]


def not_after_cancel(state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
    """Digest §11 item 14 / §3.6: 2.x is silent about updating a cancelled order; this vehicle
    refuses it as 3.0 does (ORDER_UPDATE_FOLLOWING_CANCEL), so restarts use a new orderId."""
    if not state.order_cancelled:
        return []
    return [order_error(order, ErrorType.ORDER_UPDATE, "the order was cancelled")]


def stitches(state: VehicleState, order: Order, _caps: Capabilities) -> list[Error]:
    """Steps 7/8, R46-R50, R53: the update's first node is the decision point, by nodeId AND
    sequenceId; busy this is the last released node held, idle the last traversed node."""
    expected = decision_point(state)
    first = order.nodes[0]
    if (first.node_id, first.sequence_id) == expected:
        return []
    text = (
        f"the update starts at {first.node_id!r}/{first.sequence_id}, not at the decision point "
        f"{expected[0]!r}/{expected[1]}"
    )
    return [order_error(order, ErrorType.ORDER_UPDATE, text, ("nodeId", first.node_id))]


_CONTENT_CHECKS: tuple[Check, ...] = (
    operating_mode_allows,
    actions_supported,
    fields_supported,
    maps_known,
    physically_possible,
    trajectories_followable,
    orientations_reachable,
)
NEW_ORDER_CHECKS: tuple[Check, ...] = (
    within_limits,
    valid_new_order,
    *_CONTENT_CHECKS,
    not_busy,
    start_reachable,
)
UPDATE_CHECKS: tuple[Check, ...] = (
    within_limits,
    valid_update,
    *_CONTENT_CHECKS,
    not_after_cancel,
    stitches,
)


def _outdated(state: VehicleState, order: Order) -> Error:
    """R44 (§6.6.4.3): a lower orderUpdateId is an orderUpdateError."""
    text = f"orderUpdateId {order.order_update_id} is older than {state.order_update_id}"
    return order_error(order, ErrorType.ORDER_UPDATE, text)


def _elements(order: Order) -> Iterable[tuple[ActionScope, Node | Edge]]:
    for node in order.nodes:
        yield ActionScope.NODE, node
    for edge in order.edges:
        yield ActionScope.EDGE, edge


def _reaches(state: VehicleState, node: Node, caps: Capabilities) -> bool:
    position = node.node_position
    if position is None:
        return node.node_id == state.last_node_id
    tolerance = position.allowed_deviation_xy or caps.deviation_xy_m
    if position.map_id != state.pose.map_id:
        return False
    if state.pose.distance_to(position.x, position.y) > tolerance:
        return False
    if position.theta is None or not position.allowed_deviation_theta:
        return True
    return abs(angle_difference(state.pose.theta, position.theta)) <= (
        position.allowed_deviation_theta
    )


def angle_difference(a: float, b: float) -> float:
    """``a - b`` wrapped into [-pi, pi]."""
    return (a - b + math.pi) % (2 * math.pi) - math.pi


# -- applying an accepted order ----------------------------------------------------------------


def apply_order(
    state: VehicleState,
    order: Order,
    mode: Mode,
    caps: Capabilities,
    *,
    alone: frozenset[str] = frozenset(),
    retriable: frozenset[str] = frozenset(),
) -> VehicleState:
    """The state after accepting ``order`` as a new order or an update (§6.6.2, Figure 8).

    ``alone``: actionIds that run alone while the vehicle drives (3.0 SINGLE, Table 3);
    ``retriable``: actionIds whose failure waits for retry/skipRetry (3.0 RETRIABLE).
    """
    cleared = tuple(e for e in state.errors if e.error_level is not ErrorLevel.WARNING)  # R29
    flags = _Flags(alone, retriable)
    applied = (
        _apply_new(state, order, flags) if mode == "new" else _apply_update(state, order, flags)
    )
    applied = evolve(applied, order_update_id=order.order_update_id, errors=cleared)
    return enter_next_edge(start_ready(applied, caps.catalog), caps).bumped()


@dataclass(frozen=True, slots=True)
class _Flags:
    """3.0 action properties the 2.x wire action cannot carry (see apply_order)."""

    alone: frozenset[str]
    retriable: frozenset[str]

    def record(self, action: Action, scope: ActionScope, group: int) -> ActionRecord:
        return ActionRecord(
            action,
            scope,
            group,
            alone=action.action_id in self.alone,
            retriable=action.action_id in self.retriable,
        )


def _apply_new(state: VehicleState, order: Order, flags: _Flags) -> VehicleState:
    """R42, R43: drop the old order except running instant actions; the first node counts as
    traversed at once (digest §11 item 7, R39), so its actions are triggered now."""
    kept = tuple(r for r in state.actions if r.scope is ActionScope.INSTANT and not r.terminal)
    first = order.nodes[0]
    fresh = evolve(
        state,
        order_id=order.order_id,
        zone_set_id=order.zone_set_id,
        last_node_id=first.node_id,
        last_node_sequence_id=first.sequence_id,
        nodes=tuple(order.nodes[1:]),
        edges=tuple(order.edges),
        entered_edge=None,
        order_cancelled=False,
        distance_since_last_node=0.0,
        actions=kept + _records(order.nodes, order.edges, flags),
    )
    return trigger_group(fresh, first.sequence_id)


def _apply_update(state: VehicleState, order: Order, flags: _Flags) -> VehicleState:
    """R46, R48, R51, R52, R54: drop the horizon and its WAITING actions, keep the stitching
    node as first received (its actions are not added again), append the rest of the update."""
    horizon = {n.sequence_id for n in state.nodes if not n.released}
    horizon |= {e.sequence_id for e in state.edges if not e.released}
    kept = tuple(
        r
        for r in state.actions
        if not (
            r.group in horizon
            and r.scope is not ActionScope.INSTANT
            and r.status is ActionStatus.WAITING
        )
    )
    return replace(
        state,
        nodes=tuple(n for n in state.nodes if n.released) + tuple(order.nodes[1:]),
        edges=tuple(e for e in state.edges if e.released) + tuple(order.edges),
        actions=kept + _records(order.nodes[1:], order.edges, flags),
    )


def _records(
    nodes: Iterable[Node], edges: Iterable[Edge], flags: _Flags
) -> tuple[ActionRecord, ...]:
    """R68: every action of the order, horizon included, starts WAITING."""
    node_records = [
        flags.record(action, ActionScope.NODE, node.sequence_id)
        for node in nodes
        for action in node.actions
    ]
    edge_records = [
        flags.record(action, ActionScope.EDGE, edge.sequence_id)
        for edge in edges
        for action in edge.actions
    ]
    return (*node_records, *edge_records)
