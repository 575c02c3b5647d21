"""Topic ``factsheet``: AGV → master control, retained (§6.15; 2.0 §6.16)."""

from __future__ import annotations

from enum import StrEnum

from pydantic import Field, JsonValue

from vda5050.models.base import SINCE_2_1, LenientHeaderMessage, NonNegativeFloat, WireModel
from vda5050.models.common import BlockingType, BoundingBoxReference, LoadDimensions


class AgvKinematic(StrEnum):
    DIFF = "DIFF"
    OMNI = "OMNI"
    THREEWHEEL = "THREEWHEEL"


class AgvClass(StrEnum):
    FORKLIFT = "FORKLIFT"
    CONVEYOR = "CONVEYOR"
    TUGGER = "TUGGER"
    CARRIER = "CARRIER"


class ActionScope(StrEnum):
    """Where an action may be used (§6.15 protocolFeatures.agvActions)."""

    INSTANT = "INSTANT"
    NODE = "NODE"
    EDGE = "EDGE"


class Support(StrEnum):
    SUPPORTED = "SUPPORTED"
    REQUIRED = "REQUIRED"


class ValueDataType(StrEnum):
    BOOL = "BOOL"
    NUMBER = "NUMBER"
    INTEGER = "INTEGER"
    FLOAT = "FLOAT"
    STRING = "STRING"
    OBJECT = "OBJECT"
    ARRAY = "ARRAY"


class WheelType(StrEnum):
    DRIVE = "DRIVE"
    CASTER = "CASTER"
    FIXED = "FIXED"
    MECANUM = "MECANUM"


class TypeSpecification(WireModel):
    series_name: str
    series_description: str | None = None
    agv_kinematic: AgvKinematic
    agv_class: AgvClass
    max_load_mass: NonNegativeFloat
    # The prose gives these as example values, so they stay open strings (digest §11, SOURCE.md 5).
    localization_types: list[str]
    navigation_types: list[str]


class PhysicalParameters(WireModel):
    """Speeds in m/s, accelerations in m/s², lengths in m, angular speeds in rad/s."""

    speed_min: float
    speed_max: float
    angular_speed_min: float | None = Field(default=None, json_schema_extra=SINCE_2_1)
    angular_speed_max: float | None = Field(default=None, json_schema_extra=SINCE_2_1)
    acceleration_max: float
    deceleration_max: float
    height_min: float | None = None
    height_max: float
    width: float
    length: float


class MaxStringLens(WireModel):
    msg_len: int | None = None
    topic_serial_len: int | None = None
    topic_elem_len: int | None = None
    id_len: int | None = None
    id_numerical_only: bool | None = None
    enum_len: int | None = None
    load_id_len: int | None = None


class MaxArrayLens(WireModel):
    """Array limits; the JSON keys literally contain dots (§6.15)."""

    order_nodes: int | None = Field(default=None, alias="order.nodes")
    order_edges: int | None = Field(default=None, alias="order.edges")
    node_actions: int | None = Field(default=None, alias="node.actions")
    edge_actions: int | None = Field(default=None, alias="edge.actions")
    actions_actions_parameters: int | None = Field(default=None, alias="actions.actionsParameters")
    instant_actions: int | None = Field(default=None, alias="instantActions")
    trajectory_knot_vector: int | None = Field(default=None, alias="trajectory.knotVector")
    trajectory_control_points: int | None = Field(default=None, alias="trajectory.controlPoints")
    state_node_states: int | None = Field(default=None, alias="state.nodeStates")
    state_edge_states: int | None = Field(default=None, alias="state.edgeStates")
    state_loads: int | None = Field(default=None, alias="state.loads")
    state_action_states: int | None = Field(default=None, alias="state.actionStates")
    state_errors: int | None = Field(default=None, alias="state.errors")
    state_information: int | None = Field(default=None, alias="state.information")
    error_error_references: int | None = Field(default=None, alias="error.errorReferences")
    information_info_references: int | None = Field(
        default=None, alias="information.infoReferences"
    )


class Timing(WireModel):
    """Intervals in seconds."""

    min_order_interval: float
    min_state_interval: float
    default_state_interval: float | None = None
    visualization_interval: float | None = None


