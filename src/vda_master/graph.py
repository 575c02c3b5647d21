"""The map graph master control plans on (architecture §3.3; VDA 5050 §6.6.1).

A graph file is JSON: ``{"mapId", "nodes": [...], "edges": [...]}`` (see
:class:`vda5050.graph_file.GraphFile`). Loading checks it twice: against
``schemas/graph.schema.json`` (the shape), then semantically (ids unique, every edge endpoint a
known node, no node that no edge reaches or leaves). Every error names the file and the
offending id, so a broken hand-written graph fails at startup with a message that says where.

Pure apart from :func:`load_graph`, which reads the file once at startup.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

from jsonschema.exceptions import best_match

from vda5050.errors import ConfigError
from vda5050.graph_file import GraphEdge, GraphFile, GraphNode
from vda5050.schemas import GRAPH_SCHEMA, validator


class GraphError(ConfigError):
    """A graph file that cannot be used; the message names the file and the offending id."""


@dataclass(frozen=True, slots=True)
class Graph:
    """Nodes, directed edges and the adjacency list used for routing."""

    map_id: str
    nodes: Mapping[str, GraphNode]
    edges: Mapping[str, GraphEdge]
    #: nodeId -> ids of the edges that leave it, in file order.
    outgoing: Mapping[str, tuple[str, ...]]
    source: str = "<memory>"

    def node_map_id(self, node: GraphNode) -> str:
        """The map a node lies on: its own mapId, else the graph's."""
        return node.map_id or self.map_id

    def station_nodes(self, station_type: str) -> tuple[str, ...]:
        """Ids of the nodes whose ``stationType`` is ``station_type``, in file order."""
        return tuple(n for n, node in self.nodes.items() if node.station_type == station_type)

    def edge_length(self, edge_id: str) -> float:
        """Length in metres: the file's ``length``, else the straight-line distance."""
        edge = self.edges[edge_id]
        if edge.length is not None:
            return edge.length
        start, end = self.nodes[edge.start_node_id], self.nodes[edge.end_node_id]
        return math.hypot(end.x - start.x, end.y - start.y)


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
    problems.extend(_isolated_nodes(document))
    return problems


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


def _index(document: GraphFile, source: str) -> Graph:
    outgoing: dict[str, list[str]] = {node.node_id: [] for node in document.nodes}
    for edge in document.edges:
        outgoing[edge.start_node_id].append(edge.edge_id)
    return Graph(
        map_id=document.map_id,
        nodes=MappingProxyType({node.node_id: node for node in document.nodes}),
        edges=MappingProxyType({edge.edge_id: edge for edge in document.edges}),
        outgoing=MappingProxyType({key: tuple(value) for key, value in outgoing.items()}),
        source=source,
    )


def _describe_location(raw: object, parts: list[str | int]) -> str:
    """``node '7'`` / ``edge '17'`` when the schema error lies inside one, else ``document``."""
    if len(parts) >= 2 and parts[0] in {"nodes", "edges"} and isinstance(raw, dict):  # noqa: PLR2004
        items = raw.get(parts[0])
        index = parts[1]
        if isinstance(items, list) and isinstance(index, int) and index < len(items):
            item = items[index]
            key = "nodeId" if parts[0] == "nodes" else "edgeId"
            ident = item.get(key) if isinstance(item, dict) else None
            kind = parts[0][:-1]
            return f"{kind} {ident!r}" if isinstance(ident, str) else f"{kind} #{index}"
    return "document"
