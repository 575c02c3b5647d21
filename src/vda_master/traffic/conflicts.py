"""Resources of the floor and which of them conflict, from the graph's geometry (issue 9 §1).

Every node and every edge of the graph is a *resource*. Two resources conflict when some point of
one is closer than ``safety_distance_m`` to some point of the other: node to node (point
distance), node to edge (point to segment), edge to edge (segment to segment). An edge is the
path it is driven along: the straight segment between its nodes, or its trajectory's polyline
(:meth:`vda_master.graph.Graph.edge_path`); an edge with a ``corridor`` reaches the wider of
its two widths beyond that path (2.1 §6.6.5: a corridor widens the area a vehicle may use, and
traffic control has to allow for it). On top of the
geometry, an edge always conflicts with its opposite edge (A→B and B→A share one lane), every
resource conflicts with itself, and every resource from which a vehicle reaches into a RELEASE
zone conflicts with every other such resource of that zone (one vehicle at a time, 3.0 §6.4.1.1;
docs/traffic.md, *Release zones*). Resources on different maps never conflict.

The conflict sets are computed once per graph load (:func:`build_conflicts`). Candidate pairs come
from a uniform grid: each shape is entered into every cell its bounding box, grown by half the
safety distance on each side, overlaps; two shapes closer than the safety distance have
overlapping grown boxes and so share a cell. Only pairs sharing a cell are measured exactly.

Safety distance from footprints (:func:`default_safety_distance_m`): a vehicle whose
reference point lies on a resource it holds covers at most the circle of radius
``r = √(length² + width²) / 2`` (its footprint's circumscribed circle). Two vehicles on
non-conflicting resources are at least ``d`` apart, so their footprints keep a gap of
``d − r₁ − r₂ ≥ d − 2·r_max``. The default is therefore ``d = max diagonal + margin`` over the
fleet's factsheets (``physicalParameters`` length and width), the margin covering localisation
and path deviation; 1.0 m when no footprint is known.
"""

from __future__ import annotations

import itertools
import math
import statistics
from collections import defaultdict
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from itertools import combinations
from types import MappingProxyType
from typing import NamedTuple

from vda5050.graph_file import GraphEdge, GraphZone
from vda5050.models.factsheet import Factsheet
from vda5050.polygons import near
from vda_master.graph import Graph
from vda_master.traffic.geometry import (
    Point,
    Segment,
    point_distance,
    point_segment_distance,
    segment_distance,
)

#: Safety distance (metres) when no vehicle declares its footprint (issue 9 §1).
FALLBACK_SAFETY_DISTANCE_M = 1.0
#: Added to the largest footprint diagonal: localisation error and deviation from the edge line.
DEFAULT_SAFETY_MARGIN_M = 0.25


class ResourceKind(StrEnum):
    """What a resource is on the graph."""

    NODE = "node"
    EDGE = "edge"


class Resource(NamedTuple):
    """A node or an edge of the graph, the unit of reservation.

    A named tuple rather than a frozen dataclass: resources are hashed in every inner loop of the
    release gate and the planner, and tuple hashing is several times cheaper.
    """

    kind: ResourceKind
    id: str

    def __str__(self) -> str:
        return f"{self.kind.value}:{self.id}"


def node(node_id: str) -> Resource:
    """The resource of node ``node_id``."""
    return Resource(ResourceKind.NODE, node_id)


def edge(edge_id: str) -> Resource:
    """The resource of edge ``edge_id``."""
    return Resource(ResourceKind.EDGE, edge_id)


@dataclass(frozen=True, slots=True)
class ConflictMap:
    """Resource → every resource it conflicts with (itself included); immutable."""

    safety_distance_m: float
    conflicts: Mapping[Resource, frozenset[Resource]]
    #: Edge id → id of its opposite edge (same end nodes, other direction), where one exists.
    opposite: Mapping[str, str]
    #: The same sets as tuples in a fixed order (the resource itself, then nodes, then edges, by
    #: id), so that "the first conflict" is deterministic and names a node where it can.
    ordered: Mapping[Resource, tuple[Resource, ...]]
    #: Nodes an edge that is not one-lane starts or ends on (the lanes' nodes, crossings too).
    lane_nodes: frozenset[str]
    #: RELEASE zone id → the resources a vehicle on them reaches into the zone with (they all
    #: conflict with each other: one vehicle in the zone at a time, 3.0 §6.4.1.1).
    release_zones: Mapping[str, frozenset[Resource]] = field(
        default_factory=lambda: MappingProxyType({})
    )
    #: The nodes of those resources: a base never ends on one unless the route does.
    release_nodes: frozenset[str] = frozenset()

    def __getitem__(self, resource: Resource) -> frozenset[Resource]:
        """The resources ``resource`` conflicts with; raises KeyError for an unknown one."""
        return self.conflicts[resource]

    def __contains__(self, resource: object) -> bool:
        return resource in self.conflicts

    def __iter__(self) -> Iterator[Resource]:
        return iter(self.conflicts)

    def __len__(self) -> int:
        return len(self.conflicts)

    def conflict(self, a: Resource, b: Resource) -> bool:
        """Whether ``a`` and ``b`` may not be held by two different vehicles at once."""
        return b in self.conflicts[a]

    def is_one_lane(self, edge_id: str) -> bool:
        """A one-lane edge: its opposite edge exists, so traffic both ways shares one lane."""
        return edge_id in self.opposite

    def closure(self, resources: Iterable[Resource]) -> frozenset[Resource]:
        """Every resource that conflicts with at least one of ``resources``."""
        found: set[Resource] = set()
        for resource in resources:
            found |= self.conflicts[resource]
        return frozenset(found)


