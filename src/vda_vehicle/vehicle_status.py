"""What the robot reports beyond its motion: who controls it and its safety chain (pure).

A real robot is switched between AUTOMATIC and MANUAL by an operator, stopped by an emergency
stop or a protective field; none of that is the master's doing or the order's. Its navigation
stack reports it as a :class:`StackStatus` (:meth:`vda_vehicle.runtime.VehicleRuntime.
on_stack_status`, whenever it changes); :func:`apply_status` folds it into the vehicle state:

- ``operatingMode`` follows the robot (§6.10.6 Table 1). Entering MANUAL, SERVICE or TEACHIN,
  or leaving MANUAL, clears the order (2.x Table 1 "when the AGV enters or leaves this mode,
  it immediately clears all the orders", R105; 3.0 §6.6.7 for MANUAL, SERVICE, TEACH_IN):
  nodeStates and edgeStates become empty, WAITING and interruptible order actions FAILED;
  orderId, orderUpdateId and lastNodeId stay. Orders are refused while the mode takes none
  (:func:`vda_vehicle.order_executor.operating_mode_allows`), and the vehicle does not drive.
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
from dataclasses import dataclass
from typing import Final

from vda5050.models import EStop, OperatingMode
from vda_vehicle.actions import ActionSpec
from vda_vehicle.instant import drop_order
from vda_vehicle.model import STANDSTILL, VehicleState, has_order_to_cancel

#: Modes that clear the order when entered (2.x Table 1: MANUAL; 3.0 §6.6.7: all three).
_CLEARING_MODES: Final = frozenset(
    {OperatingMode.MANUAL, OperatingMode.SERVICE, OperatingMode.TEACHIN}
)


@dataclass(frozen=True, slots=True)
class StackStatus:
    """The robot's operating mode and safety chain, as its navigation stack knows them."""

    operating_mode: OperatingMode = OperatingMode.AUTOMATIC
    e_stop: EStop = EStop.NONE
    field_violation: bool = False


def status_of(state: VehicleState) -> StackStatus:
    """The status ``state`` reports now."""
    return StackStatus(state.operating_mode, state.e_stop, state.field_violation)


def clears_order(before: OperatingMode, after: OperatingMode) -> bool:
    """Whether switching from ``before`` to ``after`` clears the order (see module docstring)."""
    return before != after and (after in _CLEARING_MODES or before is OperatingMode.MANUAL)


def apply_status(
    state: VehicleState,
    status: StackStatus,
    catalog: Mapping[str, ActionSpec],
    *,
    forgets_last_node: frozenset[OperatingMode] = frozenset(),
) -> VehicleState:
    """``state`` with the robot's ``status``; the same object when nothing changed. Entering a
    mode of ``forgets_last_node`` sets lastNodeId to "" (3.0 T62: SERVICE, TEACH_IN)."""
    if status == status_of(state):
        return state
    if clears_order(state.operating_mode, status.operating_mode):
        state = clear_order(state, catalog)
    stops = state.nodes == () or status.e_stop is not EStop.NONE
    entered = status.operating_mode != state.operating_mode
    forgets = entered and status.operating_mode in forgets_last_node
    return state.bumped(
        operating_mode=status.operating_mode,
        e_stop=status.e_stop,
        field_violation=status.field_violation,
        # A cleared order or an e-stop stops the vehicle where it stands.
        motion=STANDSTILL if stops else state.motion,
        last_node_id="" if forgets else state.last_node_id,
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
