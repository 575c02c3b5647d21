"""Route → VDA 5050 order (§6.6.1, §6.6.2, §6.6.6; architecture §1 "Order building").

A route is an edge sequence. Its order has the start node of the first edge, then the end node
of every edge, so ``len(edges) == len(nodes) - 1`` (R22). sequenceIds run 0, 1, 2, … alternating
node, edge, node (R25): node *i* has ``2i`` and edge *i* has ``2i + 1``, and they never change
across updates (§6.6.2). Node positions and edge fields come from the graph, filtered by the
vehicle's factsheet (R112, R113, see :mod:`vda_master.capabilities`).

:func:`plan_order` builds the whole order once, every element unreleased; :func:`build_message`
cuts one message out of it: the initial order (first node 0) or an update that starts at the
decision point (R56), with the base released up to a node index. Because every message is cut
from the same plan, the stitching node is always sent with exactly its first content (R58).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

from pydantic import JsonValue

from vda5050.graph_file import GraphEdge, GraphNode, GraphTrajectory
from vda5050.models import (
    Action,
    ActionParameter,
    ActionScope,
    ControlPoint,
    Corridor,
    CorridorRefPoint,
    Edge,
    Node,
    NodePosition,
    Order,
    OrientationType,
    Trajectory,
)
from vda5050.models.factsheet import Factsheet
from vda5050.nurbs import path_from, polyline_length, uniform_knots
from vda5050.topics import AgvId
from vda_master import capabilities as caps
from vda_master.capabilities import ActionSpec
from vda_master.graph import Graph
from vda_master.routing import Route

#: Placeholder header of a planned message; the per-vehicle stamper writes the real one when the
#: message is actually sent (§6.4).
_UNSTAMPED = "1970-01-01T00:00:00.000Z"
#: Graph station data that maps onto predefined action parameters (§6.8.1, R86).
_STATION_PARAMETERS = (("stationType", "station_type"), ("stationName", "station_name"))
T = TypeVar("T")


@dataclass(frozen=True, slots=True)
class BuildProblem:
    """Why no order can be built for this vehicle (a lowercase sentence naming the ids)."""

    reason: str


@dataclass(frozen=True, slots=True)
class OrderPlan:
    """Every node and edge of one order, all unreleased; messages are cut from it."""

    order_id: str
    agv: AgvId
    version: str
    nodes: tuple[Node, ...]
    edges: tuple[Edge, ...]
    #: The graph route the plan drives, index-aligned with ``nodes``/``edges`` (a temporary
    #: start node stands in for the route's first node, §6.6.3.1): traffic control reserves it.
    route: Route | None = None
    _action_ids: tuple[str, ...] = field(default=(), init=False, repr=False, compare=False)

    @property
    def last_index(self) -> int:
        """Index of the destination node."""
        return len(self.nodes) - 1

    @property
    def destination(self) -> str:
        """The nodeId the order ends at."""
        return self.nodes[-1].node_id

    def __post_init__(self) -> None:
        # Computed once: the dispatcher asks for them with every state of the vehicle.
        ids = tuple(a.action_id for a in all_actions(self))
        object.__setattr__(self, "_action_ids", ids)

    def action_ids(self) -> tuple[str, ...]:
        """Ids of every node and edge action, nodes first."""
        return self._action_ids


@dataclass(frozen=True, slots=True)
class PlanRequest:
    """What to plan: the route and the actions at its nodes and on its edges, by index."""

    route: Route
    order_id: str
    node_actions: Mapping[int, Sequence[ActionSpec]]
    edge_actions: Mapping[int, Sequence[ActionSpec]]


def plan_order(
    graph: Graph,
    request: PlanRequest,
    *,
    agv: AgvId,
    version: str,
    factsheet: Factsheet | None,
    action_ids: Iterator[str],
) -> OrderPlan | BuildProblem:
    """Plan the whole order for ``request.route``, or say why this vehicle cannot take it."""
    unfillable = caps.unfillable_required(factsheet)
    if unfillable:
        return BuildProblem(f"the vehicle requires fields this master cannot fill: {unfillable}")
    builder = _Builder(graph, factsheet, action_ids)
    try:
        nodes = tuple(
            builder.node(node_id, 2 * index, request.node_actions.get(index, ()))
            for index, node_id in enumerate(request.route.node_ids)
        )
        edges = tuple(
            builder.edge(edge_id, 2 * index + 1, request.edge_actions.get(index, ()))
            for index, edge_id in enumerate(request.route.edge_ids)
        )
        start = request.route.start_position
        if start is not None and edges:
            nodes, edges = builder.temporary_start(request.order_id, nodes, edges, start)
    except _ProblemError as exc:
        return BuildProblem(str(exc))
    plan = OrderPlan(request.order_id, agv, version, nodes, edges, request.route)
    problem = _limit_problem(plan, factsheet)
    return plan if problem is None else BuildProblem(problem)


def replan(
    graph: Graph,
    plan: OrderPlan,
    *,
    from_index: int,
    tail: Route,
    factsheet: Factsheet | None,
    last_actions: Sequence[Action],
) -> OrderPlan | BuildProblem:
    """``plan`` driving ``tail`` from node ``from_index`` on (a re-plan at the decision point,
    traffic control): nodes up to ``from_index`` and their sequenceIds stay as they are (the
    base never changes, R66); the tail's nodes and edges follow with continuing sequenceIds, and
    ``last_actions`` go to its last node."""
    if plan.route is None or tail.node_ids[0] != plan.route.node_ids[from_index]:
        where = None if plan.route is None else plan.route.node_ids[from_index]
        return BuildProblem(f"the new route starts at {tail.node_ids[0]!r}, not at {where!r}")
    builder = _Builder(graph, factsheet, iter(()))
    try:
        nodes = [
            builder.node(node_id, 2 * (from_index + offset), ())
            for offset, node_id in enumerate(tail.node_ids[1:], start=1)
        ]
        edges = [
            builder.edge(edge_id, 2 * (from_index + offset) + 1, ())
            for offset, edge_id in enumerate(tail.edge_ids)
        ]
    except _ProblemError as exc:
        return BuildProblem(str(exc))
    if nodes:
        nodes[-1] = nodes[-1].model_copy(update={"actions": list(last_actions)})
    head = plan.route
    route = Route(
        (*head.node_ids[: from_index + 1], *tail.node_ids[1:]),
        (*head.edge_ids[:from_index], *tail.edge_ids),
        sum(graph.edge_length(e) for e in (*head.edge_ids[:from_index], *tail.edge_ids)),
        head.start_position,
    )
    return OrderPlan(
        plan.order_id,
        plan.agv,
        plan.version,
        (*plan.nodes[: from_index + 1], *nodes),
        (*plan.edges[:from_index], *edges),
        route,
    )


def stop_actions(
    graph: Graph,
    node_id: str,
    specs: Sequence[ActionSpec],
    *,
    factsheet: Factsheet | None,
    action_ids: Iterator[str],
) -> tuple[Action, ...] | BuildProblem:
    """The node actions ``specs`` become at ``node_id`` (a stop of an order with several),
    checked and filled as :func:`plan_order` does for a destination."""
    try:
        return tuple(_Builder(graph, factsheet, action_ids).node(node_id, 0, specs).actions)
    except _ProblemError as exc:
        return BuildProblem(str(exc))


def build_message(
    plan: OrderPlan, *, first: int, release_end: int, update_id: int, max_nodes: int | None
) -> Order:
    """One order message: nodes from index ``first`` on, released up to node ``release_end``.

    ``first`` is 0 for the initial order and the decision point for an update (R56). At most
    ``max_nodes`` nodes go into the message (R114); a cut-off horizon is sent later.
    """
    last = plan.last_index if max_nodes is None else min(plan.last_index, first + max_nodes - 1)
    release_end = min(release_end, last)
    nodes = [
        node.model_copy(update={"released": True}) if index <= release_end else node
        for index, node in enumerate(plan.nodes[first : last + 1], start=first)
    ]
    edges = [
        edge.model_copy(update={"released": True}) if index < release_end else edge
        for index, edge in enumerate(plan.edges[first:last], start=first)
    ]
    return Order(
        header_id=0,
        timestamp=_UNSTAMPED,
        version=plan.version,
        manufacturer=plan.agv.manufacturer,
        serial_number=plan.agv.serial_number,
        order_id=plan.order_id,
        order_update_id=update_id,
        nodes=nodes,
        edges=edges,
    )


def all_actions(plan: OrderPlan) -> list[Action]:
    """Every node and edge action of ``plan``, nodes first."""
    return [a for n in plan.nodes for a in n.actions] + [a for e in plan.edges for a in e.actions]


class _ProblemError(Exception):
    """Internal: aborts planning with a reason that becomes a BuildProblem."""


class _Builder:
    """Turns graph elements into order elements for one vehicle."""

    def __init__(
        self, graph: Graph, factsheet: Factsheet | None, action_ids: Iterator[str]
    ) -> None:
        self.graph = graph
        self.factsheet = factsheet
        self.required = caps.required_fields(factsheet)
        self.sendable = caps.sendable_fields(factsheet)
        self.action_ids = action_ids
        #: Whether the vehicle requires a driving field (R113): every edge then needs one.
        self.required_driving = bool(self.required & _DRIVING_FIELDS)

    def wants(self, path: str) -> bool:
        return path in self.sendable

    def fill(self, path: str, value: T | None, default: T | None = None) -> T | None:
        """The value to send for optional field ``path``: None unless supported (R112); the
        default, or a problem, when REQUIRED and the graph has no value (R113)."""
        if not self.wants(path):
            return None
        if value is None and path in self.required:
            if default is None:
                raise _ProblemError(f"the vehicle requires {path} but the graph has no value")
            return default
        return value

    def node(self, node_id: str, sequence_id: int, specs: Sequence[ActionSpec]) -> Node:
        graph_node = self.graph.nodes[node_id]
        actions = [self.action(spec, ActionScope.NODE, graph_node) for spec in specs]
        return Node(
            node_id=node_id,
            sequence_id=sequence_id,
            released=False,
            node_description=self.fill(caps.NODE_DESCRIPTION, graph_node.description, node_id),
            node_position=self.position(graph_node),
            actions=actions,
        )

    def position(self, node: GraphNode) -> NodePosition | None:
        if not self.wants(caps.NODE_POSITION):
            return None
        return NodePosition(
            x=node.x,
            y=node.y,
            map_id=self.graph.node_map_id(node),
            theta=self.fill(caps.NODE_THETA, node.theta),
            allowed_deviation_xy=self.fill(caps.NODE_DEVIATION_XY, node.allowed_deviation_xy, 0.0),
            allowed_deviation_theta=self.fill(
                caps.NODE_DEVIATION_THETA, node.allowed_deviation_theta
            ),
        )

    def temporary_start(
        self,
        order_id: str,
        nodes: tuple[Node, ...],
        edges: tuple[Edge, ...],
        position: tuple[float, float],
    ) -> tuple[tuple[Node, ...], tuple[Edge, ...]]:
        """§6.6.3.1 method 1: the vehicle stands at ``position`` on the first edge. The first node
        becomes a temporary node there and the first edge leads from it to that edge's end."""
        if not self.wants(caps.NODE_POSITION):
            msg = (
                f"the vehicle stands between nodes {nodes[0].node_id!r} and {nodes[1].node_id!r} "
                "and its factsheet does not allow the nodePosition a temporary start node needs"
            )
            raise _ProblemError(msg)
        first, edge = nodes[0], edges[0]
        node_id, edge_id = self.temporary_ids(order_id, first.node_id, edge.edge_id)
        x, y = position
        map_id = self.graph.node_map_id(self.graph.nodes[first.node_id])
        temporary = first.model_copy(
            update={
                "node_id": node_id,
                "node_description": None,
                "node_position": NodePosition(x=x, y=y, map_id=map_id),
            }
        )
        rest = path_from(self.graph.edge_path(self.graph.edges[edge.edge_id]), position)
        length = polyline_length(rest) if edge.length is not None else None
        # The trajectory (if sent) from where the vehicle stands on it: the sampled rest.
        trajectory = None if edge.trajectory is None else polyline_trajectory(rest)
        leg = edge.model_copy(
            update={
                "edge_id": edge_id,
                "start_node_id": node_id,
                "length": length,
                "edge_description": None,
                "trajectory": trajectory,
            }
        )
        return (temporary, *nodes[1:]), (leg, *edges[1:])

    def temporary_ids(self, order_id: str, node_id: str, edge_id: str) -> tuple[str, str]:
        """Ids of a temporary start node and edge: readable, numeric for idNumericalOnly, and
        never a graph id."""
        numeric = bool(
            self.factsheet and self.factsheet.protocol_limits.max_string_lens.id_numerical_only
        )
        node, edge = (
            (order_id + "0", order_id + "1")
            if numeric
            else (
                f"{node_id}~here",
                f"{edge_id}~here",
            )
        )
        while node in self.graph.nodes or edge in self.graph.edges:
            node, edge = node + "0", edge + "0"
        return node, edge

    def edge(self, edge_id: str, sequence_id: int, specs: Sequence[ActionSpec]) -> Edge:
        graph_edge = self.graph.edges[edge_id]
        speed_max = None if self.factsheet is None else self.factsheet.physical_parameters.speed_max
        return Edge(
            edge_id=edge_id,
            sequence_id=sequence_id,
            released=False,
            start_node_id=graph_edge.start_node_id,
            end_node_id=graph_edge.end_node_id,
            edge_description=self.fill(caps.EDGE_DESCRIPTION, graph_edge.description, edge_id),
            max_speed=self.fill(caps.EDGE_MAX_SPEED, graph_edge.max_speed, speed_max),
            length=self.fill(caps.EDGE_LENGTH, self.graph.edge_length(edge_id)),
            actions=[self.action(spec, ActionScope.EDGE, None) for spec in specs],
            **self.driving_fields(graph_edge),
        )

    def driving_fields(self, graph_edge: GraphEdge) -> dict[str, object]:
        """The edge's other §6.6.6 fields the vehicle takes (R112), only those with a value: most
        graphs set none, and an order is built on every ``POST /orders``."""
        if not (self.required_driving or _has_driving_fields(graph_edge)):
            return {}
        start = self.graph.nodes[graph_edge.start_node_id]
        end = self.graph.nodes[graph_edge.end_node_id]
        straight = ((start.x, start.y), (end.x, end.y))
        candidates: dict[str, object] = {
            "max_height": self.fill(caps.EDGE_MAX_HEIGHT, graph_edge.max_height),
            "min_height": self.fill(caps.EDGE_MIN_HEIGHT, graph_edge.min_height),
            # REQUIRED and not in the graph: driving forwards along the edge (§6.6.6 default).
            "orientation": self.fill(caps.EDGE_ORIENTATION, graph_edge.orientation, 0.0),
            "orientation_type": self.fill(
                caps.EDGE_ORIENTATION_TYPE,
                None
                if graph_edge.orientation_type is None
                else OrientationType(graph_edge.orientation_type.value),
                OrientationType.TANGENTIAL,
            ),
            "direction": self.fill(caps.EDGE_DIRECTION, graph_edge.direction),
            "rotation_allowed": self.fill(caps.EDGE_ROTATION_ALLOWED, graph_edge.rotation_allowed),
            "max_rotation_speed": self.fill(
                caps.EDGE_MAX_ROTATION_SPEED, graph_edge.max_rotation_speed
            ),
            # REQUIRED and not in the graph: the straight line the edge is (degree 1).
            "trajectory": self.fill(
                caps.EDGE_TRAJECTORY,
                None if graph_edge.trajectory is None else wire_trajectory(graph_edge.trajectory),
                polyline_trajectory(straight),
            ),
            "corridor": self.fill(
                caps.EDGE_CORRIDOR,
                None
                if graph_edge.corridor is None
                else Corridor(
                    left_width=graph_edge.corridor.left_width,
                    right_width=graph_edge.corridor.right_width,
                    corridor_ref_point=None
                    if graph_edge.corridor.corridor_ref_point is None
                    else CorridorRefPoint(graph_edge.corridor.corridor_ref_point.value),
                ),
            ),
        }
        return {name: value for name, value in candidates.items() if value is not None}

    def action(self, spec: ActionSpec, scope: ActionScope, station: GraphNode | None) -> Action:
        spec = self.with_station_parameters(spec, station)
        resolved = caps.resolve_action(self.factsheet, spec, scope)
        if isinstance(resolved, str):
            raise _ProblemError(resolved)
        blocking, parameters = resolved
        return Action(
            action_type=spec.action_type,
            action_id=next(self.action_ids),
            blocking_type=blocking,
            action_parameters=[ActionParameter(key=k, value=v) for k, v in parameters.items()]
            or None,
        )

    def with_station_parameters(self, spec: ActionSpec, station: GraphNode | None) -> ActionSpec:
        """Add ``stationType``/``stationName`` from the graph when the vehicle declares them."""
        if station is None:
            return spec
        declared = caps.declared_parameter_keys(self.factsheet, spec.action_type)
        extra: dict[str, JsonValue] = {
            key: value
            for key, attribute in _STATION_PARAMETERS
            if key in declared
            and key not in spec.parameters
            and (value := getattr(station, attribute)) is not None
        }
        if not extra:
            return spec
        return ActionSpec(spec.action_type, spec.blocking_type, {**spec.parameters, **extra})