def resources_within(
    graph: Graph, point: Point, map_id: str, distance_m: float
) -> frozenset[Resource]:
    """Every node and edge of map ``map_id`` closer than ``distance_m`` to ``point``: what a
    vehicle standing there off the graph's nodes covers, in the sense of the conflict sets
    (O(graph); asked only for such vehicles)."""
    found = [
        node(graph_node.node_id)
        for graph_node in graph.nodes.values()
        if graph.node_map_id(graph_node) == map_id
        and point_distance(point, (graph_node.x, graph_node.y)) < distance_m
    ]
    for graph_edge in graph.edges.values():
        start = graph.nodes[graph_edge.start_node_id]
        if graph.node_map_id(start) != map_id:
            continue
        reach = _reach(graph_edge)
        if any(
            point_segment_distance(point, segment) - reach < distance_m
            for segment in itertools.pairwise(graph.edge_path(graph_edge))
        ):
            found.append(edge(graph_edge.edge_id))
    return frozenset(found)


def default_safety_distance_m(
    factsheets: Iterable[Factsheet | None],
    *,
    margin_m: float = DEFAULT_SAFETY_MARGIN_M,
    fallback_m: float = FALLBACK_SAFETY_DISTANCE_M,
) -> float:
    """The default safety distance for a fleet: largest footprint diagonal plus ``margin_m``.

    See the module docstring for the reasoning; ``fallback_m`` when no factsheet is known.
    """
    diagonals = [
        math.hypot(sheet.physical_parameters.length, sheet.physical_parameters.width)
        for sheet in factsheets
        if sheet is not None
    ]
    return max(diagonals) + margin_m if diagonals else fallback_m


#: min x, min y, max x, max y
Box = tuple[float, float, float, float]


@dataclass(frozen=True, slots=True)
class _Item:
    resource: Resource
    #: A node is the degenerate segment from its point to itself; an edge its path's segments.
    shape: tuple[Segment, ...]
    #: How far beyond the shape the resource reaches (an edge's corridor), metres.
    reach: float
    #: The shape's bounding box grown by ``reach``.
    box: Box


def build_conflicts(
    graph: Graph, safety_distance_m: float, release_zones: Iterable[GraphZone] = ()
) -> ConflictMap:
    """Conflict sets of every node and edge of ``graph`` for ``safety_distance_m`` (> 0); the
    resources that reach into each of ``release_zones`` (RELEASE zones) all conflict."""
    if safety_distance_m <= 0 or not math.isfinite(safety_distance_m):
        msg = f"safety_distance_m must be a positive number, got {safety_distance_m}"
        raise ValueError(msg)
    conflicts: dict[Resource, set[Resource]] = {}
    by_map: dict[str, list[_Item]] = defaultdict(list)
    for item_map, item in _items(graph):
        by_map[item_map].append(item)
        conflicts[item.resource] = {item.resource}
    for items in by_map.values():
        for a, b in _close_pairs(items, safety_distance_m):
            conflicts[a].add(b)
            conflicts[b].add(a)
    opposite = _opposites(graph)
    for edge_id, other in opposite.items():
        conflicts[edge(edge_id)].add(edge(other))
    groups = {
        zone.zone_id: _reaching_into(
            zone, by_map.get(zone.map_id or graph.map_id, []), safety_distance_m
        )
        for zone in release_zones
    }
    for group in groups.values():
        for resource in group:
            conflicts[resource] |= group
    return ConflictMap(
        safety_distance_m,
        MappingProxyType({key: frozenset(value) for key, value in conflicts.items()}),
        MappingProxyType(opposite),
        MappingProxyType(
            {
                key: (key, *sorted(value - {key}, key=_nodes_first))
                for key, value in conflicts.items()
            }
        ),
        frozenset(
            node_id
            for graph_edge in graph.edges.values()
            if graph_edge.edge_id not in opposite
            for node_id in (graph_edge.start_node_id, graph_edge.end_node_id)
        ),
        MappingProxyType(groups),
        frozenset(r.id for group in groups.values() for r in group if r.kind is ResourceKind.NODE),
    )


