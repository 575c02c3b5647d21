"""The map graph master control plans on (architecture §3.3; VDA 5050 §6.6.1).

A graph file is JSON: ``{"mapId", "nodes": [...], "edges": [...], "zones": [...]}`` (see
:class:`vda5050.graph_file.GraphFile`). Loading checks it twice: against
``schemas/graph.schema.json`` (the shape), then semantically (ids unique, every edge endpoint a
known node, no node that no edge reaches or leaves, zones with what their type needs, a
trajectory that is a VDA 5050 NURBS from the edge's start node to its end node). Every
error names the file and the offending id, so a broken hand-written graph fails at startup
with a message that says where.

Zones act on the graph itself, so that routing, traffic control and the orders built from it
honour them for every vehicle, whatever its protocol version (the zone types and rules are
VDA 5050 3.0's, §6.4.1; an edge is the path it is driven along: its trajectory, else the
straight segment between its nodes):

- BLOCKED: an edge that touches the zone is not driven (left out of :attr:`Graph.edges`, kept
  in :attr:`Graph.blocked_edges`), except one that leaves it (its start inside, its end
  outside), so a vehicle found inside can drive out. Nodes inside are
  :attr:`Graph.blocked_nodes`: no route ends there and no vehicle is parked or charged there.
- SPEED_LIMIT: every edge that touches the zone gets the zone's ``maximumSpeed`` as its
  ``maxSpeed`` (the lowest of overlapping limits, and never above the file's own), so the
  limit holds from the moment any part of the edge is in the zone.

With ``zone_margin_m`` (config) a zone reaches that much beyond its polygon: a node or edge
within the margin counts as inside or touching, so a vehicle's body, not only its reference
point, keeps out of a BLOCKED zone and is slowed before it reaches a SPEED_LIMIT one.

Zones can also be added and removed while master control runs (``POST /zones``): the graph
with another set of zones is :meth:`Graph.with_zones`, indexed afresh from the same file.

Pure apart from :func:`load_graph`, which reads the file once at startup.
"""

from __future__ import annotations

import itertools
import json
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from jsonschema.exceptions import best_match

from vda5050.errors import ConfigError
from vda5050.graph_file import (
    GraphEdge,
    GraphFile,
    GraphNode,
    GraphTrajectory,
    GraphZone,
    GraphZoneType,
)
from vda5050.nurbs import Point, curve_of, polyline_length, sample
from vda5050.polygons import near, point_near, simple_polygon_problem
from vda5050.schemas import GRAPH_SCHEMA, validator


class GraphError(ConfigError):
    """A graph file that cannot be used; the message names the file and the offending id."""


#: How far (m) a trajectory may start or end from its edge's nodes (less where the node's
#: allowedDeviationXY is smaller: vehicles hold a trajectory to it).
TRAJECTORY_END_TOLERANCE_M = 0.05


@dataclass(frozen=True, slots=True)
class ClosedEdge:
    """An edge of the file that a BLOCKED zone closes."""

    edge: GraphEdge
    zone_id: str


