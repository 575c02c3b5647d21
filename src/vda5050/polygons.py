"""Plane geometry of zones (pure): whether a straight segment touches a simple polygon.

Master control (zones of the graph file, docs/master.md) and the 3.0 vehicle (zone sets,
3.0 §6.4) ask the same question of an edge: does the straight line between its nodes lie
(partly) inside the polygon, or cross or touch its border? Master control also checks that a
zone is a simple polygon (:func:`simple_polygon_problem`) and sends its vertices
counterclockwise (:func:`counterclockwise`), as 3.0 §7.6 asks of a zone set (T85).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol, TypeVar

Point = tuple[float, float]
V = TypeVar("V", bound="Vertex")


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


def near(polygon: Sequence[Vertex], start: Point, end: Point, margin: float) -> bool:
    """The segment touches the polygon (:func:`touches`) or passes within ``margin`` of its
    border: a vehicle's body reaches that far beside the line its reference point drives."""
    if touches(polygon, start, end):
        return True
    if margin <= 0:
        return False
    corners = [(v.x, v.y) for v in polygon]
    return any(
        _segment_distance(start, end, a, b) <= margin
        for a, b in zip(corners, corners[1:] + corners[:1], strict=True)
    )


def point_near(polygon: Sequence[Vertex], point: Point, margin: float) -> bool:
    """The point lies inside the polygon or within ``margin`` of its border."""
    corners = [(v.x, v.y) for v in polygon]
    if _inside(corners, point):
        return True
    return margin > 0 and any(
        _point_distance(point, a, b) <= margin
        for a, b in zip(corners, corners[1:] + corners[:1], strict=True)
    )


def _point_distance(p: Point, a: Point, b: Point) -> float:
    """From point ``p`` to the segment a-b."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2
    t = min(1.0, max(0.0, t))
    return math.hypot(p[0] - (a[0] + t * dx), p[1] - (a[1] + t * dy))


def _segment_distance(p: Point, q: Point, a: Point, b: Point) -> float:
    """Between the segments p-q and a-b (0 where they cross or touch)."""
    if _crosses(p, q, a, b):
        return 0.0
    return min(
        _point_distance(p, a, b),
        _point_distance(q, a, b),
        _point_distance(a, p, q),
        _point_distance(b, p, q),
    )


def simple_polygon_problem(polygon: Sequence[Vertex]) -> str | None:
    """Why the vertices do not make a simple polygon (two sides that cross or touch apart from
    their shared corner, or no area at all), in words; None when they do."""
    corners = [(v.x, v.y) for v in polygon]
    sides = list(zip(corners, corners[1:] + corners[:1], strict=True))
    count = len(sides)
    for i, (a, b) in enumerate(sides):
        if a == b:
            return f"its vertices {i + 1} and {(i + 1) % count + 1} are the same point"
    for i in range(count):
        for j in range(i + 1, count):
            if j == i + 1 or (i == 0 and j == count - 1):  # neighbours share a corner
                if _folds_back(sides[i], sides[j]):
                    return f"its sides {i + 1} and {j + 1} overlap"
                continue
            if _crosses(*sides[i], *sides[j]):
                return f"its sides {i + 1} and {j + 1} cross"
    if math.isclose(_doubled_area(corners), 0.0, abs_tol=1e-12):
        return "its vertices enclose no area"
    return None


def counterclockwise(polygon: Sequence[V]) -> list[V]:
    """The vertices of a simple polygon in counterclockwise order (reversed if need be)."""
    corners = [(v.x, v.y) for v in polygon]
    return list(polygon) if _doubled_area(corners) >= 0 else list(reversed(polygon))


def _doubled_area(corners: Sequence[Point]) -> float:
    """Twice the signed area (shoelace): positive counterclockwise."""
    return sum(
        x1 * y2 - x2 * y1
        for (x1, y1), (x2, y2) in zip(corners, [*corners[1:], corners[0]], strict=True)
    )


def _folds_back(first: tuple[Point, Point], second: tuple[Point, Point]) -> bool:
    """Two neighbouring sides that run back over each other (collinear, pointing apart)."""
    (a, b), (c, d) = first, second
    shared, p, q = (b, a, d) if b == c else (a, b, c)
    if not math.isclose(_orientation(shared, p, q), 0.0, abs_tol=1e-12):
        return False
    return (p[0] - shared[0]) * (q[0] - shared[0]) + (p[1] - shared[1]) * (q[1] - shared[1]) > 0


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
