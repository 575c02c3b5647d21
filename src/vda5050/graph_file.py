"""The graph file both services read: nodes with positions and directed edges (architecture §3.3).

Master control plans routes on it; a simulated vehicle uses it to know where its start node is.
Unknown keys are rejected so that a typo in a hand-written graph fails at startup.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

from vda5050.models.base import CAMEL_CASE_CONFIG, Angle, NonNegativeFloat


class GraphModel(BaseModel):
    model_config = ConfigDict(**CAMEL_CASE_CONFIG, extra="forbid")


class GraphNode(GraphModel):
    """A node of the map graph; x, y in metres, theta in radians."""

    node_id: Annotated[str, Field(min_length=1)]
    x: float
    y: float
    theta: Angle | None = Field(default=None, description="orientation to reach at the node")
    map_id: str | None = Field(default=None, description="overrides the graph's mapId")
    allowed_deviation_xy: NonNegativeFloat | None = Field(
        default=None, alias="allowedDeviationXY", description="metres"
    )
    allowed_deviation_theta: Annotated[float, Field(ge=0, le=3.141592654)] | None = None
    description: str | None = None
    station_type: str | None = Field(
        default=None, description="e.g. 'charging', 'pick', 'drop', 'parking'"
    )
    station_name: str | None = None


class GraphControlPoint(GraphModel):
    """A NURBS control point (metres); weight > 0, 1.0 when absent."""

    x: float
    y: float
    weight: Annotated[float, Field(gt=0)] | None = None


class GraphTrajectory(GraphModel):
    """The path an edge is driven along, as a NURBS (VDA 5050 §6.6.6 ``trajectory``): degree 1
    when absent, knotVector the clamped uniform one when absent (3.0's defaults); the first and
    last control points are the edge's start and end node."""

    degree: Annotated[int, Field(ge=1)] | None = None
    knot_vector: list[Annotated[float, Field(ge=0, le=1)]] | None = None
    control_points: Annotated[list[GraphControlPoint], Field(min_length=2)]


class GraphCorridorRefPoint(StrEnum):
    """What must stay inside a corridor (2.1 §6.6.5)."""

    KINEMATICCENTER = "KINEMATICCENTER"
    CONTOUR = "CONTOUR"


class GraphCorridor(GraphModel):
    """How far left and right of its path (metres) a vehicle may leave an edge to get round an
    obstacle (2.1 §6.6.5); traffic control counts the edge that much wider."""

    left_width: Annotated[float, Field(ge=0)]
    right_width: Annotated[float, Field(ge=0)]
    corridor_ref_point: GraphCorridorRefPoint | None = None


class GraphOrientationType(StrEnum):
    """How an edge's ``orientation`` is read (§6.6.6): TANGENTIAL (default, 0 forwards, pi
    backwards) or GLOBAL (map frame)."""

    GLOBAL = "GLOBAL"
    TANGENTIAL = "TANGENTIAL"


class GraphEdge(GraphModel):
    """A directed edge; length in metres (default: the trajectory's length, else the
    straight-line distance), maxSpeed in m/s. The other optional fields are VDA 5050's edge
    fields (§6.6.6), sent to vehicles whose factsheet takes them."""

    edge_id: Annotated[str, Field(min_length=1)]
    start_node_id: str
    end_node_id: str
    length: Annotated[float, Field(gt=0)] | None = None
    max_speed: Annotated[float, Field(gt=0)] | None = None
    description: str | None = None
    max_height: Annotated[float, Field(ge=0)] | None = Field(
        default=None, description="m: highest vehicle, load included, the edge lets through"
    )
    min_height: Annotated[float, Field(ge=0)] | None = Field(
        default=None, description="m: lowest height of the load handling device on the edge"
    )
    orientation: Angle | None = Field(
        default=None, description="rad: the vehicle's orientation on the edge (orientationType)"
    )
    orientation_type: GraphOrientationType | None = None
    direction: str | None = Field(
        default=None, description="a line-guided vehicle's choice at a junction, e.g. 'left'"
    )
    rotation_allowed: bool | None = Field(
        default=None, description="whether the vehicle may rotate on the edge"
    )
    max_rotation_speed: Annotated[float, Field(gt=0)] | None = Field(
        default=None, description="rad/s"
    )
    trajectory: GraphTrajectory | None = None
    corridor: GraphCorridor | None = None


class GraphZoneType(StrEnum):
    """The zone types master control honours, named as VDA 5050 3.0 names them (§6.4.1)."""

    BLOCKED = "BLOCKED"
    SPEED_LIMIT = "SPEED_LIMIT"
    RELEASE = "RELEASE"


class GraphReleaseLoss(StrEnum):
    """What a robot inside a RELEASE zone does when its access is revoked or expires (3.0
    §6.4.1.1, Table 6)."""

    STOP = "STOP"
    CONTINUE = "CONTINUE"
    EVACUATE = "EVACUATE"


class GraphVertex(GraphModel):
    x: float
    y: float


class GraphZone(GraphModel):
    """An area of the floor: BLOCKED (no edge into or through it is driven), SPEED_LIMIT
    (every edge that touches it is driven at most at ``maximumSpeed``, m/s) or RELEASE (one
    vehicle at a time, entered only with master control's release; graph file only). A simple
    polygon, its vertices in map coordinates (metres)."""

    zone_id: Annotated[str, Field(min_length=1)]
    zone_type: GraphZoneType
    vertices: Annotated[list[GraphVertex], Field(min_length=3)]
    maximum_speed: Annotated[float, Field(gt=0)] | None = Field(
        default=None, description="m/s; required for SPEED_LIMIT"
    )
    release_loss_behavior: GraphReleaseLoss | None = Field(
        default=None,
        description="RELEASE only: what a robot inside does when its access is lost (STOP)",
    )
    map_id: str | None = Field(default=None, description="overrides the graph's mapId")
    description: str | None = None


class GraphFile(GraphModel):
    """Top level of a graph file."""

    map_id: Annotated[str, Field(min_length=1)]
    nodes: Annotated[list[GraphNode], Field(min_length=1)]
    edges: list[GraphEdge]
    zones: list[GraphZone] = Field(
        default_factory=list,
        description="blocked areas, speed limits and release zones (master control)",
    )
