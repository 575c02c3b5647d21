"""Topic ``state`` (3.0): mobile robot → fleet control (§6.6, field tables §7.8).

Changes from 2.x: ``agvPosition`` → ``mobileRobotPosition`` (``positionInitialized`` →
``localized``), ``batteryState`` → ``powerSupply`` (``batteryCharge`` → ``stateOfCharge``),
instant actions report in ``instantActionStates`` and zone actions in ``zoneActionStates``,
``resultDescription`` → ``actionResult``, ``eStop`` → ``activeEmergencyStop`` (AUTOACK is gone);
new ``zoneSets``, ``zoneRequests``, ``edgeRequests``, ``plannedPath``, ``intermediatePath``.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum
from types import MappingProxyType
from typing import Final

from vda5050.models.base import NonNegativeFloat, Percent, UInt32
from vda5050.models.state import InfoLevel, InfoReference, MapStatus
from vda5050.models.v3.base import V3Message, V3WireModel
from vda5050.models.v3.common import (
    IntermediatePath,
    Load,
    MobileRobotPosition,
    PlannedPath,
    Trajectory,
    Velocity,
)
from vda5050.models.v3.errors import Error
from vda5050.models.v3.modes import OperatingMode

__all__ = [
    "ACTION_TRANSITIONS",
    "FINAL_ACTION_STATUSES",
    "ActionState",
    "ActionStatus",
    "EdgeRequest",
    "EdgeRequestType",
    "EdgeState",
    "EmergencyStop",
    "Info",
    "InfoLevel",
    "InfoReference",
    "Map",
    "MapStatus",
    "NodeState",
    "NodeStatePosition",
    "PowerSupply",
    "RequestStatus",
    "SafetyState",
    "State",
    "StoredZoneSet",
    "ZoneRequest",
    "ZoneRequestType",
    "ZoneSetStatus",
    "may_transition",
]


class ActionStatus(StrEnum):
    """Lifecycle of an action (§6.6.9, Table 12, Figure 21). RETRIABLE is new in 3.0: a failed
    action with ``retriable: true`` waits there for ``retry`` or ``skipRetry``."""

    WAITING = "WAITING"
    INITIALIZING = "INITIALIZING"
    RUNNING = "RUNNING"
    PAUSED = "PAUSED"
    RETRIABLE = "RETRIABLE"
    FINISHED = "FINISHED"
    FAILED = "FAILED"


#: The end states: nothing leaves FINISHED or FAILED (RETRIABLE is not one).
FINAL_ACTION_STATUSES: Final = frozenset({ActionStatus.FINISHED, ActionStatus.FAILED})

_S = ActionStatus
#: Figure 21 (T51): the statuses an action may move to from each status; ``None`` is "just
#: received", i.e. the first status reported.
ACTION_TRANSITIONS: Final[Mapping[ActionStatus | None, frozenset[ActionStatus]]] = MappingProxyType(
    {
        None: frozenset({_S.WAITING, _S.INITIALIZING, _S.RUNNING, _S.FINISHED, _S.FAILED}),
        _S.WAITING: frozenset({_S.INITIALIZING, _S.RUNNING, _S.FINISHED, _S.FAILED}),
        _S.INITIALIZING: frozenset({_S.PAUSED, _S.RUNNING, _S.FAILED}),
        _S.PAUSED: frozenset({_S.INITIALIZING, _S.RUNNING, _S.FAILED}),
        _S.RUNNING: frozenset({_S.PAUSED, _S.RETRIABLE, _S.FINISHED, _S.FAILED}),
        _S.RETRIABLE: frozenset({_S.INITIALIZING, _S.RUNNING, _S.FINISHED, _S.FAILED}),
        _S.FINISHED: frozenset(),
        _S.FAILED: frozenset(),
    }
)


def may_transition(before: ActionStatus | None, after: ActionStatus) -> bool:
    """Tell whether Figure 21 allows an action to go from ``before`` (None: new) to ``after``."""
    return after in ACTION_TRANSITIONS[before]


class ZoneSetStatus(StrEnum):
    """Whether a stored zone set is in use; at most one ENABLED per map (§6.4.2)."""

    ENABLED = "ENABLED"
    DISABLED = "DISABLED"


class RequestStatus(StrEnum):
    """Lifecycle of a robot's request (§6.9, Figure 22).

    §6.9 says the field "shall support" QUEUED as well; the §7.8 tables and the official schema
    leave it out. QUEUED is accepted on input (the prose wins); a robot that wants its states to
    pass the official schema keeps a queued request at REQUESTED.
    """

    REQUESTED = "REQUESTED"
    GRANTED = "GRANTED"
    REVOKED = "REVOKED"
    EXPIRED = "EXPIRED"
    QUEUED = "QUEUED"


class ZoneRequestType(StrEnum):
    """ACCESS for a RELEASE zone, REPLANNING for a COORDINATED_REPLANNING zone (§6.4.3)."""

    ACCESS = "ACCESS"
    REPLANNING = "REPLANNING"


class EdgeRequestType(StrEnum):
    """CORRIDOR: leave the edge's trajectory inside its corridor (§6.6.10)."""

    CORRIDOR = "CORRIDOR"


