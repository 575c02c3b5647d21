"""Zone geometry (vda5050.polygons): what a simple polygon is, and counterclockwise order
(3.0 §7.6, T85)."""

from __future__ import annotations

import pytest

from vda5050.graph_file import GraphVertex
from vda5050.polygons import (
    counterclockwise,
    near,
    point_near,
    simple_polygon_problem,
    touches,
)


def _polygon(*corners: tuple[float, float]) -> list[GraphVertex]:
    return [GraphVertex(x=x, y=y) for x, y in corners]


SQUARE = _polygon((0, 0), (2, 0), (2, 2), (0, 2))


@pytest.mark.parametrize(
    ("corners", "problem"),
    [
        (((0, 0), (2, 0), (2, 2), (0, 2)), None),
        (((0, 0), (2, 0), (1, 1), (2, 2), (0, 2)), None),  # concave
        (((0, 0), (2, 2), (2, 0), (0, 2)), "its sides 1 and 3 cross"),  # a bow tie
        (((0, 0), (2, 0), (1, 0)), "its sides 1 and 2 overlap"),  # folds back on itself
        (((0, 0), (1, 1), (2, 2)), "its sides 1 and 3 overlap"),  # all on one line
        (((0, 0), (2, 0), (2, 0), (0, 2)), "its vertices 2 and 3 are the same point"),
        (((0, 0), (4, 0), (4, 4), (2, 0), (0, 4)), "its sides 1 and 3 cross"),  # touches a side
    ],
)
def test_only_a_simple_polygon_with_an_area_is_a_zone(
    corners: tuple[tuple[float, float], ...], problem: str | None
) -> None:
    assert simple_polygon_problem(_polygon(*corners)) == problem


def test_vertices_come_out_counterclockwise_whichever_way_they_were_drawn() -> None:
    clockwise = list(reversed(SQUARE))
    assert counterclockwise(clockwise) == SQUARE
    assert counterclockwise(SQUARE) == SQUARE


def test_a_segment_touches_a_polygon_it_enters_crosses_or_grazes() -> None:
    assert touches(SQUARE, (1, 1), (5, 5))  # from inside
    assert touches(SQUARE, (-1, 1), (3, 1))  # through
    assert touches(SQUARE, (-1, 2), (3, 2))  # along a side
    assert not touches(SQUARE, (-1, 3), (3, 3))


def test_a_margin_makes_a_zone_reach_beyond_its_polygon() -> None:
    """A segment passing 0.5 m from the square touches it only with a margin of 0.5 m or more;
    a point 0.5 m outside is covered likewise."""
    beside = ((-1.0, 2.5), (3.0, 2.5))
    assert not near(SQUARE, *beside, 0.0)
    assert not near(SQUARE, *beside, 0.4)
    assert near(SQUARE, *beside, 0.5)
    assert near(SQUARE, (1.0, 1.0), (1.5, 1.5), 0.0)  # inside: touches whatever the margin
    assert not point_near(SQUARE, (2.5, 1.0), 0.4)
    assert point_near(SQUARE, (2.5, 1.0), 0.6)
