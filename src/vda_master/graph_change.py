"""Orders planned on an earlier graph (pure): the graph file changed between two runs of master
control (a BLOCKED zone added, an edge taken out), and an order recovered from the store drives
a way the graph no longer has (docs/master.md, Zones).

Nothing is released onto such a way. Where the closed part is still unreleased, the order is
re-routed from the end of its released base (the base never changes, R66); where the vehicle
may already drive it, or no other way leads to the destination, master control cancels the
order (the vehicle stops at its next node, §6.6.3) and it ends FAILED, saying why.
"""

from __future__ import annotations

from dataclasses import dataclass

from vda_master.graph import Graph
from vda_master.routing import Route


@dataclass(frozen=True, slots=True)
class ClosedWay:
    """The first edge of a route, from some index on, that the graph no longer has."""

    #: Index of that edge in ``route.edge_ids`` (the node before it has the same index).
    index: int
    edge_id: str
    #: In words, for logs and the order's reason.
    why: str


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


def usable_prefix(graph: Graph, route: Route, way: ClosedWay) -> Route:
    """``route`` up to the node before its closed ``way``: what the vehicle may still hold."""
    edges = route.edge_ids[: way.index]
    return Route(
        node_ids=route.node_ids[: way.index + 1],
        edge_ids=edges,
        length_m=sum(graph.edge_length(e) for e in edges),
        start_position=route.start_position,
    )
