"""Graph file loading: schema and semantic checks, adjacency, edge lengths (architecture §3.3)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from vda_master.graph import GraphError, build_graph, load_graph
from vda_master.testing import demo_graph


def _doc(nodes: list[dict[str, object]], edges: list[dict[str, object]]) -> dict[str, object]:
    return {"mapId": "m", "nodes": nodes, "edges": edges}


def _node(node_id: str, x: float = 0.0, y: float = 0.0) -> dict[str, object]:
    return {"nodeId": node_id, "x": x, "y": y}


def _edge(edge_id: str, start: str, end: str) -> dict[str, object]:
    return {"edgeId": edge_id, "startNodeId": start, "endNodeId": end}


def test_demo_graph_contains_the_reference_route() -> None:
    """The shipped demo holds node 7 -17-> 1 -12-> 2 -11-> 10."""
    graph = demo_graph()
    chain = [(graph.edges[e].start_node_id, graph.edges[e].end_node_id) for e in ("17", "12", "11")]
    assert chain == [("7", "1"), ("1", "2"), ("2", "10")]


def test_demo_graph_has_stations_and_a_sensible_size() -> None:
    """The demo is a small warehouse (15–30 nodes) with charging, pick and drop stations."""
    graph = demo_graph()
    stations = {n.station_type for n in graph.nodes.values()}
    assert 15 <= len(graph.nodes) <= 30
    assert {"charging", "pick", "drop"} <= stations


def test_demo_graph_aisles_are_bidirectional() -> None:
    """Every edge of the demo has a reverse edge, so two robots can pass in both directions."""
    graph = demo_graph()
    pairs = {(e.start_node_id, e.end_node_id) for e in graph.edges.values()}
    assert all((end, start) in pairs for start, end in pairs)


def test_adjacency_lists_outgoing_edges() -> None:
    """The adjacency list holds the ids of the edges leaving each node."""
    graph = demo_graph()
    assert "17" in graph.outgoing["7"]
    assert all(graph.edges[e].start_node_id == "7" for e in graph.outgoing["7"])


def test_edge_length_defaults_to_straight_line_distance() -> None:
    """An edge without length is as long as the straight line between its nodes."""
    graph = build_graph(_doc([_node("a"), _node("b", 3, 4)], [_edge("e", "a", "b")]))
    assert math.isclose(graph.edge_length("e"), 5.0)


def test_explicit_edge_length_wins() -> None:
    """An edge's length from the file is used as is (e.g. a curve longer than the chord)."""
    edge = {**_edge("e", "a", "b"), "length": 7.5}
    graph = build_graph(_doc([_node("a"), _node("b", 3, 4)], [edge]))
    assert graph.edge_length("e") == 7.5


def test_unknown_edge_endpoint_is_named() -> None:
    """An edge that references a missing node fails with both ids in the message."""
    with pytest.raises(GraphError, match=r"edge 'e' references unknown end node 'zz'"):
        build_graph(_doc([_node("a"), _node("b")], [_edge("e", "a", "zz"), _edge("f", "b", "a")]))


def test_duplicate_node_id_is_named() -> None:
    """Two nodes with the same id fail, naming the id."""
    with pytest.raises(GraphError, match=r"node id 'a' is used 2 times"):
        build_graph(_doc([_node("a"), _node("a")], [_edge("e", "a", "a")]))


def test_duplicate_edge_id_is_named() -> None:
    """Two edges with the same id fail, naming the id."""
    with pytest.raises(GraphError, match=r"edge id 'e' is used 2 times"):
        build_graph(_doc([_node("a"), _node("b")], [_edge("e", "a", "b"), _edge("e", "b", "a")]))


def test_isolated_node_is_unreachable() -> None:
    """A node no edge touches fails as unreachable."""
    with pytest.raises(GraphError, match=r"node 'c' is unreachable"):
        build_graph(_doc([_node("a"), _node("b"), _node("c")], [_edge("e", "a", "b")]))


def test_self_loop_edge_is_rejected() -> None:
    """An edge from a node to itself is a mistake and fails, naming it."""
    with pytest.raises(GraphError, match=r"edge 'e' starts and ends at node 'a'"):
        build_graph(_doc([_node("a"), _node("b")], [_edge("e", "a", "a"), _edge("f", "a", "b")]))


def test_schema_error_names_the_element_and_file(tmp_path: Path) -> None:
    """A schema violation names the file and the node it lies in."""
    path = tmp_path / "g.json"
    bad = _doc([_node("a"), {"nodeId": "b", "x": "far", "y": 0}], [_edge("e", "a", "b")])
    path.write_text(json.dumps(bad), encoding="utf-8")
    with pytest.raises(GraphError, match=rf"{path}.*node 'b'.*'far' is not of type 'number'"):
        load_graph(path)


def test_unknown_key_is_rejected() -> None:
    """A typo in a key fails instead of being ignored."""
    with pytest.raises(GraphError, match=r"node 'a'.*'maxSped'"):
        build_graph(_doc([{**_node("a"), "maxSped": 1}], []))


def test_invalid_json_names_the_file(tmp_path: Path) -> None:
    """A file that is not JSON fails with its path and the position of the error."""
    path = tmp_path / "broken.json"
    path.write_text("{", encoding="utf-8")
    with pytest.raises(GraphError, match=r"broken\.json: not valid JSON"):
        load_graph(path)


def test_missing_file_names_the_file(tmp_path: Path) -> None:
    """A missing file fails with its path."""
    with pytest.raises(GraphError, match=r"missing\.json: cannot be read"):
        load_graph(tmp_path / "missing.json")
