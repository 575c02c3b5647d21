"""What the robot reports beyond its motion: who controls it and its safety chain (pure).

A real robot is switched between AUTOMATIC and MANUAL by an operator, stopped by an emergency
stop or a protective field; none of that is the master's doing or the order's. Its navigation
stack reports it as a :class:`StackStatus` (:meth:`vda_vehicle.runtime.VehicleRuntime.
on_stack_status`, whenever it changes); :func:`apply_status` folds it into the vehicle state:

- ``operatingMode`` follows the robot (2.x §6.10.6 Table 1, 3.0 §6.6.6 Tables 10-11). Entering
  MANUAL, SERVICE, TEACHIN or STARTUP, or leaving MANUAL, clears the order (2.x Table 1 "when
  the AGV enters or leaves this mode, it immediately clears all the orders", R105; 3.0 §6.6.7,
  T61): nodeStates and edgeStates become empty, WAITING and interruptible order actions FAILED;
  orderId, orderUpdateId and lastNodeId stay. Orders are refused while the mode takes none
  (:func:`vda_vehicle.order_executor.operating_mode_allows`), and the vehicle does not drive.
- 3.0 only: INTERVENED (an operator steers through the HMI) keeps the order, which goes on when
  the robot returns straight to AUTOMATIC or SEMIAUTOMATIC (T63); orders are still taken. STARTUP,
  SERVICE and TEACH_IN forget lastNodeId (T62), and so does MANUAL once the robot is moved
  where it could not take an order starting at lastNodeId (:func:`moved_by_hand`). While an
  order action that cannot be cancelled
  still runs, a clearing mode is not reported and the order's nodes stay (§6.6.7, T64): the
  vehicle stands, the mode waits in ``pending_mode``, and :func:`finish_clearing` reports it
  once every order action has ended. A 2.x vehicle has neither mode: its state says MANUAL for
  INTERVENED and SERVICE for STARTUP (:data:`MODES_IN_2X_TERMS`), with what those modes do.
- ``safetyState`` follows the robot's safety chain (§6.10.6, R104): ``eStop`` (AUTOACK,
  MANUAL, REMOTE or NONE) and ``fieldViolation``. An active e-stop holds the vehicle where it
  is (:func:`vda_vehicle.translator.must_hold`) but never clears its order: it drives on once
  the stop is acknowledged. 3.0 has no AUTOACK; its state reports such a stop (a bumper, a
  protective field) as a field violation.

Every change is an event that calls for a state message (§6.10: the operatingMode changes).
The simulated stack never reports a status: its vehicle stays AUTOMATIC with no e-stop.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Final

from vda5050.models import EStop, v3
from vda5050.models.v3.modes import V2_NAMES
from vda_vehicle.actions import ActionSpec, fail_order_actions, runs_to_its_end
from vda_vehicle.instant import drop_order
from vda_vehicle.model import (
    STANDSTILL,
    PendingMode,
    RobotMode,
    VehicleState,
    has_order_to_cancel,
)

#: Modes that clear the order when entered (2.x Table 1: MANUAL; 3.0 §6.6.7: all four).
_CLEARING_MODES: Final = frozenset(
    {RobotMode.MANUAL, RobotMode.SERVICE, RobotMode.TEACHIN, RobotMode.STARTUP}
)
#: How a 2.x vehicle reports the modes 3.0 added, as master control reads 3.0 states.
MODES_IN_2X_TERMS: Final[Mapping[RobotMode, RobotMode]] = {
    RobotMode(mode): RobotMode(V2_NAMES[mode])
    for mode in (v3.OperatingMode.INTERVENED, v3.OperatingMode.STARTUP)
}


@dataclass(frozen=True, slots=True)
class StackStatus:
    """The robot's operating mode and safety chain, as its navigation stack knows them. A mode
    in 2.x or 3.0 terms becomes a :class:`RobotMode` with ``RobotMode(mode)`` (either version's
    ``OperatingMode``, or its name); a plain name given here is read the same way."""

    operating_mode: RobotMode = RobotMode.AUTOMATIC
    e_stop: EStop = EStop.NONE
    field_violation: bool = False

    def __post_init__(self) -> None:
        if type(self.operating_mode) is not RobotMode:
            object.__setattr__(self, "operating_mode", RobotMode(self.operating_mode))


def status_of(state: VehicleState) -> StackStatus:
    """The status ``state`` reports now (a mode still pending counts as entered)."""
    pending = state.pending_mode
    mode = state.operating_mode if pending is None else pending.mode
    return StackStatus(mode, state.e_stop, state.field_violation)


def clears_order(before: RobotMode, after: RobotMode) -> bool:
    """Whether switching from ``before`` to ``after`` clears the order (see module docstring)."""
    return before != after and (after in _CLEARING_MODES or before is RobotMode.MANUAL)


@dataclass(frozen=True, slots=True)
class ModeRules:
    """What a protocol version makes of the robot's modes (see the module docstring)."""

    #: Modes reported as another (2.x: :data:`MODES_IN_2X_TERMS`).
    reported_as: Mapping[RobotMode, RobotMode]
    #: Modes whose entry sets lastNodeId to "" (3.0 T62).
    forgets_last_node: frozenset[RobotMode] = frozenset()
    #: A clearing mode waits for uncancellable order actions to end (3.0 §6.6.7, T64).
    waits_for_actions: bool = False
    #: MANUAL sets lastNodeId to "" once the robot is moved away from it (3.0 Table 10, T62).
    manual_move_forgets: bool = False


