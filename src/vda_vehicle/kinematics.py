"""Which edge orientations the vehicle's drive can hold (§6.6.6 ``orientation``; R34), pure.

An omnidirectional vehicle (``OMNI``) holds any orientation on an edge: it turns on the spot
before the edge or on it. A differential-drive vehicle (``DIFF``) drives along the edge, nose
first or tail first: ``orientationType`` TANGENTIAL must be 0 or pi, GLOBAL the edge's own
direction or its reverse, each within the vehicle's heading tolerance. Any other orientation
cannot be reached, "rotate before entering the edge" included, so the order is rejected (2.x:
"if that is not possible, reject the order"; 3.0 alike). Edges are straight lines between
their nodes (this vehicle follows no trajectories).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

from vda5050.models import Edge, Order, OrientationType
from vda_vehicle.navigation import wrap

Kinematic = Literal["OMNI", "DIFF"]


@dataclass(frozen=True, slots=True)
class OrientationProblem:
    edge_id: str
    description: str


def unreachable_orientations(
    order: Order, kinematic: Kinematic, tolerance_rad: float
) -> Iterator[OrientationProblem]:
    """The edges of ``order`` whose ``orientation`` a vehicle of ``kinematic`` cannot hold."""
    if kinematic == "OMNI":
        return
    positions = {
        node.node_id: (node.node_position.x, node.node_position.y)
        for node in order.nodes
        if node.node_position is not None
    }
    for edge in order.edges:
        offset = _offset_from_travel(edge, positions)
        if offset is None:
            continue
        off_axis = min(abs(wrap(offset)), abs(wrap(offset - math.pi)))
        if off_axis > tolerance_rad:
            kind = (edge.orientation_type or OrientationType.TANGENTIAL).value
            yield OrientationProblem(
                edge.edge_id,
                f"edge {edge.edge_id!r}: orientation {edge.orientation:.3f} rad ({kind}) cannot "
                f"be held by a differential-drive vehicle, which drives along the edge "
                f"forwards or backwards ({off_axis:.3f} rad off its axis)",
            )


def _offset_from_travel(edge: Edge, positions: dict[str, tuple[float, float]]) -> float | None:
    """The asked orientation relative to the direction of travel (None: none asked, or the
    edge's direction unknown: a node without position, or both nodes at one place)."""
    if edge.orientation is None:
        return None
    if edge.orientation_type is not OrientationType.GLOBAL:
        return edge.orientation
    start, end = positions.get(edge.start_node_id), positions.get(edge.end_node_id)
    if start is None or end is None or start == end:
        return None
    return edge.orientation - math.atan2(end[1] - start[1], end[0] - start[0])
