"""Pydantic v2 wire models of every VDA 5050 2.0.0/2.1.0 message, one module per topic.

The 3.0.0 models live in the subpackage :mod:`vda5050.models.v3` (``from vda5050.models import
v3``; ``v3.Order``, ``v3.State``, ...).
"""

from vda5050.models import v3
from vda5050.models.base import UINT32_MAX, LenientHeaderMessage, Message, WireModel
from vda5050.models.common import (
    Action,
    ActionParameter,
    AgvPosition,
    BlockingType,
    ControlPoint,
    NodePosition,
    Trajectory,
    Velocity,
)
from vda5050.models.connection import Connection, ConnectionState
from vda5050.models.factsheet import ActionScope, AgvAction, Factsheet
from vda5050.models.instant_actions import InstantActions
from vda5050.models.order import Corridor, CorridorRefPoint, Edge, Node, Order, OrientationType
from vda5050.models.state import (
    ActionState,
    ActionStatus,
    BatteryState,
    EdgeState,
    Error,
    ErrorLevel,
    ErrorReference,
    ErrorType,
    EStop,
    Info,
    Load,
    Map,
    MapStatus,
    NodeState,
    OperatingMode,
    SafetyState,
    State,
)
from vda5050.models.visualization import Visualization

__all__ = [
    "UINT32_MAX",
    "Action",
    "ActionParameter",
    "ActionScope",
    "ActionState",
    "ActionStatus",
    "AgvAction",
    "AgvPosition",
    "BatteryState",
    "BlockingType",
    "Connection",
    "ConnectionState",
    "ControlPoint",
    "Corridor",
    "CorridorRefPoint",
    "EStop",
    "Edge",
    "EdgeState",
    "Error",
    "ErrorLevel",
    "ErrorReference",
    "ErrorType",
    "Factsheet",
    "Info",
    "InstantActions",
    "LenientHeaderMessage",
    "Load",
    "Map",
    "MapStatus",
    "Message",
    "Node",
    "NodePosition",
    "NodeState",
    "OperatingMode",
    "Order",
    "OrientationType",
    "SafetyState",
    "State",
    "Trajectory",
    "Velocity",
    "Visualization",
    "WireModel",
    "v3",
]
