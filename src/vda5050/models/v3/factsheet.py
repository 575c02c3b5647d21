"""Topic ``factsheet`` (3.0): mobile robot → fleet control, retained (§6.10, §7.10).

3.0 renames ``agvGeometry`` → ``mobileRobotGeometry``, ``vehicleConfig`` →
``mobileRobotConfiguration``, ``agvActions`` → ``mobileRobotActions``, spells the limits out
(``maxStringLens`` → ``maximumStringLengths``, ``speedMax`` → ``maximumSpeed``, ...), adds
``supportedZones``, per-action ``pauseAllowed``/``cancelAllowed`` and the ZONE scope, and makes
the header required. Kinematics, class, localization, navigation and wheel types are extensible
enums: the known values are listed as enums, the fields stay strings.
"""

from __future__ import annotations

from enum import StrEnum

from pydantic import Field, JsonValue

from vda5050.models.base import NonNegativeFloat, Percent, UInt32
from vda5050.models.factsheet import Network, OptionalParameter, Support, VersionInfo, WheelPosition
from vda5050.models.v3.base import V3Message, V3WireModel
from vda5050.models.v3.common import BlockingType, BoundingBoxReference, LoadDimensions
from vda5050.models.v3.zone_set import ZoneType

__all__ = [
    "ActionScope",
    "BatteryCharging",
    "Envelope2d",
    "Envelope3d",
    "Factsheet",
    "LoadSet",
    "LoadSpecification",
    "LocalizationType",
    "MaximumArrayLengths",
    "MaximumStringLengths",
    "MobileRobotAction",
    "MobileRobotActionParameter",
    "MobileRobotClass",
    "MobileRobotConfiguration",
    "MobileRobotGeometry",
    "MobileRobotKinematics",
    "NavigationType",
    "Network",
    "OptionalParameter",
    "PhysicalParameters",
    "ProtocolFeatures",
    "ProtocolLimits",
    "Support",
    "Timing",
    "TypeSpecification",
    "ValueDataType",
    "VersionInfo",
    "WheelDefinition",
    "WheelPosition",
    "WheelType",
]


class MobileRobotKinematics(StrEnum):
    """Known kinematics (extensible)."""

    DIFFERENTIAL = "DIFFERENTIAL"
    OMNIDIRECTIONAL = "OMNIDIRECTIONAL"
    THREE_WHEEL = "THREE_WHEEL"


class MobileRobotClass(StrEnum):
    """Known robot classes (extensible)."""

    FORKLIFT = "FORKLIFT"
    CONVEYOR = "CONVEYOR"
    TUGGER = "TUGGER"
    CARRIER = "CARRIER"


class LocalizationType(StrEnum):
    """Known localization types (extensible)."""

    NATURAL = "NATURAL"
    REFLECTOR = "REFLECTOR"
    RFID = "RFID"
    DMC = "DMC"
    SPOT = "SPOT"
    GRID = "GRID"


class NavigationType(StrEnum):
    """Known navigation types (extensible), listed by priority in the factsheet."""

    PHYSICAL_LINE_GUIDED = "PHYSICAL_LINE_GUIDED"
    VIRTUAL_LINE_GUIDED = "VIRTUAL_LINE_GUIDED"
    FREELY_NAVIGATING = "FREELY_NAVIGATING"


class WheelType(StrEnum):
    """Known wheel types (extensible)."""

    DRIVE = "DRIVE"
    CASTER = "CASTER"
    FIXED = "FIXED"
    MECANUM = "MECANUM"


class ActionScope(StrEnum):
    """Where an action may be used; 3.0 adds ZONE (zone actions)."""

    INSTANT = "INSTANT"
    NODE = "NODE"
    EDGE = "EDGE"
    ZONE = "ZONE"


class ValueDataType(StrEnum):
    """Type of an action parameter's value; 3.0 drops 2.x FLOAT."""

    BOOL = "BOOL"
    NUMBER = "NUMBER"
    INTEGER = "INTEGER"
    STRING = "STRING"
    OBJECT = "OBJECT"
    ARRAY = "ARRAY"


class TypeSpecification(V3WireModel):
    """Class and capabilities of the robot type."""

    series_name: str
    series_description: str | None = None
    mobile_robot_kinematics: str
    mobile_robot_class: str
    maximum_load_mass: NonNegativeFloat
    localization_types: list[str]
    navigation_types: list[str]
    #: The zone types the robot understands; absent or empty: none (§6.4).
    supported_zones: list[ZoneType] | None = None