#: The edge fields :meth:`_Builder.driving_fields` fills.
_DRIVING_FIELDS = frozenset(
    {
        caps.EDGE_MAX_HEIGHT,
        caps.EDGE_MIN_HEIGHT,
        caps.EDGE_ORIENTATION,
        caps.EDGE_ORIENTATION_TYPE,
        caps.EDGE_DIRECTION,
        caps.EDGE_ROTATION_ALLOWED,
        caps.EDGE_MAX_ROTATION_SPEED,
        caps.EDGE_TRAJECTORY,
        caps.EDGE_CORRIDOR,
    }
)


def _has_driving_fields(edge: GraphEdge) -> bool:
    return not (
        edge.max_height is None
        and edge.min_height is None
        and edge.orientation is None
        and edge.orientation_type is None
        and edge.direction is None
        and edge.rotation_allowed is None
        and edge.max_rotation_speed is None
        and edge.trajectory is None
        and edge.corridor is None
    )


def wire_trajectory(trajectory: GraphTrajectory) -> Trajectory:
    """The graph's NURBS as sent (§6.6.6): the 3.0 defaults a graph may leave out written out,
    as 2.x requires degree and knotVector."""
    degree = trajectory.degree or 1
    count = len(trajectory.control_points)
    knots = trajectory.knot_vector or list(uniform_knots(degree, count))
    return Trajectory(
        degree=degree,
        knot_vector=knots,
        control_points=[
            ControlPoint(x=p.x, y=p.y, weight=p.weight) for p in trajectory.control_points
        ],
    )