@dataclass(frozen=True, slots=True)
class Graph:
    """Nodes, directed edges and the adjacency list used for routing."""

    map_id: str
    nodes: Mapping[str, GraphNode]
    edges: Mapping[str, GraphEdge]
    #: nodeId -> ids of the edges that leave it, in file order.
    outgoing: Mapping[str, tuple[str, ...]]
    source: str = "<memory>"
    zones: tuple[GraphZone, ...] = ()
    #: Edges a BLOCKED zone closes (not in ``edges``), by id.
    blocked_edges: Mapping[str, ClosedEdge] = field(default_factory=dict)
    #: Nodes inside a BLOCKED zone -> that zone's id.
    blocked_nodes: Mapping[str, str] = field(default_factory=dict)
    #: Edges whose maxSpeed a SPEED_LIMIT zone lowered -> that zone's id.
    limited_edges: Mapping[str, str] = field(default_factory=dict)
    #: The file as read (its own zones); None for a graph built without one.
    document: GraphFile | None = field(default=None, compare=False, repr=False)
    #: How far beyond its polygon a zone reaches (config ``zone_margin_m``).
    zone_margin_m: float = 0.0
    #: Edge id -> the points it is driven through, start node to end node: the sampled
    #: trajectory for an edge that has one (every edge of the file, closed ones too).
    curved_paths: Mapping[str, tuple[Point, ...]] = field(
        default_factory=dict, compare=False, repr=False
    )

    def node_map_id(self, node: GraphNode) -> str:
        """The map a node lies on: its own mapId, else the graph's."""
        return node.map_id or self.map_id

    def station_nodes(self, station_type: str) -> tuple[str, ...]:
        """Ids of the nodes whose ``stationType`` is ``station_type``, in file order."""
        return tuple(
            n
            for n, node in self.nodes.items()
            if node.station_type == station_type and n not in self.blocked_nodes
        )

    def node_closed(self, node_id: str) -> str | None:
        """Why ``node_id`` cannot be driven to: the BLOCKED zone it lies in (None: open)."""
        zone = self.blocked_nodes.get(node_id)
        return None if zone is None else f"node {node_id!r} lies in BLOCKED zone {zone!r}"

    def station_type_closed(self, station_type: str) -> tuple[str, bool] | None:
        """Why no node of ``station_type`` can be driven to, and whether the graph has that
        type at all (False: no node has it); None when one lies outside every BLOCKED zone."""
        if self.station_nodes(station_type):
            return None
        if any(node.station_type == station_type for node in self.nodes.values()):
            return f"every node of stationType {station_type!r} lies in a BLOCKED zone", True
        return f"no node of the graph has stationType {station_type!r}", False

    @property
    def file_zone_ids(self) -> frozenset[str]:
        """Ids of the zones the graph file itself defines (the others came at run time)."""
        document = self.document
        return frozenset(z.zone_id for z in document.zones) if document is not None else frozenset()

    @property
    def release_zones(self) -> tuple[GraphZone, ...]:
        """The RELEASE zones in force (one vehicle at a time; docs/traffic.md)."""
        return tuple(z for z in self.zones if z.zone_type is GraphZoneType.RELEASE)

    def with_zones(self, zones: Sequence[GraphZone]) -> Graph:
        """The same file with ``zones`` instead of the zones in force; raises
        :class:`GraphError` naming the zone that cannot be used (a duplicate id, a map no node
        lies on, a speed the type needs or forbids, not a simple polygon)."""
        if self.document is None:
            msg = f"graph {self.source}: built without a file, its zones cannot change"
            raise GraphError(msg)
        document = self.document.model_copy(update={"zones": list(zones)})
        problems = _zone_problems(document)
        if problems:
            raise GraphError("; ".join(problems))
        return _index(
            document,
            self.source,
            file_document=self.document,
            zone_margin_m=self.zone_margin_m,
            curved=self.curved_paths,
        )

    def with_zone_margin(self, margin_m: float) -> Graph:
        """The same zones reaching ``margin_m`` beyond their polygons (config
        ``zone_margin_m``): an edge or node that close is closed, slowed or inside."""
        if margin_m == self.zone_margin_m or self.document is None:
            return self
        document = self.document.model_copy(update={"zones": list(self.zones)})
        return _index(
            document,
            self.source,
            file_document=self.document,
            zone_margin_m=margin_m,
            curved=self.curved_paths,
        )

    def unzoned(self) -> Graph:
        """The file's nodes and every edge, no zone applied: the floor's geometry (traffic
        control's conflict sets, which zones never change)."""
        if not self.zones or self.document is None:
            return self
        return _index(
            self.document.model_copy(update={"zones": []}),
            self.source,
            file_document=None,
            curved=self.curved_paths,
        )

    def edge_length(self, edge_id: str) -> float:
        """Length in metres: the file's ``length``, else the trajectory's, else the
        straight-line distance."""
        edge = self.edges[edge_id]
        if edge.length is not None:
            return edge.length
        curved = self.curved_paths.get(edge_id)
        if curved is not None:
            return polyline_length(curved)
        start, end = self.nodes[edge.start_node_id], self.nodes[edge.end_node_id]
        return math.hypot(end.x - start.x, end.y - start.y)

    def edge_path(self, edge: GraphEdge) -> tuple[Point, ...]:
        """The points ``edge`` is driven through, from its start node to its end node: its
        trajectory sampled, else the two nodes."""
        curved = self.curved_paths.get(edge.edge_id)
        if curved is not None:
            return curved
        start, end = self.nodes[edge.start_node_id], self.nodes[edge.end_node_id]
        return ((start.x, start.y), (end.x, end.y))


