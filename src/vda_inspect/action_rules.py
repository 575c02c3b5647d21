"""Whether a vehicle's action states follow the actions it was sent (pure; R60, R68-R78,
R81, R82; docs/inspect.md).
:mod:`vda_inspect.progress` calls these with the order (as its latest
update left it) that a state carries.

- R68 (§6.11): every action of the order, horizon included, is listed in ``actionStates``;
- R70, R71 (§6.10.2): a node action leaves WAITING only once its node is traversed, an edge
  action only once its edge is entered;
- R72 (§6.8.1): an action on the horizon (an element not released) stays WAITING;
- R69 (§6.11, Figure 16): FINISHED and FAILED are final;
- R73, R74, R75 (§6.12): no driving while a SOFT or HARD action of the current node runs;
  nothing else of the list RUNNING beside a RUNNING HARD action; the actions of a list start
  in its order;
- R60 (§6.6.3): once a cancelOrder is FINISHED, no action of the order is WAITING (they
  became FAILED), R82 (§6.8.2): nor did a ``waitForTrigger`` that was waiting end FINISHED;
- R76, R77 (§6.8.2): in the state where ``startPause``/``stopPause`` first shows FINISHED,
  ``paused`` is true (and ``driving`` false) / false; where ``startCharging``/``stopCharging``
  does, ``charging`` is true / false;
- R78, R81 (§6.8.2): where ``initPosition`` (3.0: ``initializePosition``) first shows
  FINISHED, the pose and ``lastNodeId`` are its parameters; where ``pick``/``drop`` does,
  ``loads`` (when reported) has more / fewer entries than while it waited;
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

from vda5050.models import ActionStatus, Order, State, v3
from vda_inspect.severity import Problem, Severity

#: actionId → (sequenceId of its node or edge, actionType, blockingType, place in its list)
OrderActions = dict[str, tuple[int, str, str, int]]
#: actionId → (actionStatus, actionType if the state gives it)
Listed = dict[str, tuple[str, str | None]]

WAITING: Final = ActionStatus.WAITING.value
FINAL: Final = frozenset({ActionStatus.FINISHED.value, ActionStatus.FAILED.value})
FINISHED: Final = ActionStatus.FINISHED.value
RUNNING: Final = ActionStatus.RUNNING.value
#: Started and not ended.
STARTED: Final = frozenset({ActionStatus.INITIALIZING.value, RUNNING, ActionStatus.PAUSED.value})


def order_actions(order: Order | v3.Order) -> OrderActions:
    """The order message's actions by id, with where they sit."""
    found: OrderActions = {}
    for element in (*order.nodes, *order.edges):
        for place, action in enumerate(element.actions or ()):
            blocking = action.blocking_type.value if action.blocking_type else "HARD"
            found[action.action_id] = (element.sequence_id, action.action_type, blocking, place)
    return found


def listed(state: State | v3.State) -> Listed:
    """The state's action states (3.0: instant ones too) by id."""
    actions = [*state.action_states]
    if isinstance(state, v3.State):
        actions.extend(state.instant_action_states)
    return {a.action_id: (a.action_status.value, a.action_type) for a in actions}


