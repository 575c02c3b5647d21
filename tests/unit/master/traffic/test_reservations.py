"""The reservation table and its invariant: never two holders of conflicting resources."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vda5050.topics import AgvId
from vda_master.graph import Graph
from vda_master.traffic.conflicts import ConflictMap, Resource, build_conflicts, edge, node
from vda_master.traffic.reservations import Refused, ReservationTable
from vda_master.traffic.testing import agv, make_graph

R1, R2, R3 = agv("r1"), agv("r2"), agv("r3")


def _line() -> ReservationTable:
    """a - b - c - d, 3 m apart, two-way; safety 1.7 m."""
    graph = make_graph(
        {"a": (0, 0), "b": (3, 0), "c": (6, 0), "d": (9, 0)},
        two_way=[("a", "b"), ("b", "c"), ("c", "d")],
    )
    return ReservationTable(build_conflicts(graph, 1.7))


def test_claim_of_free_resources_succeeds() -> None:
    """A vehicle claims free resources and then holds them."""
    table = _line().claim(R1, [node("a"), edge("a-b"), node("b")])
    assert isinstance(table, ReservationTable)
    assert table.held_by(R1) == {node("a"), edge("a-b"), node("b")}
    assert table.holder(edge("a-b")) == R1


def test_claim_of_a_conflicting_resource_is_refused() -> None:
    """A resource conflicting with another vehicle's holding is refused, naming both."""
    table = _line().claim(R1, [node("b")])
    assert isinstance(table, ReservationTable)
    refused = table.claim(R2, [node("c"), edge("b-c")])
    assert refused == Refused(edge("b-c"), node("b"), R1)
    assert table.held_by(R2) == frozenset()
    assert table.is_free(R2, [node("c")])
    assert table.is_free(R1, [edge("b-c")])  # its own holdings never block it
    assert table.blockers(R2, [edge("a-b"), edge("b-c")]) == {R1}


def test_release_frees_for_others() -> None:
    """Released resources can be claimed by another vehicle."""
    table = _line().claim(R1, [node("b"), edge("b-c"), node("c")])
    assert isinstance(table, ReservationTable)
    table = table.release(R1, [node("b"), edge("b-c"), node("d")])
    assert table.held_by(R1) == {node("c")}
    assert isinstance(table.claim(R2, [node("a"), edge("a-b")]), ReservationTable)


def test_replace_swaps_holdings_only_when_free() -> None:
    """Replace sets exactly the new holdings, or is refused and changes nothing."""
    table = _line().claim(R1, [node("a")])
    assert isinstance(table, ReservationTable)
    table = table.claim(R2, [node("d")])
    assert isinstance(table, ReservationTable)
    moved = table.replace(R1, [node("b")])
    assert isinstance(moved, ReservationTable)
    assert moved.held_by(R1) == {node("b")}
    assert moved.holder(node("a")) is None
    assert isinstance(moved.replace(R1, [edge("c-d")]), Refused)
    emptied = moved.replace(R1, [])
    assert isinstance(emptied, ReservationTable)
    assert dict(emptied.vehicles()) == {R2: {node("d")}}


# -- the invariant, on random graphs, fleets and operation sequences -------------------------


@st.composite
def random_setups(draw: st.DrawFn) -> tuple[Graph, float]:
    count = draw(st.integers(min_value=3, max_value=10))
    coordinate = st.integers(min_value=0, max_value=15).map(float)
    positions = {f"n{i}": (draw(coordinate), draw(coordinate)) for i in range(count)}
    chain = [(f"n{i}", f"n{i + 1}") for i in range(count - 1)]
    extra = draw(
        st.lists(st.tuples(st.sampled_from(sorted(positions)), st.sampled_from(sorted(positions))))
    )
    two_way = sorted({(min(p), max(p)) for p in chain + extra if p[0] != p[1]})
    return make_graph(positions, two_way=two_way), draw(st.sampled_from([0.5, 1.7, 4.0]))


def _holdings_conflict(conflicts: ConflictMap, table: ReservationTable) -> list[object]:
    held = list(table.vehicles())
    return [
        (a, ra, b, rb)
        for i, (a, mine) in enumerate(held)
        for b, theirs in held[i + 1 :]
        for ra in mine
        for rb in theirs
        if conflicts.conflict(ra, rb)
    ]


operations = st.tuples(
    st.sampled_from(["claim", "release", "replace"]),
    st.sampled_from([R1, R2, R3]),
    st.lists(st.integers(min_value=0, max_value=200), max_size=5),
)


@settings(max_examples=100, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(random_setups(), st.lists(operations, max_size=25))
def test_no_two_vehicles_ever_hold_conflicting_resources(
    setup: tuple[Graph, float], steps: list[tuple[str, AgvId, list[int]]]
) -> None:
    """Whatever claims, releases and replacements happen, conflicting resources never have two
    different holders, and a refused operation changes nothing."""
    graph, safety = setup
    conflicts = build_conflicts(graph, safety)
    universe: list[Resource] = sorted(conflicts)
    table = ReservationTable(conflicts)
    for operation, vehicle, picks in steps:
        chosen = [universe[p % len(universe)] for p in picks]
        if operation == "release":
            result: ReservationTable | Refused = table.release(vehicle, chosen)
        elif operation == "claim":
            result = table.claim(vehicle, chosen)
        else:
            result = table.replace(vehicle, chosen)
        if isinstance(result, ReservationTable):
            table = result
        else:
            assert result.holder != vehicle
            assert conflicts.conflict(result.wanted, result.held)
        assert _holdings_conflict(conflicts, table) == []
        for holder, resources in table.vehicles():
            assert all(table.holder(r) == holder for r in resources)
