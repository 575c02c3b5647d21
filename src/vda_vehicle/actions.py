"""Action state machines (§6.11 Figure 16) and blocking rules (§6.12 Figure 17), pure.

Every status change goes through :func:`moved`, which checks the transition table, so an
illegal path (say WAITING → FINISHED) is a programming error caught by the tests (R69).
An action's life is data: :class:`ActionSpec` gives its scopes, parameters, preparation and run
durations and whether it can be interrupted; its effect on the vehicle is a pure function
applied when it finishes (``action_catalog`` holds the vehicle's actions).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, replace
from typing import Final

from vda5050.evolve import evolve
from vda5050.models import Action, ActionScope, ActionStatus, BlockingType, Error
from vda5050.models.factsheet import ValueDataType
from vda_vehicle.faults import with_errors
from vda_vehicle.model import ActionRecord, VehicleState

S = ActionStatus

#: Figure 16. ``None`` is the start: instant actions may begin RUNNING or even FINISHED.
#: PAUSED → FAILED is missing from the 2.x figure but cancelOrder needs it; 3.0 adds it (§5.3).
TRANSITIONS: Final[Mapping[ActionStatus | None, frozenset[ActionStatus]]] = {
    None: frozenset({S.WAITING, S.INITIALIZING, S.RUNNING, S.FINISHED}),
    S.WAITING: frozenset({S.INITIALIZING, S.RUNNING, S.FAILED}),
    S.INITIALIZING: frozenset({S.RUNNING, S.PAUSED, S.FAILED}),
    S.RUNNING: frozenset({S.PAUSED, S.FINISHED, S.FAILED}),
    S.PAUSED: frozenset({S.RUNNING, S.INITIALIZING, S.FAILED}),
    S.FINISHED: frozenset(),
    S.FAILED: frozenset(),
}


@dataclass(frozen=True, slots=True)
class EffectResult:
    """What finishing an action did: the new vehicle state, or why the action failed."""

    state: VehicleState
    error: Error | None = None
    result: str | None = None


#: Applied when the action's run phase ends; ``error`` makes it FAILED instead of FINISHED.
Effect = Callable[[VehicleState, ActionRecord], EffectResult]


def no_effect(state: VehicleState, _record: ActionRecord) -> EffectResult:
    return EffectResult(state)


@dataclass(frozen=True, slots=True)
class ParameterSpec:
    """An action parameter as the factsheet declares it (§6.15 agvActions.actionParameters)."""

    key: str
    value_type: ValueDataType
    description: str
    optional: bool = False


@dataclass(frozen=True, slots=True)
class ActionSpec:
    """How this vehicle performs one actionType."""

    action_type: str
    description: str
    scopes: frozenset[ActionScope]
    parameters: tuple[ParameterSpec, ...] = ()
    init_s: float = 0.0
    run_s: float = 0.0
    interruptible: bool = True
    effect: Effect = no_effect
    result_description: str | None = None
    blocking_types: frozenset[BlockingType] = frozenset(BlockingType)


def moved(record: ActionRecord, status: ActionStatus, **changes: object) -> ActionRecord:
    """``record`` in ``status``; raises ValueError for a transition Figure 16 does not allow."""
    if status not in TRANSITIONS[record.status]:
        msg = f"action {record.action_id!r}: {record.status} -> {status} is not allowed"
        raise ValueError(msg)
    return evolve(record, status=status, **changes)


def first_phase(spec: ActionSpec) -> tuple[ActionStatus, float]:
    """INITIALIZING where the action prepares (init_s > 0), else RUNNING (§6.11)."""
    if spec.init_s > 0:
        return S.INITIALIZING, spec.init_s
    return S.RUNNING, spec.run_s


def action_problem(spec: ActionSpec | None, scope: ActionScope, action: Action) -> str | None:
    """Why this vehicle cannot run ``action`` in ``scope``, or None (R31, R83, §6.15)."""
    if spec is None:
        return f"actionType {action.action_type!r} is not supported by this vehicle"
    if scope not in spec.scopes:
        return f"{spec.action_type} cannot be used as a {scope.value.lower()} action"
    if action.blocking_type not in spec.blocking_types:
        return f"{spec.action_type} does not support blockingType {action.blocking_type}"
    for parameter in spec.parameters:
        value = action.parameter(parameter.key)
        if value is None and not parameter.optional:
            return f"{spec.action_type} needs parameter {parameter.key!r}"
        if value is not None and not _fits(value, parameter.value_type):
            return f"{spec.action_type} parameter {parameter.key!r} must be {parameter.value_type}"
    return None


#: The actions whose ``loadType`` must be one the vehicle handles (§6.8.2).
LOAD_ACTIONS: Final = frozenset({"pick", "drop"})


def load_type_problem(action: Action, load_types: Collection[str]) -> str | None:
    """Why a pick or drop of ``action``'s ``loadType`` is beyond this vehicle, whose factsheet
    declares one load set per type in ``load_types``; None when it is not (or names none)."""
    if action.action_type not in LOAD_ACTIONS:
        return None
    load_type = action.parameter("loadType")
    if not isinstance(load_type, str) or load_type in load_types:
        return None
    handled = ", ".join(repr(t) for t in load_types)
    return (
        f"{action.action_type} parameter 'loadType' {load_type!r} is not a load type of this "
        f"vehicle (its load sets: {handled})"
    )


def _fits(value: object, kind: ValueDataType) -> bool:
    if kind is ValueDataType.STRING:
        return isinstance(value, str)
    if kind in (ValueDataType.NUMBER, ValueDataType.FLOAT, ValueDataType.INTEGER):
        return isinstance(value, int | float) and not isinstance(value, bool)
    return True


# -- scheduling: §6.12 Figure 17 ----------------------------------------------------------------


def startable(group: list[ActionRecord]) -> list[ActionRecord]:
    """The WAITING actions of one list that may start now, walking it in list order.

    NONE and SOFT actions start together as a parallel set; a HARD (or 3.0 SINGLE) action
    starts only when every earlier action has ended, and nothing after it starts while it runs
    (R74, R75; 3.0 Table 3, T48).
    """
    ready: list[ActionRecord] = []
    for index, record in enumerate(group):
        hard = record.runs_alone  # HARD, or 3.0 SINGLE (Table 3)
        if record.status is S.WAITING:
            if not hard:
                ready.append(record)
                continue
            if all(earlier.terminal for earlier in group[:index]):
                ready.append(record)
            break
        if hard and not record.terminal:
            break
    return ready


def triggered_groups(state: VehicleState) -> dict[int, list[ActionRecord]]:
    groups: dict[int, list[ActionRecord]] = {}
    for record in state.actions:
        if record.triggered and not record.terminal:
            groups.setdefault(record.group, [])
    for record in state.actions:
        if record.group in groups:
            groups[record.group].append(record)
    return groups


def motion_blocked(state: VehicleState) -> bool:
    """§6.12, R73: no driving while a triggered SOFT/HARD action has not ended. A running
    cancelOrder (master controllers send it HARD) does not hold a line-guided vehicle that
    drives on to the node it stops on (§6.6.3, R63)."""
    return any(
        record.triggered
        and record.blocking
        and not record.terminal
        and record.action_id != state.cancel_action_id
        for record in state.actions
    )


# -- progress -----------------------------------------------------------------------------------


def replace_record(state: VehicleState, record: ActionRecord) -> VehicleState:
    actions = tuple(
        record if held.action_id == record.action_id else held for held in state.actions
    )
    return evolve(state, actions=actions)


def record_of(state: VehicleState, action_id: str) -> ActionRecord | None:
    for record in state.actions:
        if record.action_id == action_id:
            return record
    return None


def finish(state: VehicleState, record: ActionRecord, spec: ActionSpec) -> VehicleState:
    """End the run phase: apply the effect, then FINISHED, or FAILED with its error."""
    outcome = spec.effect(state, record)
    current = record_of(outcome.state, record.action_id) or record
    if outcome.error is not None and current.retriable:
        # 3.0 RETRIABLE: no end of its own; retry or skipRetry decides (Figure 21).
        waiting = replace(
            current,
            awaiting_retry=True,
            remaining_s=math.inf,
            result=outcome.error.error_description,
        )
        return replace_record(outcome.state, waiting)
    if outcome.error is not None:
        done = moved(current, S.FAILED, remaining_s=0.0, result=outcome.error.error_description)
        errors = with_errors(outcome.state.errors, outcome.error)
        return replace(replace_record(outcome.state, done), errors=errors)
    done = moved(current, S.FINISHED, remaining_s=0.0, result=outcome.result)
    return replace_record(outcome.state, done)


def start(state: VehicleState, record: ActionRecord, spec: ActionSpec) -> VehicleState:
    status, duration = first_phase(spec)
    return replace_record(state, moved(record, status, remaining_s=duration))


def progress(
    state: VehicleState, record: ActionRecord, spec: ActionSpec, dt: float
) -> VehicleState:
    """Let ``record`` (INITIALIZING or RUNNING) work for ``dt`` seconds, across phase ends."""
    remaining = record.remaining_s - dt
    if remaining > 0 or math.isinf(remaining):
        return replace_record(state, evolve(record, remaining_s=remaining))
    if record.status is S.INITIALIZING:
        running = moved(record, S.RUNNING, remaining_s=spec.run_s)
        return progress(replace_record(state, running), running, spec, -remaining)
    return finish(state, record, spec)


def step_actions(state: VehicleState, dt: float, catalog: Mapping[str, ActionSpec]) -> VehicleState:
    """Advance every triggered action by ``dt`` and start what §6.12 allows.

    While paused, order actions neither start nor progress; new instant actions still run.
    """
    if not any(r.triggered and not r.terminal for r in state.actions):
        return state
    # Only the few running actions are visited: O(running × held), not O(held²).
    working = [r.action_id for r in state.actions if r.status in (S.INITIALIZING, S.RUNNING)]
    for action_id in working:
        current = record_of(state, action_id)
        if current is not None and current.status in (S.INITIALIZING, S.RUNNING):
            state = progress(state, current, catalog[current.action_type], dt)
    return start_ready(state, catalog)


def start_ready(state: VehicleState, catalog: Mapping[str, ActionSpec]) -> VehicleState:
    """Start every action §6.12 lets start now, repeating while zero-length actions finish.

    While paused only instant actions start (a paused order must not go on, R76).
    """
    while True:
        ready = [
            r
            for group in triggered_groups(state).values()
            for r in startable(group)
            if not state.paused or r.scope is ActionScope.INSTANT
        ]
        if not ready:
            return state
        for record in ready:
            spec = catalog[record.action_type]
            state = start(state, record, spec)
            started = record_of(state, record.action_id)
            if started is not None and started.remaining_s <= 0:
                state = progress(state, started, spec, 0.0)


# -- pause, cancel and leaving an edge --------------------------------------------------------


def pause_all(state: VehicleState, *, keep: str) -> VehicleState:
    """startPause: every running or preparing action except ``keep`` becomes PAUSED (§11 item 9)."""
    actions = tuple(
        moved(r, S.PAUSED, resume_to=r.status)
        if r.status in (S.INITIALIZING, S.RUNNING) and r.action_id != keep and not r.awaiting_retry
        else r
        for r in state.actions
    )
    return replace(state, actions=actions, paused=True)


def resume_all(state: VehicleState) -> VehicleState:
    """stopPause: PAUSED actions go back to where they were."""
    actions = tuple(
        moved(r, r.resume_to or S.RUNNING, resume_to=None) if r.status is S.PAUSED else r
        for r in state.actions
    )
    return replace(state, actions=actions, paused=False)


def runs_to_its_end(record: ActionRecord, catalog: Mapping[str, ActionSpec]) -> bool:
    """An order action under way that a cancel or a clearing cannot stop: it runs to its end
    (§6.6.3 step 3, R61; 3.0 §6.6.7). A RETRIABLE one waiting for its retry can be stopped."""
    if record.scope is ActionScope.INSTANT or record.terminal or record.status is S.WAITING:
        return False
    spec = catalog.get(record.action_type)
    return not (record.awaiting_retry or spec is None or spec.interruptible)


def fail_order_actions(state: VehicleState, catalog: Mapping[str, ActionSpec]) -> VehicleState:
    """§6.6.3 steps 2-3, R60, R61: WAITING and interruptible order actions become FAILED."""

    def cancelled(record: ActionRecord) -> ActionRecord:
        if record.scope is ActionScope.INSTANT or record.terminal:
            return record
        if runs_to_its_end(record, catalog):
            return record
        return moved(record, S.FAILED, remaining_s=0.0, result="cancelled")

    return replace(state, actions=tuple(cancelled(r) for r in state.actions))


def end_edge_actions(state: VehicleState, edge_sequence_id: int) -> VehicleState:
    """§6.10.2, R71: edge actions end when the edge's end node is traversed.

    A running one is FINISHED (what it changed is undone with the edge); one that never got
    past WAITING or INITIALIZING is FAILED.
    """

    def ended(record: ActionRecord) -> ActionRecord:
        if record.group != edge_sequence_id or record.scope is not ActionScope.EDGE:
            return record
        if record.terminal:
            return record
        done = record.status is S.RUNNING and not record.awaiting_retry
        target = S.FINISHED if done else S.FAILED
        return moved(record, target, remaining_s=0.0, result="edge left")

    return _with_actions(state, tuple(ended(r) for r in state.actions))


def trigger_group(state: VehicleState, group: int) -> VehicleState:
    """Mark the actions of a traversed node or an entered edge as triggered (§6.10.2)."""
    actions = tuple(
        evolve(r, triggered=True) if r.group == group and not r.triggered else r
        for r in state.actions
    )
    return _with_actions(state, actions)


def _with_actions(state: VehicleState, actions: tuple[ActionRecord, ...]) -> VehicleState:
    """``state`` holding ``actions``: ``state`` itself when no record changed (most nodes and
    edges carry no action, and every node reached comes through here: no copy for them)."""
    if all(new is old for new, old in zip(actions, state.actions, strict=True)):
        return state
    return evolve(state, actions=actions)
