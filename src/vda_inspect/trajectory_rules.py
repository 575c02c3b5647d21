"""Edge trajectories master control sends (§6.6.6 ``trajectory``; 3.0 §7.3), pure.

Each one must be a NURBS a vehicle can follow (:func:`vda5050.nurbs.build_curve`: enough control
points for its degree, degree + 1 more knots than control points, knots in [0, 1] and not
decreasing, positive weights; in 3.0 also clamped), and where the order bounds how close the
vehicle must come to a node (a positive ``allowedDeviationXY``; 3.0: the ellipse's semi-major
axis) it starts and ends that close to its nodes: a vehicle holding its trajectory could not
reach them otherwise. Without a bound the vehicle's own tolerance applies, which a listener does
not know, so the ends are not judged then.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

from vda5050.models import Edge, NodePosition, Order, v3
from vda5050.nurbs import curve_of
from vda_vehicle.trajectories import unclamped

#: Rounding in the control points (m).
_SLACK_M = 1e-3


def trajectory_problems(order: Order | v3.Order) -> list[str]:
    """What is wrong with the order's edge trajectories, one sentence each."""
    return list(_problems(order))


def _problems(order: Order | v3.Order) -> Iterator[str]:
    edges: Sequence[Edge | v3.Edge] = order.edges
    for index, edge in enumerate(edges[: len(order.nodes) - 1]):
        trajectory = edge.trajectory
        if trajectory is None:
            continue
        curve = curve_of(trajectory)
        where = f"edge {edge.edge_id}'s trajectory"
        if isinstance(curve, str):
            yield f"{where}: {curve}"
            continue
        if isinstance(order, v3.Order) and trajectory.knot_vector is not None:
            problem = unclamped(curve.degree, curve.knots)
            if problem is not None:
                yield f"{where}: {problem} (a clamped NURBS, 3.0 §7.3)"
        ends = (
            ("starts", curve.start, order.nodes[index]),
            ("ends", curve.end, order.nodes[index + 1]),
        )
        for verb, (x, y), node in ends:
            position = node.node_position
            bound = _bound(position)
            if position is None or bound is None:
                continue
            off = math.hypot(x - position.x, y - position.y)
            if off > bound + _SLACK_M:
                yield (
                    f"{where} {verb} {off:.2f} m from node {node.node_id}, beyond its "
                    f"allowedDeviationXY of {bound:.2f} m"
                )


def _bound(position: NodePosition | v3.NodePosition | None) -> float | None:
    """How far from the node the vehicle may be, when the order says (positive)."""
    if position is None or position.allowed_deviation_xy is None:
        return None
    deviation = position.allowed_deviation_xy
    bound = deviation if isinstance(deviation, float | int) else max(deviation.a, deviation.b)
    return float(bound) if bound > 0 else None