class ProtocolLimits(WireModel):
    max_string_lens: MaxStringLens
    max_array_lens: MaxArrayLens
    timing: Timing


class OptionalParameter(WireModel):
    """An optional field the vehicle supports, by its full dotted path."""

    parameter: str
    support: Support
    description: str | None = None


class AgvActionParameter(WireModel):
    key: str
    value_data_type: ValueDataType
    description: str | None = None
    is_optional: bool | None = None


class AgvAction(WireModel):
    """A supported action with its scopes and parameters."""

    action_type: str
    action_description: str | None = None
    action_scopes: list[ActionScope]
    action_parameters: list[AgvActionParameter] | None = None
    result_description: str | None = None
    blocking_types: list[BlockingType] | None = Field(default=None, json_schema_extra=SINCE_2_1)


class ProtocolFeatures(WireModel):
    optional_parameters: list[OptionalParameter]
    agv_actions: list[AgvAction]


class WheelPosition(WireModel):
    x: float
    y: float
    theta: float | None = None


class WheelDefinition(WireModel):
    type: WheelType
    is_active_driven: bool
    is_active_steered: bool
    position: WheelPosition
    diameter: float
    width: float
    center_displacement: float | None = None
    constraints: str | None = None


class PolygonPoint(WireModel):
    x: float
    y: float


class Envelope2d(WireModel):
    set: str
    polygon_points: list[PolygonPoint]
    description: str | None = None


class Envelope3d(WireModel):
    set: str
    format: str
    data: dict[str, JsonValue] | None = None
    url: str | None = None
    # A string in the prose; the official 2.1 schema types it as integer by mistake.
    description: str | None = None


class AgvGeometry(WireModel):
    wheel_definitions: list[WheelDefinition] | None = None
    # Explicit aliases: the camelCase generator would write "envelopes2D", but §6.15 and the
    # official schemas spell them with a lowercase d.
    envelopes2d: list[Envelope2d] | None = Field(default=None, alias="envelopes2d")
    envelopes3d: list[Envelope3d] | None = Field(default=None, alias="envelopes3d")


class LoadSet(WireModel):
    set_name: str
    load_type: str
    load_positions: list[str] | None = None
    bounding_box_reference: BoundingBoxReference | None = None
    load_dimensions: LoadDimensions | None = None
    max_weight: float | None = None
    min_loadhandling_height: float | None = None
    max_loadhandling_height: float | None = None
    min_loadhandling_depth: float | None = None
    max_loadhandling_depth: float | None = None
    min_loadhandling_tilt: float | None = None
    max_loadhandling_tilt: float | None = None
    agv_speed_limit: float | None = None
    agv_acceleration_limit: float | None = None
    agv_deceleration_limit: float | None = None
    pick_time: float | None = None
    drop_time: float | None = None
    description: str | None = None


class LoadSpecification(WireModel):
    load_positions: list[str] | None = None
    load_sets: list[LoadSet] | None = None


class VersionInfo(WireModel):
    key: str
    value: str


class Network(WireModel):
    dns_servers: list[str] | None = None
    local_ip_address: str | None = None
    ntp_servers: list[str] | None = None
    netmask: str | None = None
    default_gateway: str | None = None


class VehicleConfig(WireModel):
    """Software/hardware versions and network settings (2.1)."""

    versions: list[VersionInfo] | None = None
    network: Network | None = None


class Factsheet(LenientHeaderMessage):
    """What this vehicle is and which parts of the protocol it supports (§6.15)."""

    type_specification: TypeSpecification
    physical_parameters: PhysicalParameters
    protocol_limits: ProtocolLimits
    protocol_features: ProtocolFeatures
    agv_geometry: AgvGeometry
    load_specification: LoadSpecification
    vehicle_config: VehicleConfig | None = Field(default=None, json_schema_extra=SINCE_2_1)

    def action(self, action_type: str) -> AgvAction | None:
        """Return the declared action ``action_type``, or None if it is not supported."""
        for action in self.protocol_features.agv_actions:
            if action.action_type == action_type:
                return action
        return None

    def supports_parameter(self, parameter: str) -> bool:
        """Tell whether the optional field ``parameter`` (dotted path) is SUPPORTED or REQUIRED."""
        return any(p.parameter == parameter for p in self.protocol_features.optional_parameters)