class PhysicalParameters(V3WireModel):
    """Speeds in m/s, accelerations in m/s², lengths in m, angular speeds in rad/s."""

    minimum_speed: NonNegativeFloat
    maximum_speed: NonNegativeFloat
    minimum_angular_speed: NonNegativeFloat | None = None
    maximum_angular_speed: NonNegativeFloat | None = None
    maximum_acceleration: NonNegativeFloat
    maximum_deceleration: float
    minimum_height: float
    maximum_height: float
    width: float
    length: float


class MaximumStringLengths(V3WireModel):
    """String limits; absent or 0 means no explicit limit."""

    maximum_message_length: UInt32 | None = None
    maximum_topic_serial_length: UInt32 | None = None
    maximum_topic_element_length: UInt32 | None = None
    maximum_id_length: UInt32 | None = None
    id_numerical_only: bool | None = None
    maximum_load_id_length: UInt32 | None = None


class MaximumArrayLengths(V3WireModel):
    """Array limits; the JSON keys literally contain dots (§7.10 protocolLimits)."""

    order_nodes: UInt32 | None = Field(default=None, alias="order.nodes")
    order_edges: UInt32 | None = Field(default=None, alias="order.edges")
    node_actions: UInt32 | None = Field(default=None, alias="node.actions")
    edge_actions: UInt32 | None = Field(default=None, alias="edge.actions")
    actions_actions_parameters: UInt32 | None = Field(
        default=None, alias="actions.actionsParameters"
    )
    instant_actions: UInt32 | None = Field(default=None, alias="instantActions")
    trajectory_knot_vector: UInt32 | None = Field(default=None, alias="trajectory.knotVector")
    trajectory_control_points: UInt32 | None = Field(default=None, alias="trajectory.controlPoints")
    zone_set_zones: UInt32 | None = Field(default=None, alias="zoneSet.zones")
    state_node_states: UInt32 | None = Field(default=None, alias="state.nodeStates")
    state_edge_states: UInt32 | None = Field(default=None, alias="state.edgeStates")
    state_loads: UInt32 | None = Field(default=None, alias="state.loads")
    state_action_states: UInt32 | None = Field(default=None, alias="state.actionStates")
    state_instant_action_states: UInt32 | None = Field(
        default=None, alias="state.instantActionStates"
    )
    state_zone_action_states: UInt32 | None = Field(default=None, alias="state.zoneActionStates")
    state_errors: UInt32 | None = Field(default=None, alias="state.errors")
    state_information: UInt32 | None = Field(default=None, alias="state.information")
    error_error_references: UInt32 | None = Field(default=None, alias="error.errorReferences")
    information_info_references: UInt32 | None = Field(
        default=None, alias="information.infoReferences"
    )


class Timing(V3WireModel):
    """Intervals in seconds. Two states are never closer than ``minimumStateInterval``; without
    events one is sent at least every ``defaultStateInterval`` (30 s when absent, §6.6)."""

    minimum_order_interval: NonNegativeFloat
    minimum_state_interval: NonNegativeFloat
    default_state_interval: NonNegativeFloat | None = None
    visualization_interval: NonNegativeFloat | None = None


class ProtocolLimits(V3WireModel):
    """Limits of identifiers, arrays and timing the robot can handle."""

    maximum_string_lengths: MaximumStringLengths
    maximum_array_lengths: MaximumArrayLengths
    timing: Timing


class MobileRobotActionParameter(V3WireModel):
    """A parameter of a supported action."""

    key: str
    value_data_type: ValueDataType
    description: str | None = None
    is_optional: bool | None = None


class MobileRobotAction(V3WireModel):
    """A supported action: where it may be used, its parameters, whether it can be paused and
    cancelled (``cancelOrder`` waits for actions that cannot be cancelled, §6.1.3)."""

    action_type: str
    action_description: str | None = None
    action_scopes: list[ActionScope]
    action_parameters: list[MobileRobotActionParameter] | None = None
    action_result: str | None = None
    blocking_types: list[BlockingType] | None = None
    pause_allowed: bool
    cancel_allowed: bool


class ProtocolFeatures(V3WireModel):
    """Supported optional fields and actions."""

    optional_parameters: list[OptionalParameter]
    mobile_robot_actions: list[MobileRobotAction]


