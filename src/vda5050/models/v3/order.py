"""Topic ``order`` (3.0): fleet control → mobile robot (§6.1, field tables §7.3).

Changes from 2.x: edges no longer name their start and end nodes (the sequenceIds do: edge n
joins nodes n-1 and n+1, §6.1.1); ``allowedDeviationXY`` is an ellipse; ``maxSpeed`` /
``maxHeight`` / ``minHeight`` / ``rotationAllowed`` / ``maxRotationSpeed`` become
``maximumSpeed`` / ``maximumMobileRobotHeight`` / ``minimumLoadHandlingDeviceHeight`` /
``reachOrientationBeforeEntering`` / ``maximumRotationSpeed``; ``*Description`` becomes
``*Descriptor`` (except ``orderDescription``); the order has no ``zoneSetId`` any more.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated

from pydantic import AliasChoices, Field

from vda5050.models.base import Angle, NonNegativeFloat, UInt32
from vda5050.models.order import OrientationType
from vda5050.models.v3.base import V3Message, V3WireModel
from vda5050.models.v3.common import Action, Trajectory

__all__ = [
    "AllowedDeviationXY",
    "Corridor",
    "CorridorReferencePoint",
    "CorridorReleaseLossBehavior",
    "Edge",
    "Node",
    "NodePosition",
    "Order",
    "OrientationType",
]

# The official schema bounds the ellipse rotation to ±π/2 (enough for any ellipse); the text
# gives no range, so the schema's applies.
_HALF_PI_BOUND = 1.570796327
_TOLERANCE_M = 1e-9


class AllowedDeviationXY(V3WireModel):
    """How close the robot's control point must come to a node: an ellipse centred on the node
    (§6.6.2.1, §7.3). ``a`` is the semi-major and ``b`` the semi-minor axis in metres, ``theta``
    the angle from the map's x axis to the major axis. a = b = 0 means "as exactly as the robot
    can"; a robot that supports the field assumes 0 when it is absent."""

    a: NonNegativeFloat
    b: NonNegativeFloat
    theta: Annotated[float, Field(ge=-_HALF_PI_BOUND, le=_HALF_PI_BOUND)]

    def contains(self, dx: float, dy: float) -> bool:
        """Tell whether the offset (``dx``, ``dy``) in metres from the node, in map axes, lies
        inside or on the ellipse. A zero axis degenerates to a segment (or to the node itself)."""
        cos, sin = math.cos(self.theta), math.sin(self.theta)
        along = dx * cos + dy * sin  # offset along the major axis
        across = -dx * sin + dy * cos  # offset along the minor axis
        return (
            _within(along, self.a)
            and _within(across, self.b)
            and (
                self.a <= _TOLERANCE_M
                or self.b <= _TOLERANCE_M
                or (along / self.a) ** 2 + (across / self.b) ** 2 <= 1 + _TOLERANCE_M
            )
        )


def _within(offset: float, half_axis: float) -> bool:
    return abs(offset) <= half_axis + _TOLERANCE_M


class NodePosition(V3WireModel):
    """Where a node is, on which map, and how precisely it must be reached (§7.3)."""

    x: float
    y: float
    theta: Angle | None = None
    allowed_deviation_xy: AllowedDeviationXY | None = Field(
        default=None, alias="allowedDeviationXY"
    )
    allowed_deviation_theta: Annotated[float, Field(ge=0, le=3.141592654)] | None = None
    map_id: str


class Node(V3WireModel):
    """A node of an order (§7.3 ``node``)."""

    node_id: str
    sequence_id: UInt32
    node_descriptor: str | None = None
    released: bool
    node_position: NodePosition | None = None
    actions: list[Action]


class CorridorReferencePoint(StrEnum):
    """Which part of the robot must stay inside a corridor; KINEMATIC_CENTER when absent."""

    KINEMATIC_CENTER = "KINEMATIC_CENTER"
    CONTOUR = "CONTOUR"


class CorridorReleaseLossBehavior(StrEnum):
    """What the robot does when the release of a corridor expires or is revoked; STOP when
    absent (§7.3 ``corridor``, §6.6.10)."""

    STOP = "STOP"
    RETURN = "RETURN"


class Corridor(V3WireModel):
    """Bounds left and right of the trajectory the robot may use to avoid obstacles (§6.1.5)."""

    left_width: NonNegativeFloat
    right_width: NonNegativeFloat
    corridor_reference_point: CorridorReferencePoint | None = None
    #: true: the robot asks fleet control (edgeRequest) before leaving the trajectory (§6.6.10).
    release_required: bool | None = None
    release_loss_behavior: CorridorReleaseLossBehavior | None = None


class Edge(V3WireModel):
    """A directed edge of an order (§7.3 ``edge``). It joins the nodes whose sequenceIds are one
    below and one above its own (§6.1.1); 3.0 edges carry no start or end node ids."""

    edge_id: str
    sequence_id: UInt32
    edge_descriptor: str | None = None
    released: bool
    maximum_speed: float | None = None
    maximum_mobile_robot_height: float | None = None
    minimum_load_handling_device_height: float | None = None
    orientation: Angle | None = None
    orientation_type: OrientationType | None = None
    direction: str | None = None
    #: Omnidirectional robots only: reach ``orientation`` before entering the edge (default
    #: false). Replaces 2.x ``rotationAllowed`` with the opposite sense.
    reach_orientation_before_entering: bool | None = None
    # The text (§7.3) names this field maximumRotationSpeed, the official 3.0 schema
    # maxRotationSpeed. The text wins, so that name is sent; the schema's is accepted on input so
    # a schema-generated fleet control is not silently ignored (§7.1.1: never ignore a field).
    maximum_rotation_speed: float | None = Field(
        default=None,
        validation_alias=AliasChoices("maximumRotationSpeed", "maxRotationSpeed"),
        serialization_alias="maximumRotationSpeed",
    )
    trajectory: Trajectory | None = None
    length: float | None = None
    corridor: Corridor | None = None
    actions: list[Action]


class Order(V3Message):
    """An order or order update (§6.1, §7.3)."""

    order_id: str
    order_update_id: UInt32
    order_description: str | None = None
    nodes: list[Node]
    edges: list[Edge]

    def base(self) -> tuple[list[Node], list[Edge]]:
        """The released nodes and edges (the base, §6.1.2)."""
        return [n for n in self.nodes if n.released], [e for e in self.edges if e.released]

    def decision_point(self) -> Node | None:
        """The last released node, where the robot stops without an update (§6.1.2)."""
        released = [node for node in self.nodes if node.released]
        return released[-1] if released else None