def polyline_trajectory(points: Sequence[tuple[float, float]]) -> Trajectory:
    """A degree 1 NURBS through ``points``: exactly the polyline."""
    return Trajectory(
        degree=1,
        knot_vector=list(uniform_knots(1, len(points))),
        control_points=[ControlPoint(x=x, y=y) for x, y in points],
    )


def _limit_problem(plan: OrderPlan, factsheet: Factsheet | None) -> str | None:
    """The first protocolLimits rule the plan breaks (R114), if any."""
    max_nodes = caps.max_order_nodes(factsheet)
    if max_nodes is not None and max_nodes < 2 and plan.edges:  # noqa: PLR2004
        return f"the vehicle's order.nodes limit of {max_nodes} leaves no room for an edge"
    ids = [plan.order_id, *(n.node_id for n in plan.nodes), *(e.edge_id for e in plan.edges)]
    problems = caps.id_problems(factsheet, [*ids, *plan.action_ids()])
    actions = all_actions(plan)
    counts = {
        "node.actions": max((len(n.actions) for n in plan.nodes), default=0),
        "edge.actions": max((len(e.actions) for e in plan.edges), default=0),
        "actions.actionsParameters": max(
            (len(a.action_parameters or ()) for a in actions), default=0
        ),
    }
    trajectories = [e.trajectory for e in plan.edges if e.trajectory is not None]
    if trajectories:
        counts["trajectory.knotVector"] = max(len(t.knot_vector) for t in trajectories)
        counts["trajectory.controlPoints"] = max(len(t.control_points) for t in trajectories)
    problems += caps.array_problems(factsheet, counts)
    problems += caps.action_limit_problems(factsheet, actions)
    return problems[0] if problems else None
