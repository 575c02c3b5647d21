"""Topic ``state``: AGV → master control (§6.10, fields §6.10.6)."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

from pydantic import Field

from vda5050.models.base import (
    SINCE_2_1,
    Message,
    NonNegativeFloat,
    Percent,
    UInt32,
    WireModel,
)
from vda5050.models.common import (
    AgvPosition,
    BoundingBoxReference,
    LoadDimensions,
    Trajectory,
    Velocity,
)


class MapStatus(StrEnum):
    """Whether a stored map may be used (2.1 §6.7)."""

    ENABLED = "ENABLED"
    DISABLED = "DISABLED"


class OperatingMode(StrEnum):
    """Who controls the vehicle (§6.10.6 Table 1)."""

    AUTOMATIC = "AUTOMATIC"
    SEMIAUTOMATIC = "SEMIAUTOMATIC"
    MANUAL = "MANUAL"
    SERVICE = "SERVICE"
    TEACHIN = "TEACHIN"


class ActionStatus(StrEnum):
    """Lifecycle of an action (§6.11 Figure 16). PAUSED is missing from the official 2.1 schema
    enum but listed by the prose, which wins (digest §11 item 1)."""

    WAITING = "WAITING"
    INITIALIZING = "INITIALIZING"
    RUNNING = "RUNNING"
    PAUSED = "PAUSED"
    FINISHED = "FINISHED"
    FAILED = "FAILED"


class ErrorLevel(StrEnum):
    """WARNING resolves itself; FATAL needs a person (§6.10.5)."""

    WARNING = "WARNING"
    FATAL = "FATAL"


class InfoLevel(StrEnum):
    """Level of an information entry (§6.10.4)."""

    INFO = "INFO"
    DEBUG = "DEBUG"


class EStop(StrEnum):
    """Kind of active emergency stop (§6.10.6)."""

    AUTOACK = "AUTOACK"
    MANUAL = "MANUAL"
    REMOTE = "REMOTE"
    NONE = "NONE"


class ErrorType:
    """The errorType names this stack uses. errorType is a free string in 2.x; these follow the
    2.x prose and the 2.0 Figure 8 names (digest §11 item 6)."""

    VALIDATION = "validationError"
    ORDER = "orderError"
    ORDER_UPDATE = "orderUpdateError"
    NO_ROUTE = "noRouteError"
    NO_ORDER_TO_CANCEL = "noOrderToCancel"


class Map(WireModel):
    """A map stored on the vehicle (2.1 §6.7)."""

    map_id: str
    map_version: str
    map_description: str | None = None
    map_status: MapStatus


class NodeStatePosition(WireModel):
    """Position of a pending node, for debugging only."""

    x: float
    y: float
    theta: float | None = None
    map_id: str


class NodeState(WireModel):
    """A node still to be traversed (§6.10.6)."""

    node_id: str
    sequence_id: UInt32
    node_description: str | None = None
    released: bool
    node_position: NodeStatePosition | None = None


class EdgeState(WireModel):
    """An edge still to be traversed (§6.10.6)."""

    edge_id: str
    sequence_id: UInt32
    edge_description: str | None = None
    released: bool
    trajectory: Trajectory | None = None


class Load(WireModel):
    """A load the vehicle carries (§6.10.6)."""

    load_id: str | None = None
    load_type: str | None = None
    load_position: str | None = None
    bounding_box_reference: BoundingBoxReference | None = None
    load_dimensions: LoadDimensions | None = None
    weight: NonNegativeFloat | None = None


class ActionState(WireModel):
    """Current status of one action (§6.10.6, §6.11)."""

    action_id: str
    action_type: str | None = None
    action_description: str | None = None
    action_status: ActionStatus
    result_description: str | None = None


class BatteryState(WireModel):
    """Battery charge in %, voltage in V, reach in m (§6.10.6)."""

    battery_charge: float
    battery_voltage: float | None = None
    battery_health: Percent | None = None
    charging: bool
    reach: Annotated[float, Field(ge=0)] | None = None


class ErrorReference(WireModel):
    """Points an error at the message or element that caused it (§7.1)."""

    reference_key: str
    reference_value: str


class Error(WireModel):
    """An active error or warning (§6.10.5)."""

    error_type: str
    error_references: list[ErrorReference] | None = None
    error_description: str | None = None
    error_hint: str | None = Field(default=None, json_schema_extra=SINCE_2_1)
    error_level: ErrorLevel


class InfoReference(WireModel):
    """Reference of an information entry."""

    reference_key: str
    reference_value: str


class Info(WireModel):
    """Debug or visualisation information; master control must not base logic on it (§6.10.4)."""

    info_type: str
    info_references: list[InfoReference] | None = None
    info_description: str | None = None
    info_level: InfoLevel


class SafetyState(WireModel):
    """Emergency stop and protective field (§6.10.6)."""

    e_stop: EStop
    field_violation: bool


class State(Message):
    """The vehicle's complete status (§6.10)."""

    maps: list[Map] | None = Field(default=None, json_schema_extra=SINCE_2_1)
    order_id: str
    order_update_id: UInt32
    zone_set_id: str | None = None
    last_node_id: str
    last_node_sequence_id: UInt32
    driving: bool
    paused: bool | None = None
    new_base_request: bool | None = None
    distance_since_last_node: float | None = None
    operating_mode: OperatingMode
    node_states: list[NodeState]
    edge_states: list[EdgeState]
    agv_position: AgvPosition | None = None
    velocity: Velocity | None = None
    loads: list[Load] | None = None
    action_states: list[ActionState]
    battery_state: BatteryState
    errors: list[Error]
    information: list[Info] | None = None
    safety_state: SafetyState
