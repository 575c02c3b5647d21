"""The vehicle's internal state: immutable data the pure core transforms.

``VehicleState`` is everything the vehicle knows: the part of its order still ahead (base and
horizon), the action records, pose, battery, loads, errors. The reporter turns it into the wire
``State``; the core never touches bytes, topics or the clock. Frozen slotted dataclasses keep a
tick cheap for a thousand vehicles in one process (a copy sets ~25 slots; the tick's hot paths
copy with :func:`vda5050.evolve.evolve`, a third of ``dataclasses.replace``'s time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Final

from vda5050.evolve import evolve
from vda5050.models import (
    Action,
    ActionScope,
    ActionStatus,
    BlockingType,
    Edge,
    Error,
    EStop,
    Load,
    Node,
)

TERMINAL: Final = frozenset({ActionStatus.FINISHED, ActionStatus.FAILED})
ACTIVE: Final = frozenset({ActionStatus.INITIALIZING, ActionStatus.RUNNING, ActionStatus.PAUSED})
BLOCKING: Final = frozenset({BlockingType.SOFT, BlockingType.HARD})
#: Instant-action batches are numbered below zero; nodes and edges use their sequenceId (>= 0).
FIRST_INSTANT_GROUP: Final = -1


class RobotMode(StrEnum):
    """Who controls the robot, for both protocol versions: 2.x §6.10.6 Table 1, and 3.0 §6.6.6
    Table 10, which adds STARTUP and INTERVENED (and spells TEACH_IN, read here as TEACHIN). A
    2.x vehicle holds only the 2.x modes (:mod:`vda_vehicle.vehicle_status` translates)."""

    AUTOMATIC = "AUTOMATIC"
    SEMIAUTOMATIC = "SEMIAUTOMATIC"
    MANUAL = "MANUAL"
    SERVICE = "SERVICE"
    TEACHIN = "TEACHIN"
    INTERVENED = "INTERVENED"
    STARTUP = "STARTUP"

    @classmethod
    def _missing_(cls, value: object) -> RobotMode | None:
        return cls.TEACHIN if value == "TEACH_IN" else None


@dataclass(frozen=True, slots=True)
class PendingMode:
    """A clearing mode the robot has entered but may not report yet (3.0 §6.6.7, T64): an order
    action that cannot be cancelled still runs. ``forgets_last_node``: lastNodeId becomes ""
    once the mode is reported (3.0 T62)."""

    mode: RobotMode
    forgets_last_node: bool = False


@dataclass(frozen=True, slots=True)
class HeldMap:
    """A map on the vehicle (§6.7.2): ``enabled`` is mapStatus ENABLED, else DISABLED."""

    map_id: str
    map_version: str
    enabled: bool


@dataclass(frozen=True, slots=True)
class Pose:
    """Where the vehicle is: metres and radians in the frame of ``map_id`` (§6.7)."""

    x: float
    y: float
    theta: float
    map_id: str

    def distance_to(self, x: float, y: float) -> float:
        return math.hypot(x - self.x, y - self.y)


@dataclass(frozen=True, slots=True)
class ActionRecord:
    """One action the vehicle holds and its progress through Figure 16 (§6.11).

    ``group`` is the sequenceId of the node or edge the action belongs to, or a negative batch
    number for instant actions; actions of one group follow the §6.12 blocking rules in list
    order. ``triggered`` turns true when the node is traversed, the edge entered, or the instant
    action received (§6.10.2); untriggered actions stay WAITING (R70, R72).
    """

    action: Action
    scope: ActionScope
    group: int
    status: ActionStatus = ActionStatus.WAITING
    triggered: bool = False
    remaining_s: float = 0.0
    resume_to: ActionStatus | None = None
    result: str | None = None
    #: Runs alone but lets the vehicle drive (3.0 blocking type SINGLE, §6.2.2 Table 3); the
    #: 2.x wire action then says NONE.
    alone: bool = False
    #: 3.0 ``retriable``: a failure waits for retry/skipRetry instead of ending FAILED.
    retriable: bool = False
    #: Failed while retriable: 3.0 RETRIABLE (kept RUNNING here, with no end of its own, so it
    #: is not terminal and blocks what its blocking type blocks) until retry or skipRetry.
    awaiting_retry: bool = False

    @property
    def action_id(self) -> str:
        return self.action.action_id

    @property
    def action_type(self) -> str:
        return self.action.action_type

    @property
    def blocking(self) -> bool:
        return self.action.blocking_type in BLOCKING

    @property
    def is_retriable_now(self) -> bool:
        """3.0 RETRIABLE: failed, waiting for retry or skipRetry (and not ended since)."""
        return self.awaiting_retry and not self.terminal

    @property
    def runs_alone(self) -> bool:
        """HARD, or 3.0 SINGLE: no other action of its list runs beside it (§6.12)."""
        return self.alone or self.action.blocking_type is BlockingType.HARD

    @property
    def terminal(self) -> bool:
        return self.status in TERMINAL


@dataclass(frozen=True, slots=True)
class Motion:
    """What the navigation stack last reported: speeds in the vehicle frame."""

    vx: float = 0.0
    vy: float = 0.0
    omega: float = 0.0

    @property
    def moving(self) -> bool:
        return self.vx != 0.0 or self.vy != 0.0 or self.omega != 0.0


STANDSTILL: Final = Motion()


@dataclass(frozen=True, slots=True)
class VehicleState:
    """Everything the pure core knows about one vehicle.

    ``nodes``/``edges`` are the order elements not yet traversed, base then horizon, exactly
    what ``nodeStates``/``edgeStates`` report (§6.10.1, R98). ``revision`` goes up on every event
    of §6.10 that calls for a state message; the shell publishes when it changed.
    """

    pose: Pose
    position_initialized: bool = True
    order_id: str = ""
    order_update_id: int = 0
    zone_set_id: str | None = None
    last_node_id: str = ""
    last_node_sequence_id: int = 0
    nodes: tuple[Node, ...] = ()
    edges: tuple[Edge, ...] = ()
    entered_edge: int | None = None
    #: Not to be entered: the edge with this sequenceId and every one after it (3.0: a zone
    #: ahead keeps the vehicle out, T89/T91). The vehicle stops at the node before it, and the
    #: edge's actions wait until it is entered (§6.10.2 step 5).
    hold_before: int | None = None
    order_cancelled: bool = False
    cancel_action_id: str | None = None
    actions: tuple[ActionRecord, ...] = ()
    next_group: int = FIRST_INSTANT_GROUP
    errors: tuple[Error, ...] = ()
    loads: tuple[Load, ...] = ()
    #: The maps the vehicle holds (vda_vehicle.maps); orders may use the ENABLED ones.
    maps: tuple[HeldMap, ...] = ()
    battery_charge: float = 100.0
    charging: bool = False
    paused: bool = False
    operating_mode: RobotMode = RobotMode.AUTOMATIC
    #: The mode the order is being cleared for while an uncancellable action ends (T64).
    pending_mode: PendingMode | None = None
    #: The robot's safety chain (§6.10.6 safetyState), as its stack reports it (vehicle_status).
    e_stop: EStop = EStop.NONE
    field_violation: bool = False
    motion: Motion = field(default=STANDSTILL)
    distance_since_last_node: float = 0.0
    new_base_request: bool = False
    log_count: int = 0
    factsheet_requested: bool = False
    revision: int = 0

    @property
    def driving(self) -> bool:
        """True exactly while translating or rotating (§6.10.6, R100)."""
        return self.motion.moving

    def bumped(self, **changes: object) -> VehicleState:
        """A copy with ``changes`` and a new revision: the change calls for a state (§6.10)."""
        return evolve(self, revision=self.revision + 1, **changes)


def is_busy(state: VehicleState) -> bool:
    """Figure 8 step 3 (2.1): nodeStates non-empty or an actionState neither FINISHED nor FAILED.

    Horizon nodes count, so a vehicle waiting at its decision point for an update is busy.
    """
    return bool(state.nodes) or any(not record.terminal for record in state.actions)


def has_order_to_cancel(state: VehicleState) -> bool:
    """§6.6.3.2: an order is running when nodes remain or an order action has not ended."""
    if state.order_cancelled or state.cancel_action_id is not None:
        return False
    return bool(state.nodes) or any(
        record.scope is not ActionScope.INSTANT and not record.terminal for record in state.actions
    )


def decision_point(state: VehicleState) -> tuple[str, int]:
    """The last released node the vehicle holds (§6.6.2), as (nodeId, sequenceId).

    While the base still lies ahead it is the last released pending node; once it has been
    reached (or without any order) it is the last traversed node.
    """
    for node in reversed(state.nodes):
        if node.released:
            return node.node_id, node.sequence_id
    return state.last_node_id, state.last_node_sequence_id