def load_graph(path: Path) -> Graph:
    """Read, schema-check and semantically check the graph file at ``path``."""
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        msg = f"graph file {path}: cannot be read ({exc.strerror or exc})"
        raise GraphError(msg) from None
    except json.JSONDecodeError as exc:
        msg = f"graph file {path}: not valid JSON (line {exc.lineno} column {exc.colno})"
        raise GraphError(msg) from None
    return build_graph(raw, source=str(path))


def build_graph(raw: object, *, source: str = "<memory>") -> Graph:
    """Check a parsed graph document and index it; raises :class:`GraphError`."""
    schema_error = best_match(validator(GRAPH_SCHEMA).iter_errors(raw))
    if schema_error is not None:
        where = "".join(f"[{p!r}]" if isinstance(p, int) else f".{p}" for p in schema_error.path)
        msg = f"graph file {source}: {_describe_location(raw, list(schema_error.absolute_path))}"
        msg += f" ($ {where}): {schema_error.message}"
        raise GraphError(msg)
    document = GraphFile.model_validate(raw)
    problems = semantic_problems(document)
    if problems:
        msg = f"graph file {source}: " + "; ".join(problems)
        raise GraphError(msg)
    return _index(document, source)


def semantic_problems(document: GraphFile) -> list[str]:
    """Everything the schema cannot express: duplicate ids, unknown or isolated nodes."""
    problems = [
        f"{kind} id {item!r} is used {count} times"
        for kind, ids in (
            ("node", [n.node_id for n in document.nodes]),
            ("edge", [e.edge_id for e in document.edges]),
        )
        for item, count in Counter(ids).items()
        if count > 1
    ]
    known = {node.node_id for node in document.nodes}
    for edge in document.edges:
        problems.extend(
            f"edge {edge.edge_id!r} references unknown {end} node {node_id!r}"
            for end, node_id in (("start", edge.start_node_id), ("end", edge.end_node_id))
            if node_id not in known
        )
        if edge.start_node_id == edge.end_node_id:
            problems.append(f"edge {edge.edge_id!r} starts and ends at node {edge.start_node_id!r}")
        if (
            edge.trajectory is not None
            and edge.start_node_id in known
            and edge.end_node_id in known
        ):
            problems.extend(_trajectory_problems(edge, edge.trajectory, document))
    problems.extend(_isolated_nodes(document))
    problems.extend(_zone_problems(document))
    return problems


def _zone_problems(document: GraphFile) -> list[str]:
    """Zone ids unique, a speed for (and only for) SPEED_LIMIT, a releaseLossBehavior only for
    RELEASE, a map some node lies on, a simple polygon."""
    problems = [
        f"zone id {zone_id!r} is used {count} times"
        for zone_id, count in Counter(z.zone_id for z in document.zones).items()
        if count > 1
    ]
    maps = {node.map_id or document.map_id for node in document.nodes}
    for zone in document.zones:
        limit = zone.zone_type is GraphZoneType.SPEED_LIMIT
        if limit and zone.maximum_speed is None:
            problems.append(f"zone {zone.zone_id!r}: a SPEED_LIMIT zone needs maximumSpeed")
        if not limit and zone.maximum_speed is not None:
            problems.append(f"zone {zone.zone_id!r}: maximumSpeed applies to SPEED_LIMIT only")
        release = zone.zone_type is GraphZoneType.RELEASE
        if not release and zone.release_loss_behavior is not None:
            problems.append(
                f"zone {zone.zone_id!r}: releaseLossBehavior applies to RELEASE zones only"
            )
        if (zone.map_id or document.map_id) not in maps:
            problems.append(f"zone {zone.zone_id!r}: no node lies on its map {zone.map_id!r}")
        shape = simple_polygon_problem(zone.vertices)
        if shape is not None:
            problems.append(f"zone {zone.zone_id!r}: {shape}; a zone is a simple polygon")
    return problems


