"""Topic ``order``: master control → AGV (§6.6, field tables §6.6.6)."""

from __future__ import annotations

from enum import StrEnum

from pydantic import Field

from vda5050.models.base import SINCE_2_1, Angle, Message, NonNegativeFloat, UInt32, WireModel
from vda5050.models.common import Action, NodePosition, Trajectory


class OrientationType(StrEnum):
    """How ``edge.orientation`` is meant; TANGENTIAL when absent (§6.6.6)."""

    GLOBAL = "GLOBAL"
    TANGENTIAL = "TANGENTIAL"


class CorridorRefPoint(StrEnum):
    """Which part of the vehicle must stay inside a corridor (2.1 §6.6.5)."""

    KINEMATICCENTER = "KINEMATICCENTER"
    CONTOUR = "CONTOUR"


class Corridor(WireModel):
    """Bounds left and right of the trajectory the vehicle may use (2.1 §6.6.5)."""

    left_width: NonNegativeFloat
    right_width: NonNegativeFloat
    corridor_ref_point: CorridorRefPoint | None = None


class Node(WireModel):
    """A node of an order (§6.6.6)."""

    node_id: str
    sequence_id: UInt32
    node_description: str | None = None
    released: bool
    node_position: NodePosition | None = None
    actions: list[Action]


class Edge(WireModel):
    """A directed edge of an order (§6.6.6)."""

    edge_id: str
    sequence_id: UInt32
    edge_description: str | None = None
    released: bool
    start_node_id: str
    end_node_id: str
    max_speed: float | None = None
    max_height: float | None = None
    min_height: float | None = None
    orientation: Angle | None = None
    orientation_type: OrientationType | None = None
    direction: str | None = None
    rotation_allowed: bool | None = None
    max_rotation_speed: float | None = None
    trajectory: Trajectory | None = None
    length: float | None = None
    corridor: Corridor | None = Field(default=None, json_schema_extra=SINCE_2_1)
    actions: list[Action]


class Order(Message):
    """An order or order update (§6.6)."""

    order_id: str
    order_update_id: UInt32
    zone_set_id: str | None = None
    nodes: list[Node]
    edges: list[Edge]
