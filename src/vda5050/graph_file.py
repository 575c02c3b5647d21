"""The graph file both services read: nodes with positions and directed edges (architecture §3.3).

Master control plans routes on it; a simulated vehicle uses it to know where its start node is.
Unknown keys are rejected so that a typo in a hand-written graph fails at startup.
"""

from __future__ import annotations

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


class GraphFile(GraphModel):
    """Top level of a graph file."""

    map_id: Annotated[str, Field(min_length=1)]
    nodes: Annotated[list[GraphNode], Field(min_length=1)]
    edges: list[GraphEdge]