class EmergencyStop(StrEnum):
    """Kind of active emergency stop (§7.8 ``safetyState``); 2.x AUTOACK no longer exists."""

    MANUAL = "MANUAL"
    REMOTE = "REMOTE"
    NONE = "NONE"


class Map(V3WireModel):
    """A map stored on the robot (§6.3.2)."""

    map_id: str
    map_version: str
    map_descriptor: str | None = None
    map_status: MapStatus


class StoredZoneSet(V3WireModel):
    """A zone set stored on the robot, as listed in ``state.zoneSets`` (§7.8 ``zoneSet``)."""

    zone_set_id: str
    map_id: str
    zone_set_status: ZoneSetStatus


class NodeStatePosition(V3WireModel):
    """Position of a pending node, for debugging only."""

    x: float
    y: float
    theta: float | None = None
    map_id: str


class NodeState(V3WireModel):
    """A node still to be traversed (§7.8 ``nodeState``)."""

    node_id: str
    sequence_id: UInt32
    node_descriptor: str | None = None
    released: bool
    node_position: NodeStatePosition | None = None


class EdgeState(V3WireModel):
    """An edge still to be traversed (§7.8 ``edgeState``)."""

    edge_id: str
    sequence_id: UInt32
    edge_descriptor: str | None = None
    released: bool
    trajectory: Trajectory | None = None


class ZoneRequest(V3WireModel):
    """A request to enter a RELEASE zone or to (re)plan through a COORDINATED_REPLANNING zone
    (§6.4.3)."""

    request_id: str
    request_type: ZoneRequestType
    zone_id: str
    zone_set_id: str
    request_status: RequestStatus
    #: The planned path through the zone, for REPLANNING requests.
    trajectory: Trajectory | None = None


class EdgeRequest(V3WireModel):
    """A request to use the corridor of a base edge (§6.6.10)."""

    request_id: str
    request_type: EdgeRequestType
    edge_id: str
    sequence_id: UInt32
    request_status: RequestStatus


class ActionState(V3WireModel):
    """Current status of one action (§7.8 ``actionState``)."""

    action_id: str
    action_type: str | None = None
    action_descriptor: str | None = None
    action_status: ActionStatus
    action_result: str | None = None


class PowerSupply(V3WireModel):
    """Power-supply status (§7.8; 2.x ``batteryState``). ``stateOfCharge`` in %, voltage in V,
    current in A, ``range`` in m.

    The text types ``batteryHealth`` as int8 and ``range`` as uint32, the schema both as
    number; any number in range is accepted so a robot reporting 97.5 % is not dropped.
    """

    state_of_charge: Percent
    battery_voltage: float | None = None
    battery_current: float | None = None
    battery_health: Percent | None = None
    #: Reported false only while the robot is available for orders (§7.8).
    charging: bool
    range: NonNegativeFloat | None = None


class Info(V3WireModel):
    """Debug or visualisation information; fleet control must not base logic on it (§6.6.4)."""

    info_type: str
    info_references: list[InfoReference] | None = None
    info_descriptor: str | None = None
    info_level: InfoLevel


class SafetyState(V3WireModel):
    """Emergency stop and protective field (§7.8 ``safetyState``)."""

    active_emergency_stop: EmergencyStop
    field_violation: bool


class State(V3Message):
    """The robot's complete status (§6.6, §7.8)."""

    maps: list[Map] | None = None
    zone_sets: list[StoredZoneSet] | None = None
    order_id: str
    order_update_id: UInt32
    last_node_id: str
    last_node_sequence_id: UInt32
    node_states: list[NodeState]
    edge_states: list[EdgeState]
    planned_path: PlannedPath | None = None
    intermediate_path: IntermediatePath | None = None
    mobile_robot_position: MobileRobotPosition | None = None
    velocity: Velocity | None = None
    loads: list[Load] | None = None
    driving: bool
    paused: bool | None = None
    new_base_request: bool | None = None
    zone_requests: list[ZoneRequest] | None = None
    edge_requests: list[EdgeRequest] | None = None
    distance_since_last_node: float | None = None
    action_states: list[ActionState]
    instant_action_states: list[ActionState]
    #: Required when the robot supports ACTION zones (§7.8).
    zone_action_states: list[ActionState] | None = None
    power_supply: PowerSupply
    operating_mode: OperatingMode
    errors: list[Error]
    information: list[Info] | None = None
    safety_state: SafetyState

    def is_idle(self) -> bool:
        """§6.6.8: no nodeStates, no edgeStates, and every order action FINISHED or FAILED.

        Instant and zone actions do not count; a robot with a horizon is waiting for an update
        and is not idle.
        """
        return (
            not self.node_states
            and not self.edge_states
            and all(a.action_status in FINAL_ACTION_STATUSES for a in self.action_states)
        )

    def action_state(self, action_id: str) -> ActionState | None:
        """The state of order, instant or zone action ``action_id``, or None."""
        for states in (self.action_states, self.instant_action_states, self.zone_action_states):
            for state in states or ():
                if state.action_id == action_id:
                    return state
        return None
