"""Receiving instant actions (§6.9) and cancelling an order (§6.6.3 Figure 9), pure."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

from vda5050.models import Action, ActionScope, ActionStatus, Error, InstantActions
from vda_vehicle.actions import (
    ActionSpec,
    action_problem,
    fail_order_actions,
    moved,
    record_of,
    replace_record,
    start_ready,
)
from vda_vehicle.capabilities import Capabilities
from vda_vehicle.faults import action_error, no_order_to_cancel, with_errors
from vda_vehicle.model import ActionRecord, VehicleState, has_order_to_cancel
from vda_vehicle.navigation import EPSILON

CANCEL_ORDER = "cancelOrder"


def receive_instant_actions(
    state: VehicleState, message: InstantActions, caps: Capabilities
) -> VehicleState:
    """Add every action of the batch to actionStates at once (R67) and start what may start.

    The batch is one list for the §6.12 blocking rules, in array order (digest §5.2, derived).
    Work is linear in the batch and in the actions held: ids are looked up in a set, and ended
    instant actions beyond ``kept_instant_action_states`` are forgotten, oldest first.
    """
    group = state.next_group
    state = forget_old_instant_states(state, caps.limits.kept_instant_action_states)
    state = replace(state, next_group=group - 1)
    known = {record.action_id for record in state.actions}
    for action in message.actions:
        if action.action_id in known:
            error = action_error(action, f"actionId {action.action_id!r} is already in use")
            state = replace(state, errors=with_errors(state.errors, error))
            continue
        known.add(action.action_id)
        state = _receive(state, action, group, caps)
    state = start_ready(state, caps.catalog)
    return finish_cancel(state).bumped()


def forget_old_instant_states(state: VehicleState, keep: int) -> VehicleState:
    """§6.10.6 keeps instant actions' states until the next order; so that a stream of instant
    actions cannot grow every state without bound, only the newest ``keep`` ended ones stay."""
    ended = [r for r in state.actions if r.scope is ActionScope.INSTANT and r.terminal]
    if len(ended) <= keep:
        return state
    dropped = {r.action_id for r in ended[: len(ended) - keep]}
    return replace(state, actions=tuple(r for r in state.actions if r.action_id not in dropped))


def _receive(state: VehicleState, action: Action, group: int, caps: Capabilities) -> VehicleState:
    record = ActionRecord(action, ActionScope.INSTANT, group, triggered=True)
    problem = action_problem(caps.catalog.get(action.action_type), ActionScope.INSTANT, action)
    if problem is not None:
        return _refused(state, record, action_error(action, problem))
    if action.action_type == CANCEL_ORDER:
        return begin_cancel(state, record, caps)
    return replace(state, actions=(*state.actions, record))


def _refused(state: VehicleState, record: ActionRecord, error: Error) -> VehicleState:
    """Unknown or out-of-scope instant action: FAILED with a WARNING on its actionId (R83)."""
    failed = moved(record, ActionStatus.FAILED, result=error.error_description)
    return replace(state, actions=(*state.actions, failed), errors=with_errors(state.errors, error))


def begin_cancel(state: VehicleState, record: ActionRecord, caps: Capabilities) -> VehicleState:
    """§6.6.3: cancelOrder goes RUNNING, WAITING and interruptible order actions FAIL.

    The simulated vehicle is line-guided (its factsheet says VIRTUAL_LINE_GUIDED) and stops on
    nodes (R63): on an edge it drives on to the edge's end node, keeping only that node's
    nodeState (no edgeState), and only then is the cancel FINISHED; standing on a node, or with
    ``stop_between_nodes``, it stops where it is and drops every node and edge state at once,
    as it does where a 3.0 zone holds it on the edge (it may not drive on into the zone).
    Either way it ends on a spot where a new order can start (§6.6.3.1).

    Without an order to cancel it ends FAILED with a noOrderToCancel WARNING (R64).
    """
    # RUNNING without an end of its own: finish_cancel ends it (§6.6.3 step 5).
    running = moved(record, ActionStatus.RUNNING, remaining_s=math.inf)
    if not has_order_to_cancel(state):
        failed = moved(running, ActionStatus.FAILED, result="no order to cancel")
        errors = with_errors(state.errors, no_order_to_cancel(record.action))
        return replace(state, actions=(*state.actions, failed), errors=errors)
    on_edge = (
        state.entered_edge is not None
        and bool(state.edges)
        and bool(state.nodes)
        and state.distance_since_last_node > EPSILON  # not still standing on the node it passed
    )
    # A vehicle a zone holds on this edge (3.0, hold_before) may not drive on into it.
    hold = state.hold_before
    held = on_edge and hold is not None and state.edges[0].sequence_id >= hold
    finish_edge = on_edge and not caps.stop_between_nodes and not state.paused and not held
    state = drop_order(state, caps.catalog, keep_next_node=finish_edge)
    return replace(state, actions=(*state.actions, running), cancel_action_id=record.action_id)


def drop_order(
    state: VehicleState, catalog: Mapping[str, ActionSpec], *, keep_next_node: bool = False
) -> VehicleState:
    """What a cancel (§6.6.3 steps 2-4) and a clearing (3.0 §6.6.7) do to the order: WAITING
    and interruptible order actions FAIL; node and edge states go, but for the next node with
    ``keep_next_node`` (a line-guided vehicle finishing its edge, R63); orderId, orderUpdateId
    and lastNodeId stay (R62), and the order takes no update any more."""
    state = fail_order_actions(state, catalog)
    return replace(
        state,
        nodes=state.nodes[:1] if keep_next_node else (),
        edges=state.edges[:1] if keep_next_node else (),
        entered_edge=state.entered_edge if keep_next_node else None,
        order_cancelled=True,
        new_base_request=False,
    )


def finish_cancel(state: VehicleState) -> VehicleState:
    """§6.6.3 step 5, R59, R61: cancelOrder is FINISHED once the vehicle stands and every order
    action has ended; orderId and orderUpdateId stay (R62)."""
    if state.cancel_action_id is None or state.driving or state.nodes:
        return state  # still moving, or still on its way to the node it stops on (R63)
    if any(not r.terminal and r.scope is not ActionScope.INSTANT for r in state.actions):
        return state
    record = record_of(state, state.cancel_action_id)
    state = replace(state, cancel_action_id=None)
    if record is None or record.status is not ActionStatus.RUNNING:
        return state
    return replace_record(state, moved(record, ActionStatus.FINISHED, result="order cancelled"))