class WheelDefinition(V3WireModel):
    """A wheel: type (extensible), drive and steering, position and size in metres."""

    type: str
    is_active_driven: bool
    is_active_steered: bool
    position: WheelPosition
    diameter: float
    width: float
    center_displacement: float | None = None
    constraints: str | None = None


class PolygonVertex(V3WireModel):
    """A polygon corner in robot coordinates, metres."""

    x: float
    y: float


class Envelope2d(V3WireModel):
    """A 2D envelope (outline or safety field) as a closed simple polygon."""

    envelope2d_id: str = Field(alias="envelope2dId")
    vertices: list[PolygonVertex]
    description: str | None = None


class Envelope3d(V3WireModel):
    """A 3D envelope in a named format, inline or by URL."""

    envelope3d_id: str = Field(alias="envelope3dId")
    format: str
    data: dict[str, JsonValue] | None = None
    url: str | None = None
    description: str | None = None


class MobileRobotGeometry(V3WireModel):
    """Wheels and envelopes (2.x ``agvGeometry``)."""

    wheel_definitions: list[WheelDefinition] | None = None
    envelopes2d: list[Envelope2d] | None = Field(default=None, alias="envelopes2d")
    envelopes3d: list[Envelope3d] | None = Field(default=None, alias="envelopes3d")


class LoadSet(V3WireModel):
    """A load type the robot can handle, with its limits."""

    set_name: str
    load_type: str
    load_positions: list[str] | None = None
    bounding_box_reference: BoundingBoxReference | None = None
    load_dimensions: LoadDimensions | None = None
    maximum_weight: NonNegativeFloat | None = None
    minimum_loadhandling_height: NonNegativeFloat | None = None
    maximum_loadhandling_height: NonNegativeFloat | None = None
    minimum_loadhandling_depth: float | None = None
    maximum_loadhandling_depth: float | None = None
    minimum_loadhandling_tilt: float | None = None
    maximum_loadhandling_tilt: float | None = None
    maximum_speed: NonNegativeFloat | None = None
    maximum_acceleration: NonNegativeFloat | None = None
    maximum_deceleration: float | None = None
    pick_time: NonNegativeFloat | None = None
    drop_time: NonNegativeFloat | None = None
    description: str | None = None


class LoadSpecification(V3WireModel):
    """Load handling devices and load sets; no ``loadPositions``: no load handling device."""

    load_positions: list[str] | None = None
    load_sets: list[LoadSet] | None = None


class BatteryCharging(V3WireModel):
    """Charging levels in %, minimum charging time in s (new in 3.0)."""

    critical_low_charging_level: Percent | None = None
    maximum_desired_charging_level: Percent | None = None
    minimum_desired_charging_level: Percent | None = None
    # uint32 in the text, number in the schema: any non-negative number is accepted.
    minimum_charging_time: NonNegativeFloat | None = None


class MobileRobotConfiguration(V3WireModel):
    """Software/hardware versions, network settings and charging parameters (2.x
    ``vehicleConfig``)."""

    versions: list[VersionInfo] | None = None
    network: Network | None = None
    battery_charging: BatteryCharging | None = None


class Factsheet(V3Message):
    """What this robot is and which parts of the protocol it supports (§6.10, §7.10)."""

    type_specification: TypeSpecification
    physical_parameters: PhysicalParameters
    protocol_limits: ProtocolLimits
    protocol_features: ProtocolFeatures
    mobile_robot_geometry: MobileRobotGeometry
    load_specification: LoadSpecification
    mobile_robot_configuration: MobileRobotConfiguration | None = None

    def action(self, action_type: str) -> MobileRobotAction | None:
        """Return the declared action ``action_type``, or None if it is not supported."""
        for action in self.protocol_features.mobile_robot_actions:
            if action.action_type == action_type:
                return action
        return None

    def supports_parameter(self, parameter: str) -> bool:
        """Tell whether the optional field ``parameter`` (dotted path) is SUPPORTED or REQUIRED."""
        return any(p.parameter == parameter for p in self.protocol_features.optional_parameters)

    def supports_zone(self, zone_type: ZoneType) -> bool:
        """Tell whether ``supportedZones`` lists ``zone_type`` (§6.4)."""
        return zone_type in (self.type_specification.supported_zones or ())