def _trajectory_problems(
    edge: GraphEdge, trajectory: GraphTrajectory, document: GraphFile
) -> list[str]:
    """A curve VDA 5050 allows, starting and ending at the edge's nodes."""
    curve = curve_of(trajectory)
    if isinstance(curve, str):
        return [f"edge {edge.edge_id!r}: trajectory: {curve}"]
    nodes = {node.node_id: node for node in document.nodes}
    problems = []
    for end, node_id, point in (
        ("starts", edge.start_node_id, curve.start),
        ("ends", edge.end_node_id, curve.end),
    ):
        node = nodes[node_id]
        gap = math.hypot(point[0] - node.x, point[1] - node.y)
        # A vehicle takes the node's own deviation as the bound (0 or none: its default).
        tolerance = min(TRAJECTORY_END_TOLERANCE_M, node.allowed_deviation_xy or math.inf)
        if gap > tolerance:
            problems.append(
                f"edge {edge.edge_id!r}: trajectory {end} at ({point[0]:.3f}, {point[1]:.3f}), "
                f"{gap:.2f} m from node {node_id!r} at ({node.x}, {node.y})"
            )
    return problems


def _curved_paths(
    document: GraphFile, nodes: Mapping[str, GraphNode]
) -> dict[str, tuple[Point, ...]]:
    """Each edge with a trajectory -> its sampled points, ending exactly on its nodes."""
    paths = {}
    for edge in document.edges:
        if edge.trajectory is None:
            continue
        curve = curve_of(edge.trajectory)
        if isinstance(curve, str):  # refused when the file was loaded
            continue
        start, end = nodes[edge.start_node_id], nodes[edge.end_node_id]
        points = sample(curve)
        paths[edge.edge_id] = ((start.x, start.y), *points[1:-1], (end.x, end.y))
    return paths


def _isolated_nodes(document: GraphFile) -> list[str]:
    """Nodes no edge touches: no route can ever reach or leave them."""
    if len(document.nodes) < 2:  # noqa: PLR2004 - a one-node graph needs no edges
        return []
    touched = {e.start_node_id for e in document.edges} | {e.end_node_id for e in document.edges}
    return [
        f"node {node.node_id!r} is unreachable: no edge starts or ends there"
        for node in document.nodes
        if node.node_id not in touched
    ]


def _index(
    document: GraphFile,
    source: str,
    *,
    file_document: GraphFile | None = None,
    zone_margin_m: float = 0.0,
    curved: Mapping[str, tuple[Point, ...]] | None = None,
) -> Graph:
    """``file_document``: the file as read, when ``document`` carries other zones;
    ``curved``: the file's sampled trajectories, when an index of the same file has them
    (zones never change the edges)."""
    nodes = {node.node_id: node for node in document.nodes}
    if curved is None:
        curved = _curved_paths(document, nodes)
    zoning = _Zoning(document, nodes, zone_margin_m, curved)
    edges = {}
    for edge in document.edges:
        if edge.edge_id not in zoning.blocked_edges:
            edges[edge.edge_id] = zoning.limited(edge)
    outgoing: dict[str, list[str]] = {node.node_id: [] for node in document.nodes}
    for edge in edges.values():
        outgoing[edge.start_node_id].append(edge.edge_id)
    return Graph(
        map_id=document.map_id,
        nodes=MappingProxyType(nodes),
        edges=MappingProxyType(edges),
        outgoing=MappingProxyType({key: tuple(value) for key, value in outgoing.items()}),
        source=source,
        zones=tuple(document.zones),
        blocked_edges=MappingProxyType(zoning.blocked_edges),
        blocked_nodes=MappingProxyType(zoning.blocked_nodes),
        limited_edges=MappingProxyType(zoning.limited_edges),
        document=file_document or document,
        zone_margin_m=zone_margin_m,
        curved_paths=MappingProxyType(dict(curved)),
    )


