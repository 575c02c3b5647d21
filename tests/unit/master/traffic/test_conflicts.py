"""Conflict sets from geometry: nodes, edges, opposite edges, safety distance (issue 9 §1)."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vda_master.testing import make_factsheet
from vda_master.traffic.conflicts import (
    FALLBACK_SAFETY_DISTANCE_M,
    build_conflicts,
    default_safety_distance_m,
    edge,
    node,
)
from vda_master.traffic.geometry import segment_distance
from vda_master.traffic.testing import make_graph


def test_every_resource_conflicts_with_itself() -> None:
    """A node and an edge each conflict with themselves, so no two vehicles share one."""
    graph = make_graph({"a": (0, 0), "b": (10, 0)}, one_way=[("a", "b")])
    conflicts = build_conflicts(graph, 1.0)
    assert conflicts.conflict(node("a"), node("a"))
    assert conflicts.conflict(edge("a-b"), edge("a-b"))


def test_nodes_conflict_only_below_the_safety_distance() -> None:
    """Two nodes 1.6 m apart conflict at a 1.7 m safety distance, 1.8 m apart they do not."""
    graph = make_graph(
        {"a": (0, 0), "near": (1.6, 0), "far": (0, 1.8), "x": (20, 20)},
        one_way=[("a", "x"), ("near", "x"), ("far", "x")],
    )
    conflicts = build_conflicts(graph, 1.7)
    assert conflicts.conflict(node("a"), node("near"))
    assert not conflicts.conflict(node("a"), node("far"))


def test_node_conflicts_with_an_edge_passing_close_by() -> None:
    """A node 1 m beside the middle of an edge conflicts with it; 3 m away it does not."""
    graph = make_graph(
        {"a": (0, 0), "b": (10, 0), "side": (5, 1), "away": (5, 3)},
        one_way=[("a", "b"), ("side", "away")],
    )
    conflicts = build_conflicts(graph, 1.5)
    assert conflicts.conflict(node("side"), edge("a-b"))
    assert not conflicts.conflict(node("away"), edge("a-b"))
    assert conflicts.conflict(node("a"), edge("a-b"))  # its own end point


def test_crossing_edges_conflict_far_from_any_node() -> None:
    """Two edges that cross in the middle conflict although all four nodes are far apart."""
    graph = make_graph(
        {"w": (0, 5), "e": (10, 5), "s": (5, 0), "n": (5, 10)},
        one_way=[("w", "e"), ("s", "n")],
    )
    conflicts = build_conflicts(graph, 1.0)
    assert conflicts.conflict(edge("w-e"), edge("s-n"))
    assert not conflicts.conflict(node("w"), node("s"))


@pytest.mark.parametrize(("gap_m", "expected"), [(1.65, True), (1.75, False)])
def test_parallel_lanes_conflict_only_closer_than_the_safety_distance(
    gap_m: float, expected: bool
) -> None:
    """Two parallel lanes just below the safety distance (1.7 m) conflict, just above do not."""
    graph = make_graph(
        {"a": (0, 0), "b": (10, 0), "c": (10, gap_m), "d": (0, gap_m)},
        one_way=[("a", "b"), ("c", "d")],
    )
    conflicts = build_conflicts(graph, 1.7)
    assert conflicts.conflict(edge("a-b"), edge("c-d")) is expected
    assert conflicts.is_one_lane("a-b") is False


def test_opposite_edges_share_one_lane() -> None:
    """A→B and B→A conflict and are one-lane; a one-way edge is not."""
    graph = make_graph(
        {"a": (0, 0), "b": (10, 0), "c": (20, 0)}, two_way=[("a", "b")], one_way=[("b", "c")]
    )
    conflicts = build_conflicts(graph, 0.1)
    assert conflicts.conflict(edge("a-b"), edge("b-a"))
    assert conflicts.is_one_lane("a-b")
    assert conflicts.is_one_lane("b-a")
    assert not conflicts.is_one_lane("b-c")
    assert conflicts.opposite["a-b"] == "b-a"


def test_resources_on_different_maps_never_conflict() -> None:
    """Nodes at the same coordinates on two maps (two floors) do not conflict."""
    graph = make_graph(
        {"a": (0, 0), "b": (5, 0), "a2": (0, 0), "b2": (5, 0)},
        one_way=[("a", "b"), ("a2", "b2")],
        map_of={"a2": "floor2", "b2": "floor2"},
    )
    conflicts = build_conflicts(graph, 2.0)
    assert not conflicts.conflict(node("a"), node("a2"))
    assert not conflicts.conflict(edge("a-b"), edge("a2-b2"))


def test_safety_distance_comes_from_the_largest_footprint() -> None:
    """Default: the largest footprint diagonal plus the margin; 1.0 m without factsheets."""
    sheet = make_factsheet()  # 1.2 m long, 0.8 m wide
    assert default_safety_distance_m([sheet, None], margin_m=0.25) == pytest.approx(
        math.hypot(1.2, 0.8) + 0.25
    )
    assert default_safety_distance_m([None]) == FALLBACK_SAFETY_DISTANCE_M
    assert default_safety_distance_m([]) == 1.0


def test_non_positive_safety_distance_is_refused() -> None:
    """A zero safety distance is a configuration error."""
    graph = make_graph({"a": (0, 0), "b": (1, 0)}, one_way=[("a", "b")])
    with pytest.raises(ValueError, match="positive"):
        build_conflicts(graph, 0.0)


coordinates = st.integers(min_value=0, max_value=12).map(float)


@st.composite
def random_graphs(draw: st.DrawFn) -> tuple[dict[str, tuple[float, float]], list[tuple[str, str]]]:
    count = draw(st.integers(min_value=2, max_value=9))
    positions = {f"n{i}": (draw(coordinates), draw(coordinates)) for i in range(count)}
    names = sorted(positions)
    pairs = draw(st.lists(st.tuples(st.sampled_from(names), st.sampled_from(names)), max_size=14))
    edges = sorted({(a, b) for a, b in pairs if a != b})
    touched = {n for pair in edges for n in pair}
    edges += [(n, names[0] if n != names[0] else names[1]) for n in names if n not in touched]
    return positions, sorted(set(edges))


@settings(max_examples=60, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(random_graphs(), st.sampled_from([0.5, 1.0, 1.69, 3.0]))
def test_grid_search_finds_exactly_the_close_pairs(
    drawn: tuple[dict[str, tuple[float, float]], list[tuple[str, str]]], safety: float
) -> None:
    """The grid-bucketed conflict sets equal a brute-force comparison of every pair."""
    positions, pairs = drawn
    graph = make_graph(positions, one_way=pairs)
    conflicts = build_conflicts(graph, safety)
    shapes = {node(n): (p, p) for n, p in positions.items()}
    shapes |= {edge(f"{a}-{b}"): (positions[a], positions[b]) for a, b in pairs}
    ends = {edge(f"{a}-{b}"): (a, b) for a, b in pairs}
    for first, shape in shapes.items():
        for second, other in shapes.items():
            opposite = first in ends and second in ends and ends[first] == ends[second][::-1]
            expected = first == second or opposite or segment_distance(shape, other) < safety
            assert conflicts.conflict(first, second) is expected, (first, second)


def test_thousands_of_elements_get_exactly_their_neighbours() -> None:
    """A 25 × 25 grid of two-way lanes (over 3,000 resources): each node conflicts with exactly
    the edges that touch it (speed: benchmarks/traffic_planner.py)."""
    size = 25
    positions = {f"n{i}_{j}": (3.0 * i, 3.0 * j) for i in range(size) for j in range(size)}
    lanes = [(f"n{i}_{j}", f"n{i + 1}_{j}") for i in range(size - 1) for j in range(size)]
    lanes += [(f"n{i}_{j}", f"n{i}_{j + 1}") for i in range(size) for j in range(size - 1)]
    graph = make_graph(positions, two_way=lanes)
    conflicts = build_conflicts(graph, 1.69)
    assert len(conflicts) == len(graph.nodes) + len(graph.edges) > 3000
    assert conflicts[node("n5_5")] == {
        node("n5_5"),
        *(edge(f"n5_5-{o}") for o in ("n4_5", "n6_5", "n5_4", "n5_6")),
        *(edge(f"{o}-n5_5") for o in ("n4_5", "n6_5", "n5_4", "n5_6")),
    }
