"""Plane geometry of zones (pure): whether a straight segment touches a simple polygon.

Master control (zones of the graph file, docs/master.md) and the 3.0 vehicle (zone sets,
3.0 §6.4) ask the same question of an edge: does the straight line between its nodes lie
(partly) inside the polygon, or cross or touch its border?
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

Point = tuple[float, float]


class Vertex(Protocol):
    """A polygon corner: anything with ``x`` and ``y`` (a 3.0 zone's or a graph zone's)."""

    @property
    def x(self) -> float: ...

    @property
    def y(self) -> float: ...


def touches(polygon: Sequence[Vertex], start: Point, end: Point) -> bool:
    """The segment lies (partly) inside the simple polygon or crosses its border."""
    corners = [(v.x, v.y) for v in polygon]
    if _inside(corners, start) or _inside(corners, end):
        return True
    return any(
        _crosses(start, end, a, b) for a, b in zip(corners, corners[1:] + corners[:1], strict=True)
    )


def inside(polygon: Sequence[Vertex], point: Point) -> bool:
    """The point lies inside the simple polygon or on its border."""
    return _inside([(v.x, v.y) for v in polygon], point)


def _inside(corners: Sequence[Point], point: Point) -> bool:
    """Ray casting; points on the border count as inside."""
    x, y = point
    inside = False
    for (x1, y1), (x2, y2) in zip(corners, [*corners[1:], corners[0]], strict=True):
        if _on_segment((x1, y1), (x2, y2), point):
            return True
        if (y1 > y) != (y2 > y):
            cross_x = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
            if x < cross_x:
                inside = not inside
    return inside


def _orientation(a: Point, b: Point, c: Point) -> float:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _on_segment(a: Point, b: Point, p: Point) -> bool:
    if not math.isclose(_orientation(a, b, p), 0.0, abs_tol=1e-12):
        return False
    return min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])


def _crosses(p: Point, q: Point, a: Point, b: Point) -> bool:
    """Segments p-q and a-b intersect (touching included)."""
    d1, d2 = _orientation(a, b, p), _orientation(a, b, q)
    d3, d4 = _orientation(p, q, a), _orientation(p, q, b)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and d1 and d2 and d3 and d4:
        return True
    return any(
        (_on_segment(a, b, p), _on_segment(a, b, q), _on_segment(p, q, a), _on_segment(p, q, b))
    )
