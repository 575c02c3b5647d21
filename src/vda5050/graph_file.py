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


class GraphEdge(GraphModel):
    """A directed edge; length in metres (default: straight-line distance), maxSpeed in m/s."""

    edge_id: Annotated[str, Field(min_length=1)]
    start_node_id: str
    end_node_id: str
    length: Annotated[float, Field(gt=0)] | None = None
    max_speed: Annotated[float, Field(gt=0)] | None = None
    description: str | None = None


class GraphZoneType(StrEnum):
    """The zone types master control honours, named as VDA 5050 3.0 names them (§6.4.1)."""

    BLOCKED = "BLOCKED"
    SPEED_LIMIT = "SPEED_LIMIT"


class GraphVertex(GraphModel):
    x: float
    y: float


class GraphZone(GraphModel):
    """An area of the floor: BLOCKED (no edge into or through it is driven) or SPEED_LIMIT
    (every edge that touches it is driven at most at ``maximumSpeed``, m/s). A simple polygon,
    its vertices in map coordinates (metres)."""

    zone_id: Annotated[str, Field(min_length=1)]
    zone_type: GraphZoneType
    vertices: Annotated[list[GraphVertex], Field(min_length=3)]
    maximum_speed: Annotated[float, Field(gt=0)] | None = Field(
        default=None, description="m/s; required for SPEED_LIMIT"
    )
    map_id: str | None = Field(default=None, description="overrides the graph's mapId")
    description: str | None = None


class GraphFile(GraphModel):
    """Top level of a graph file."""

    map_id: Annotated[str, Field(min_length=1)]
    nodes: Annotated[list[GraphNode], Field(min_length=1)]
    edges: list[GraphEdge]
    zones: list[GraphZone] = Field(
        default_factory=list, description="blocked areas and speed limits (master control)"
    )