def order_action_problems(
    actions: OrderActions,
    kinds: Mapping[int, tuple[str, str, bool]],
    shown: Listed,
    last: int,
) -> list[Problem]:
    """R68, R70-R72 for a state at ``lastNodeSequenceId`` ``last``; ``kinds`` are the order's
    elements by sequenceId (kind, id, released)."""
    missing = sorted(set(actions) - set(shown))
    found: list[Problem] = []
    if missing:
        sequence_id, action_type, _, _ = actions[missing[0]]
        more = f", and {len(missing) - 1} more" if len(missing) > 1 else ""
        text = f"{action_type} {missing[0]!r} (at sequenceId {sequence_id}) not in actionStates"
        found.append(("R68", text + more, Severity.VIOLATION))
    for action_id, (sequence_id, action_type, _, _) in sorted(actions.items(), key=lambda a: a[1]):
        status = shown.get(action_id, (WAITING, None))[0]
        element = kinds.get(sequence_id)
        if status == WAITING or element is None:
            continue
        kind, element_id, released = element
        where = f"{action_type} {action_id!r} on {kind} {element_id!r} (sequenceId {sequence_id})"
        if not released:
            found.append(("R72", f"{where} is {status} on the horizon", Severity.VIOLATION))
        elif kind == "node" and sequence_id > last:
            text = f"{where} is {status} before the node is traversed (last {last})"
            found.append(("R70", text, Severity.VIOLATION))
        elif kind == "edge" and sequence_id > last + 1:
            text = f"{where} is {status} before the edge is entered (last node {last})"
            found.append(("R71", text, Severity.VIOLATION))
        else:
            continue
        break  # one is enough to tell the vehicle gets it wrong
    return found


def blocking_problems(
    actions: OrderActions, shown: Listed, last: int, *, driving: bool
) -> list[Problem]:
    """R73-R75 for a state at ``lastNodeSequenceId`` ``last``: no driving while a SOFT or HARD
    action of the current node has started and not ended (R73); nothing else of a list RUNNING
    beside a RUNNING HARD action (R74); no action started while an earlier one of its list
    still waits (R75)."""
    lists: dict[int, list[tuple[int, str, str, str, str]]] = {}
    for action_id, (sequence_id, action_type, blocking, place) in actions.items():
        status = shown.get(action_id, (WAITING, None))[0]
        lists.setdefault(sequence_id, []).append((place, action_id, action_type, blocking, status))
    for sequence_id, members in sorted(lists.items()):
        members.sort()
        running = [m for m in members if m[4] == RUNNING]
        hard = [m for m in running if m[3] == "HARD"]
        if hard and len(running) > 1:
            other = next(m for m in running if m is not hard[0])
            text = (
                f"HARD {hard[0][2]} {hard[0][1]!r} RUNNING beside {other[2]} {other[1]!r} "
                f"(sequenceId {sequence_id})"
            )
            return [("R74", text, Severity.VIOLATION)]
        waiting_before = None
        for _, action_id, action_type, blocking, status in members:
            if status == WAITING:
                waiting_before = waiting_before or (action_type, action_id)
            elif status in STARTED | {FINISHED} and waiting_before is not None:
                text = (
                    f"{action_type} {action_id!r} is {status} while {waiting_before[0]} "
                    f"{waiting_before[1]!r}, before it in the list, still waits"
                )
                return [("R75", text, Severity.VIOLATION)]
            if sequence_id == last and blocking != "NONE" and status in STARTED and driving:
                text = f"driving while {blocking} {action_type} {action_id!r} is {status}"
                return [("R73", text, Severity.VIOLATION)]
    return []


def after_cancel_problems(
    actions: OrderActions, shown: Listed, before: Mapping[str, str]
) -> list[Problem]:
    """R60: nothing of the order still WAITING once its cancel is FINISHED; R82: a
    ``waitForTrigger`` that had not ended before (``before``: the statuses of the state
    before) ended FAILED, not FINISHED."""
    waiting = sorted(a for a in actions if shown.get(a, (None, None))[0] == WAITING)
    if waiting:
        text = f"{actions[waiting[0]][1]} {waiting[0]!r} still WAITING after cancelOrder FINISHED"
        return [("R60", text, Severity.VIOLATION)]
    for action_id, (_, action_type, _, _) in sorted(actions.items()):
        if action_type != "waitForTrigger" or before.get(action_id) in FINAL:
            continue
        if shown.get(action_id, (None, None))[0] == FINISHED:
            text = f"waitForTrigger {action_id!r} of the cancelled order FINISHED, not FAILED"
            return [("R82", text, Severity.VIOLATION)]
    return []