RULES_2X: Final = ModeRules(reported_as=MODES_IN_2X_TERMS)
RULES_3_0: Final = ModeRules(
    reported_as={},
    forgets_last_node=frozenset({RobotMode.SERVICE, RobotMode.TEACHIN, RobotMode.STARTUP}),
    waits_for_actions=True,
    manual_move_forgets=True,
)


def moved_by_hand(
    state: VehicleState, anchor: tuple[float, float], reach_m: float, rules: ModeRules
) -> VehicleState:
    """3.0 T62: a robot in MANUAL that an operator moved farther than ``reach_m`` (how far from
    a node it still takes an order starting there) from where it stood when MANUAL began
    (``anchor``) cannot start an order at lastNodeId any more: it reports lastNodeId "". The
    same object otherwise (2.x keeps lastNodeId)."""
    if (
        not rules.manual_move_forgets
        or state.operating_mode is not RobotMode.MANUAL
        or not state.last_node_id
        or state.pose.distance_to(*anchor) <= reach_m
    ):
        return state
    return state.bumped(last_node_id="")


def apply_status(
    state: VehicleState,
    status: StackStatus,
    catalog: Mapping[str, ActionSpec],
    rules: ModeRules = RULES_2X,
) -> VehicleState:
    """``state`` with the robot's ``status``; the same object when nothing changed."""
    mode = rules.reported_as.get(status.operating_mode, status.operating_mode)
    status = StackStatus(mode, status.e_stop, status.field_violation)
    if status == status_of(state):
        return state
    before = state.operating_mode
    if state.pending_mode is not None:  # the clearing under way ends in the newest mode
        state = replace(state, pending_mode=PendingMode(mode, _forgets(state, mode, rules)))
    elif clears_order(before, mode):
        if rules.waits_for_actions and _uncancellable_running(state, catalog):
            pending = PendingMode(mode, _forgets(state, mode, rules))
            state = replace(
                fail_order_actions(state, catalog), pending_mode=pending, order_cancelled=True
            )
            return _safety(state, status, stop=True)
        state = clear_order(state, catalog)
    if state.pending_mode is None and mode != before:
        forgets = _forgets(state, mode, rules)
        state = replace(
            state,
            operating_mode=mode,
            last_node_id="" if forgets else state.last_node_id,
        )
    return _safety(state, status, stop=not state.nodes)


def _forgets(state: VehicleState, mode: RobotMode, rules: ModeRules) -> bool:
    return mode != state.operating_mode and mode in rules.forgets_last_node


def _safety(state: VehicleState, status: StackStatus, *, stop: bool) -> VehicleState:
    """The safety chain set and the change counted; a cleared or pending order, or an e-stop,
    stops the vehicle where it stands."""
    stop = stop or status.e_stop is not EStop.NONE
    return state.bumped(
        e_stop=status.e_stop,
        field_violation=status.field_violation,
        motion=STANDSTILL if stop else state.motion,
    )


def _uncancellable_running(state: VehicleState, catalog: Mapping[str, ActionSpec]) -> bool:
    """An order action under way that a clearing lets run to its end (§6.6.7)."""
    return any(runs_to_its_end(record, catalog) for record in state.actions)


def finish_clearing(state: VehicleState, catalog: Mapping[str, ActionSpec]) -> VehicleState:
    """A pending clearing mode (T64) is reported, with the order cleared, once every order
    action has ended."""
    pending = state.pending_mode
    if pending is None or _uncancellable_running(state, catalog):
        return state
    state = drop_order(replace(state, pending_mode=None), catalog)
    return state.bumped(
        operating_mode=pending.mode,
        last_node_id="" if pending.forgets_last_node else state.last_node_id,
        motion=STANDSTILL,
    )


def clear_order(state: VehicleState, catalog: Mapping[str, ActionSpec]) -> VehicleState:
    """The order cleared where the vehicle stands (3.0 §6.6.7): no node or edge states left,
    WAITING and interruptible order actions FAILED (one that cannot be interrupted runs to its
    end), orderId, orderUpdateId and lastNodeId kept. Like a cancelled order, it takes no
    update afterwards (:func:`vda_vehicle.order_executor.not_after_cancel`): the next order
    needs a new orderId."""
    if not state.nodes and not state.edges and not has_order_to_cancel(state):
        return state  # no order, or one a cancel has already cleared
    return drop_order(state, catalog)
