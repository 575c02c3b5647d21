"""Edge trajectories at the vehicle (§6.6.6 ``trajectory`` and ``corridor``; 3.0 §7.3), pure.

Order acceptance checks each trajectory (:func:`trajectory_problems`): a NURBS
(:func:`vda5050.nurbs.build_curve`), of a degree the simulated stack follows, starting and
ending at its edge's nodes within their allowedDeviationXY. The stack drives the trajectory as
a polyline (:func:`path_of`, :mod:`vda_vehicle.navigation`).

Corridors (2.1 §6.6.5, 3.0 §6.1.5) are accepted and never used: the simulated stack follows
the trajectory (or the straight line) exactly, so it is always inside any corridor, raises no
OUTSIDE_OF_CORRIDOR and, with 3.0 ``releaseRequired``, never has to ask for an edgeRequest.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Final

from vda5050.models import Edge, NodePosition, Order, Trajectory
from vda5050.nurbs import Point, curve_of, sample

#: The highest degree the simulated stack follows: sampling costs grow with its square, and
#: path curves are of degree 2 to 5 (declared in the factsheet's optionalParameters).
MAX_DEGREE: Final = 5
#: How much farther than the node's allowed deviation a trajectory may start or end (m):
#: rounding in the control points.
END_SLACK_M: Final = 1e-3


@dataclass(frozen=True, slots=True)
class TrajectoryProblem:
    """What is wrong with an edge's trajectory. ``invalid``: no NURBS, or at odds with its
    nodes (2.x validationError); otherwise a curve this vehicle cannot follow (orderError)."""

    edge_id: str
    description: str
    invalid: bool = True


def trajectory_problems(order: Order, deviation_xy_m: float) -> Iterator[TrajectoryProblem]:
    """Every edge trajectory of ``order`` that is no NURBS, of a degree above
    :data:`MAX_DEGREE`, or starts or ends farther from its node than the node's
    allowedDeviationXY (``deviation_xy_m`` when 0 or absent, §6.6.6) plus :data:`END_SLACK_M`."""
    for index, edge in enumerate(order.edges[: len(order.nodes) - 1]):
        if edge.trajectory is None:
            continue
        curve = curve_of(edge.trajectory)
        if isinstance(curve, str):
            yield TrajectoryProblem(edge.edge_id, f"edge {edge.edge_id}'s trajectory: {curve}")
            continue
        if curve.degree > MAX_DEGREE:
            text = (
                f"edge {edge.edge_id}'s trajectory has degree {curve.degree}; this vehicle "
                f"follows degrees 1 to {MAX_DEGREE}"
            )
            yield TrajectoryProblem(edge.edge_id, text, invalid=False)
            continue
        ends = (
            ("starts", curve.start, order.nodes[index]),
            ("ends", curve.end, order.nodes[index + 1]),
        )
        for verb, (x, y), node in ends:
            position = node.node_position
            if position is None:  # rejected on its own: nodePosition is REQUIRED
                continue
            off = math.hypot(x - position.x, y - position.y)
            allowed = position.allowed_deviation_xy or deviation_xy_m
            if off > allowed + END_SLACK_M:
                text = (
                    f"edge {edge.edge_id}'s trajectory {verb} {off:.2f} m from node "
                    f"{node.node_id} (allowed: {allowed:.2f} m)"
                )
                yield TrajectoryProblem(edge.edge_id, text)


def unclamped(degree: int, knots: Sequence[float]) -> str | None:
    """3.0 §7.3: the first and the last knot each appear exactly degree + 1 times, no other
    knot more than degree times (a clamped NURBS); what breaks that, or None."""
    runs = [len(list(group)) for _, group in itertools.groupby(knots)]
    if runs[0] != degree + 1 or runs[-1] != degree + 1:
        return f"the first and last knots must each appear degree + 1 = {degree + 1} times"
    if any(count > degree for count in runs[1:-1]):
        return f"no inner knot may appear more than degree = {degree} times"
    return None


def polyline_of(trajectory: Trajectory) -> tuple[Point, ...] | None:
    """The trajectory sampled from its start to its end; None when it is no NURBS."""
    curve = curve_of(trajectory)
    return None if isinstance(curve, str) else sample(curve)


def path_of(edge: Edge, end: NodePosition) -> tuple[Point, ...] | None:
    """The stack's path along ``edge`` (:attr:`vda_vehicle.navigation.RouteEdge.path`): the
    sampled trajectory after its start, ending exactly on the end node; None without one."""
    if edge.trajectory is None:
        return None
    points = polyline_of(edge.trajectory)
    if points is None:  # rejected by decide_order
        msg = f"edge {edge.edge_id!r} has an invalid trajectory"
        raise ValueError(msg)
    return (*points[1:-1], (end.x, end.y))