def _reaching_into(
    zone: GraphZone, items: list[_Item], safety_distance_m: float
) -> frozenset[Resource]:
    """The resources of ``items`` from which a vehicle's contour may reach into ``zone``: their
    shape comes within half the safety distance of it (a footprint's circumscribed radius and
    half the margin, see :func:`default_safety_distance_m`), plus an edge's corridor."""
    found = []
    for item in items:
        margin = safety_distance_m / 2 + item.reach
        if any(near(zone.vertices, a, b, margin) for a, b in item.shape):
            found.append(item.resource)
    return frozenset(found)


def _nodes_first(resource: Resource) -> tuple[bool, str]:
    return resource.kind != ResourceKind.NODE, resource.id


def _items(graph: Graph) -> Iterator[tuple[str, _Item]]:
    """Each resource with its map and shape; an edge lies on the map of its start node."""
    for graph_node in graph.nodes.values():
        point = (graph_node.x, graph_node.y)
        item = _Item(node(graph_node.node_id), ((point, point),), 0.0, (*point, *point))
        yield graph.node_map_id(graph_node), item
    for graph_edge in graph.edges.values():
        start = graph.nodes[graph_edge.start_node_id]
        path = graph.edge_path(graph_edge)
        reach = _reach(graph_edge)
        xs, ys = [x for x, _ in path], [y for _, y in path]
        box = (min(xs) - reach, min(ys) - reach, max(xs) + reach, max(ys) + reach)
        shape = tuple(itertools.pairwise(path))
        yield graph.node_map_id(start), _Item(edge(graph_edge.edge_id), shape, reach, box)


def _reach(graph_edge: GraphEdge) -> float:
    """How far beyond its path a vehicle may leave ``graph_edge``: its corridor's wider side."""
    corridor = graph_edge.corridor
    return 0.0 if corridor is None else max(corridor.left_width, corridor.right_width)


def _shape_distance(a: _Item, b: _Item) -> float:
    """The gap between two resources' shapes, each grown by its reach."""
    gap = min(segment_distance(s, t) for s in a.shape for t in b.shape)
    return gap - a.reach - b.reach


def _close_pairs(items: list[_Item], distance: float) -> Iterator[tuple[Resource, Resource]]:
    """Pairs of distinct items closer than ``distance``, each pair once."""
    cell = _cell_size(items, distance)
    grid: dict[tuple[int, int], list[int]] = defaultdict(list)
    grow = distance / 2
    for index, item in enumerate(items):
        x0, y0, x1, y1 = item.box
        for cx in range(math.floor((x0 - grow) / cell), math.floor((x1 + grow) / cell) + 1):
            for cy in range(math.floor((y0 - grow) / cell), math.floor((y1 + grow) / cell) + 1):
                grid[cx, cy].append(index)
    seen: set[tuple[int, int]] = set()
    for members in grid.values():
        for i, j in combinations(members, 2):
            if (i, j) in seen:
                continue
            seen.add((i, j))
            a, b = items[i], items[j]
            if _boxes_apart(a.box, b.box, distance):
                continue
            if _shape_distance(a, b) < distance:
                yield a.resource, b.resource


def _boxes_apart(a: Box, b: Box, distance: float) -> bool:
    """Bounding boxes at least ``distance`` apart along x or y: the shapes are too."""
    return (
        a[0] - b[2] >= distance
        or b[0] - a[2] >= distance
        or a[1] - b[3] >= distance
        or b[1] - a[3] >= distance
    )


def _cell_size(items: list[_Item], distance: float) -> float:
    """Grid cell edge: at least the safety distance, and about one typical edge long, so that a
    long edge spans few cells and a cell holds few shapes."""
    extents = [max(i.box[2] - i.box[0], i.box[3] - i.box[1]) for i in items]
    typical = statistics.median(e for e in extents if e > 0) if any(extents) else 0.0
    return max(distance, typical, 1e-6)


def _opposites(graph: Graph) -> dict[str, str]:
    """Edge id → the first (file order) edge running between the same nodes the other way."""
    by_ends: dict[tuple[str, str], str] = {}
    for graph_edge in graph.edges.values():
        by_ends.setdefault((graph_edge.start_node_id, graph_edge.end_node_id), graph_edge.edge_id)
    return {
        graph_edge.edge_id: other
        for graph_edge in graph.edges.values()
        if (other := by_ends.get((graph_edge.end_node_id, graph_edge.start_node_id))) is not None
    }