class _Zoning:
    """What the graph file's zones do to its nodes and edges (see the module docstring); with a
    ``margin`` (metres), a zone reaches that much farther: a node or edge that close counts as
    inside or touching."""

    def __init__(
        self,
        document: GraphFile,
        nodes: Mapping[str, GraphNode],
        margin: float = 0.0,
        curved: Mapping[str, tuple[Point, ...]] | None = None,
    ) -> None:
        self._map_id = document.map_id
        self._margin = margin
        self._limits: dict[str, tuple[float, str]] = {}
        self.blocked_nodes: dict[str, str] = {}
        self.blocked_edges: dict[str, ClosedEdge] = {}
        self.limited_edges: dict[str, str] = {}
        for zone in document.zones:
            zone_map = zone.map_id or document.map_id
            if zone.zone_type is GraphZoneType.BLOCKED:
                for node_id, node in nodes.items():
                    if self._on(node) == zone_map and self._covers(zone, node):
                        self.blocked_nodes.setdefault(node_id, zone.zone_id)
            for edge in document.edges:
                start, end = nodes[edge.start_node_id], nodes[edge.end_node_id]
                path = (curved or {}).get(edge.edge_id) or ((start.x, start.y), (end.x, end.y))
                if self._on(start) == zone_map and any(
                    near(zone.vertices, a, b, margin) for a, b in itertools.pairwise(path)
                ):
                    self._apply(zone, edge, start, end)

    def _covers(self, zone: GraphZone, node: GraphNode) -> bool:
        return point_near(zone.vertices, (node.x, node.y), self._margin)

    def _apply(self, zone: GraphZone, edge: GraphEdge, start: GraphNode, end: GraphNode) -> None:
        """``zone`` touches ``edge``."""
        if zone.zone_type is GraphZoneType.BLOCKED:
            if not (self._covers(zone, start) and not self._covers(zone, end)):  # leaving it
                self.blocked_edges.setdefault(edge.edge_id, ClosedEdge(edge, zone.zone_id))
        elif zone.maximum_speed is not None:
            self._limit(edge.edge_id, zone.maximum_speed, zone.zone_id)

    def _on(self, node: GraphNode) -> str:
        return node.map_id or self._map_id

    def _limit(self, edge_id: str, speed: float, zone_id: str) -> None:
        known = self._limits.get(edge_id)
        if known is None or speed < known[0]:
            self._limits[edge_id] = (speed, zone_id)

    def limited(self, edge: GraphEdge) -> GraphEdge:
        """``edge`` with the lowest limit of the zones it touches, if below its own."""
        limit = self._limits.get(edge.edge_id)
        if limit is None or (edge.max_speed is not None and edge.max_speed <= limit[0]):
            return edge
        self.limited_edges[edge.edge_id] = limit[1]
        return edge.model_copy(update={"max_speed": limit[0]})


#: The id key of each list of the graph file, to name an item in an error.
_ID_KEYS = {"nodes": "nodeId", "edges": "edgeId", "zones": "zoneId"}


def _describe_location(raw: object, parts: list[str | int]) -> str:
    """``node '7'`` / ``edge '17'`` / ``zone 'z'`` when the schema error lies inside one, else
    ``document``."""
    if len(parts) >= 2 and parts[0] in _ID_KEYS and isinstance(raw, dict):  # noqa: PLR2004
        items = raw.get(parts[0])
        index = parts[1]
        if isinstance(items, list) and isinstance(index, int) and index < len(items):
            item = items[index]
            key = _ID_KEYS[str(parts[0])]
            ident = item.get(key) if isinstance(item, dict) else None
            kind = parts[0][:-1]
            return f"{kind} {ident!r}" if isinstance(ident, str) else f"{kind} #{index}"
    return "document"