def final_problems(before: Mapping[str, str], shown: Listed) -> list[Problem]:
    """R69: an action that was FINISHED or FAILED shows another status."""
    for action_id, (status, action_type) in shown.items():
        was = before.get(action_id)
        if was in FINAL and status != was:
            name = f"{action_type} " if action_type else ""
            text = f"action {name}{action_id!r} went from {was} to {status}"
            return [("R69", text, Severity.VIOLATION)]
    return []


def effect_problems(
    action_type: str,
    state: State | v3.State,
    parameters: Mapping[str, object] | None = None,
    loads_before: int | None = None,
) -> list[Problem]:
    """R76-R78 and R81 in the state where an action of ``action_type`` first shows FINISHED;
    ``parameters`` are the sent action's (for initPosition), ``loads_before`` the number of
    loads the vehicle reported while a pick or drop still waited."""
    if action_type in ("startPause", "stopPause", "startCharging", "stopCharging"):
        return _pause_and_charging_problems(action_type, state)
    if action_type in INIT_POSITION and parameters is not None:
        return _init_position_problems(state, parameters)
    if action_type in ("pick", "drop") and state.loads is not None and loads_before is not None:
        now = len(state.loads)
        if (now <= loads_before) if action_type == "pick" else (now >= loads_before):
            text = f"{action_type} FINISHED, yet loads went from {loads_before} to {now} entries"
            return [("R81", text, Severity.VIOLATION)]
    return []


def _pause_and_charging_problems(action_type: str, state: State | v3.State) -> list[Problem]:
    """R76, R77: ``paused`` and ``charging`` as the FINISHED action left them."""
    paused = state.paused
    charging = (
        state.power_supply.charging if isinstance(state, v3.State) else state.battery_state.charging
    )
    if action_type == "startPause" and (paused is not True or state.driving):
        text = f"startPause FINISHED with paused={paused} and driving={state.driving}"
        return [("R76", text, Severity.VIOLATION)]
    if action_type == "stopPause" and paused:
        return [("R76", "stopPause FINISHED with paused=true", Severity.VIOLATION)]
    if action_type == "startCharging" and not charging:
        return [("R77", "startCharging FINISHED with charging=false", Severity.VIOLATION)]
    if action_type == "stopCharging" and charging:
        return [("R77", "stopCharging FINISHED with charging=true", Severity.VIOLATION)]
    return []


#: initPosition, as 3.0 renamed it (``initializePosition``, same parameters).
INIT_POSITION: Final = frozenset({"initPosition", "initializePosition"})
#: How far a reported pose may lie from initPosition's (localisation settles; R78).
INIT_POSITION_XY_M: Final = 0.1
INIT_POSITION_THETA_RAD: Final = 0.1


def _init_position_problems(
    state: State | v3.State, parameters: Mapping[str, object]
) -> list[Problem]:
    """R78: the pose and lastNodeId the state reports are initPosition's parameters."""
    position = state.agv_position if isinstance(state, State) else state.mobile_robot_position
    expected_node = parameters.get("lastNodeId")
    if isinstance(expected_node, str) and state.last_node_id != expected_node:
        text = (
            f"initPosition FINISHED with lastNodeId {state.last_node_id!r}, not {expected_node!r}"
        )
        return [("R78", text, Severity.VIOLATION)]
    if position is None:
        return [("R78", "initPosition FINISHED without a position", Severity.VIOLATION)]
    for key, reported, tolerance in (
        ("x", position.x, INIT_POSITION_XY_M),
        ("y", position.y, INIT_POSITION_XY_M),
        ("theta", position.theta, INIT_POSITION_THETA_RAD),
    ):
        wanted = parameters.get(key)
        if isinstance(wanted, int | float) and abs(reported - wanted) > tolerance:
            text = f"initPosition FINISHED with {key}={reported:g}, not {wanted:g}"
            return [("R78", text, Severity.VIOLATION)]
    wanted_map = parameters.get("mapId")
    if isinstance(wanted_map, str) and position.map_id != wanted_map:
        text = f"initPosition FINISHED on map {position.map_id!r}, not {wanted_map!r}"
        return [("R78", text, Severity.VIOLATION)]
    return []
