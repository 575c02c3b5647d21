"""Pydantic v2 wire models of every VDA 5050 3.0.0 message, one module per topic.

Use them as a namespace beside the 2.x models::

    from vda5050.models import v3

    order = v3.Order.model_validate_json(payload, strict=True)

Objects whose wire shape did not change (``ActionParameter``, ``Velocity``,
``BoundingBoxReference``, ``ErrorReference``, ...) are the 2.x classes, re-exported here.
"""

from vda5050.models.v3.base import VERSION, V3Message, V3WireModel
from vda5050.models.v3.common import (
    Action,
    ActionParameter,
    BlockingType,
    BoundingBoxReference,
    ControlPoint,
    IntermediatePath,
    Load,
    LoadDimensions,
    MobileRobotPosition,
    PlannedPath,
    Trajectory,
    Velocity,
    Waypoint,
)
from vda5050.models.v3.connection import Connection, ConnectionState
from vda5050.models.v3.errors import (
    PREDEFINED_ERROR_LEVELS,
    Error,
    ErrorLevel,
    ErrorReference,
    ErrorType,
    Translation,
    predefined_error,
)
from vda5050.models.v3.factsheet import (
    ActionScope,
    Factsheet,
    MobileRobotAction,
    MobileRobotActionParameter,
    MobileRobotClass,
    MobileRobotKinematics,
    NavigationType,
)
from vda5050.models.v3.instant_actions import InstantAction, InstantActions
from vda5050.models.v3.modes import MODE_RULES, ModeRules, OperatingMode
from vda5050.models.v3.order import (
    AllowedDeviationXY,
    Corridor,
    CorridorReferencePoint,
    CorridorReleaseLossBehavior,
    Edge,
    Node,
    NodePosition,
    Order,
    OrientationType,
)
from vda5050.models.v3.responses import GrantType, Response, Responses
from vda5050.models.v3.state import (
    ACTION_TRANSITIONS,
    FINAL_ACTION_STATUSES,
    ActionState,
    ActionStatus,
    EdgeRequest,
    EdgeRequestType,
    EdgeState,
    EmergencyStop,
    Info,
    InfoLevel,
    Map,
    MapStatus,
    NodeState,
    PowerSupply,
    RequestStatus,
    SafetyState,
    State,
    StoredZoneSet,
    ZoneRequest,
    ZoneRequestType,
    ZoneSetStatus,
    may_transition,
)
from vda5050.models.v3.visualization import Visualization
from vda5050.models.v3.zone_set import (
    CONTOUR_BASED_ZONES,
    ZONE_PARAMETERS,
    Vertex,
    Zone,
    ZoneAction,
    ZoneReleaseLossBehavior,
    ZoneSet,
    ZoneSetMessage,
    ZoneType,
)

#: Every 3.0 message model.
AnyMessage = (
    Order
    | InstantActions
    | State
    | Visualization
    | Connection
    | Factsheet
    | ZoneSetMessage
    | Responses
)

__all__ = [
    "ACTION_TRANSITIONS",
    "CONTOUR_BASED_ZONES",
    "FINAL_ACTION_STATUSES",
    "MODE_RULES",
    "PREDEFINED_ERROR_LEVELS",
    "VERSION",
    "ZONE_PARAMETERS",
    "Action",
    "ActionParameter",
    "ActionScope",
    "ActionState",
    "ActionStatus",
    "AllowedDeviationXY",
    "AnyMessage",
    "BlockingType",
    "BoundingBoxReference",
    "Connection",
    "ConnectionState",
    "ControlPoint",
    "Corridor",
    "CorridorReferencePoint",
    "CorridorReleaseLossBehavior",
    "Edge",
    "EdgeRequest",
    "EdgeRequestType",
    "EdgeState",
    "EmergencyStop",
    "Error",
    "ErrorLevel",
    "ErrorReference",
    "ErrorType",
    "Factsheet",
    "GrantType",
    "Info",
    "InfoLevel",
    "InstantAction",
    "InstantActions",
    "IntermediatePath",
    "Load",
    "LoadDimensions",
    "Map",
    "MapStatus",
    "MobileRobotAction",
    "MobileRobotActionParameter",
    "MobileRobotClass",
    "MobileRobotKinematics",
    "MobileRobotPosition",
    "ModeRules",
    "NavigationType",
    "Node",
    "NodePosition",
    "NodeState",
    "OperatingMode",
    "Order",
    "OrientationType",
    "PlannedPath",
    "PowerSupply",
    "RequestStatus",
    "Response",
    "Responses",
    "SafetyState",
    "State",
    "StoredZoneSet",
    "Trajectory",
    "Translation",
    "V3Message",
    "V3WireModel",
    "Velocity",
    "Vertex",
    "Visualization",
    "Waypoint",
    "Zone",
    "ZoneAction",
    "ZoneReleaseLossBehavior",
    "ZoneRequest",
    "ZoneRequestType",
    "ZoneSet",
    "ZoneSetMessage",
    "ZoneSetStatus",
    "ZoneType",
    "may_transition",
    "predefined_error",
]
