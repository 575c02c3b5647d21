"""Orders planned on an earlier graph (pure): the graph file changed between two runs of master
control (a BLOCKED zone added, an edge taken out), or a zone was added or removed while it runs
(``POST /zones``), and an order drives a way the graph no longer has (docs/master.md, Zones).

Nothing is released onto such a way. Where the closed part is still unreleased, the order is
re-routed from the end of its released base (the base never changes, R66); where the vehicle
may already drive it, or no other way leads to the destination, or the destination itself now
lies in a BLOCKED zone, master control cancels the order (the vehicle stops at its next node,
§6.6.3) and it ends FAILED, saying why. An order whose unreleased edges now have another speed
limit is re-planned on the same way, so that its next releases carry the new ``maxSpeed``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from vda5050.models import Factsheet
from vda_master import stops
from vda_master.graph import Graph
from vda_master.order_builder import OrderPlan, replan
from vda_master.routing import Route, RouteProblem


@dataclass(frozen=True, slots=True)
class ClosedWay:
    """The first edge of a route, from some index on, that the graph no longer has."""

    #: Index of that edge in ``route.edge_ids`` (the node before it has the same index).
    index: int
    edge_id: str
    #: In words, for logs and the order's reason.
    why: str


@dataclass(frozen=True, slots=True)
class Rerouted:
    """The order goes on by ``plan``, round the closed way (``why``)."""

    plan: OrderPlan
    why: str


@dataclass(frozen=True, slots=True)
class Stop:
    """The order is to be cancelled on the vehicle and end FAILED with ``reason``."""

    reason: str


def closed_way(graph: Graph, route: Route, from_index: int = 0) -> ClosedWay | None:
    """The first edge of ``route`` at or after ``from_index`` that ``graph`` no longer drives."""
    for index in range(max(0, from_index), len(route.edge_ids)):
        edge_id = route.edge_ids[index]
        if edge_id in graph.edges and route.node_ids[index + 1] in graph.nodes:
            continue
        closed = graph.blocked_edges.get(edge_id)
        if closed is not None:
            why = f"edge {edge_id!r} enters BLOCKED zone {closed.zone_id!r}"
        else:
            why = f"edge {edge_id!r} is no longer in the graph"
        return ClosedWay(index, edge_id, why)
    return None


def holdable(
    graph: Graph, route: Route, released_end: int, from_index: int = 0
) -> tuple[Route, int, ClosedWay | None]:
    """What traffic control may hold of ``route`` released up to ``released_end``: all of it,
    or the part before its first closed edge at or after ``from_index`` (with that edge)."""
    way = closed_way(graph, route, from_index)
    if way is None:
        return route, released_end, None
    edges = route.edge_ids[: way.index]
    prefix = Route(
        node_ids=route.node_ids[: way.index + 1],
        edge_ids=edges,
        length_m=sum(graph.edge_length(e) for e in edges),
        start_position=route.start_position,
    )
    return prefix, min(released_end, way.index), way


def speed_changed(old: Graph, new: Graph, route: Route, released_end: int) -> bool:
    """Whether an edge of ``route`` beyond its released base (node ``released_end``) has another
    maxSpeed on ``new`` than on ``old`` (a SPEED_LIMIT zone added or removed)."""
    for edge_id in route.edge_ids[released_end:]:
        before, after = old.edges.get(edge_id), new.edges.get(edge_id)
        if before is not None and after is not None and before.max_speed != after.max_speed:
            return True
    return False


def around_closed_way(
    graph: Graph,
    plan: OrderPlan,
    *,
    released_end: int,
    progress: int,
    cancelling: bool,
    tail_for: Callable[[str, str], Route | RouteProblem],
    factsheet: Factsheet | None,
    resume_to: str | None = None,
    onward: Sequence[stops.Stop] = (),
    first_onward: int = 2,
) -> Rerouted | Stop | None:
    """What becomes of an order whose way from node ``progress`` on the graph no longer has
    (None: it has none, or the vehicle has passed it). ``tail_for(start, destination)`` is the
    route to look for (time-aware with traffic control); ``resume_to``: where an order that
    backs off goes on to afterwards (stopped too once a BLOCKED zone holds it); ``onward``:
    the stops still to come (numbered from ``first_onward``), each of which must stay open."""
    route = plan.route
    if route is None:
        return None
    way = closed_way(graph, route, progress)
    blocked = _blocked_goal(graph, resume_to, None if way is None else route.destination)
    if blocked is not None:
        return Stop(
            f"master control stopped it: its destination {blocked[0]!r} lies in BLOCKED zone "
            f"{blocked[1]!r} (the graph changed since the order was planned)"
        )
    closed = stops.closed_stop(graph, onward, first_onward)
    if closed is not None:
        return Stop(f"master control stopped it: {closed}")
    if way is None:
        return None
    destination = route.destination
    if way.index >= released_end and not cancelling:
        tail = tail_for(route.node_ids[released_end], destination)
        if not isinstance(tail, RouteProblem):
            new = replan(
                graph,
                plan,
                from_index=released_end,
                tail=tail,
                factsheet=factsheet,
                last_actions=tuple(plan.nodes[-1].actions),
            )
            if isinstance(new, OrderPlan):
                return Rerouted(new, way.why)
    return Stop(
        f"master control stopped it: its way is closed ({way.why}, graph changed since the "
        f"order was planned) and no other way leads to {destination!r} from where it may stop"
    )


def _blocked_goal(graph: Graph, *goals: str | None) -> tuple[str, str] | None:
    """The first of ``goals`` inside a BLOCKED zone, with the zone's id."""
    for goal in goals:
        zone_id = None if goal is None else graph.blocked_nodes.get(goal)
        if goal is not None and zone_id is not None:
            return goal, zone_id
    return None
