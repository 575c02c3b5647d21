"""Which edge orientations the vehicle's drive can hold (§6.6.6 ``orientation``; R34), pure.

An omnidirectional vehicle (``OMNI``) holds any orientation on an edge: it turns on the spot
before the edge or on it. A differential-drive vehicle (``DIFF``) drives along the edge, nose
first or tail first: ``orientationType`` TANGENTIAL must be 0 or pi, GLOBAL the edge's own
direction or its reverse, each within the vehicle's heading tolerance. Any other orientation
cannot be reached, "rotate before entering the edge" included, so the order is rejected (2.x:
"if that is not possible, reject the order"; 3.0 alike). An edge is the straight line between
its nodes, or its trajectory: TANGENTIAL follows the curve's tangent, GLOBAL must stay on the
axis of every leg of the sampled curve.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Literal

from vda5050.models import Edge, Order, OrientationType
from vda_vehicle.navigation import wrap
from vda_vehicle.trajectories import polyline_of

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
        off_axis = _off_axis(edge, positions)
        if off_axis is not None and off_axis > tolerance_rad:
            kind = (edge.orientation_type or OrientationType.TANGENTIAL).value
            yield OrientationProblem(
                edge.edge_id,
                f"edge {edge.edge_id!r}: orientation {edge.orientation:.3f} rad ({kind}) cannot "
                f"be held by a differential-drive vehicle, which drives along the edge "
                f"forwards or backwards ({off_axis:.3f} rad off its axis)",
            )


def _off_axis(edge: Edge, positions: dict[str, tuple[float, float]]) -> float | None:
    """How far (rad) the asked orientation lies from the axis of travel, forwards or backwards,
    at worst along the edge (None: none asked, or the edge's direction unknown)."""
    if edge.orientation is None:
        return None
    if edge.orientation_type is not OrientationType.GLOBAL:
        return _from_axis(edge.orientation)
    directions = _directions(edge, positions)
    if not directions:
        return None
    return max(_from_axis(edge.orientation - direction) for direction in directions)


def _from_axis(offset: float) -> float:
    return min(abs(wrap(offset)), abs(wrap(offset - math.pi)))


def _directions(edge: Edge, positions: dict[str, tuple[float, float]]) -> list[float]:
    """The directions of travel on ``edge``: each leg of its sampled trajectory, or the straight
    line between its nodes; none when unknown (a node without position, both nodes at one
    place, a trajectory that is no NURBS: rejected on its own)."""
    if edge.trajectory is not None:
        points: Sequence[tuple[float, float]] = polyline_of(edge.trajectory) or ()
    else:
        start, end = positions.get(edge.start_node_id), positions.get(edge.end_node_id)
        points = () if start is None or end is None else (start, end)
    return [
        math.atan2(by - ay, bx - ax)
        for (ax, ay), (bx, by) in pairwise(points)
        if (ax, ay) != (bx, by)
    ]
