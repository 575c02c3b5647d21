"""Plane distances between the shapes of graph resources: points (nodes) and segments (edges).

Pure and exact up to floating point; coordinates in metres on one map.
"""

from __future__ import annotations

import math

Point = tuple[float, float]
Segment = tuple[Point, Point]


def point_distance(a: Point, b: Point) -> float:
    """Euclidean distance between two points."""
    return math.hypot(a[0] - b[0], a[1] - b[1])


def point_segment_distance(p: Point, segment: Segment) -> float:
    """Distance from ``p`` to the closest point of ``segment`` (a point if both ends coincide)."""
    (ax, ay), (bx, by) = segment
    dx, dy = bx - ax, by - ay
    squared = dx * dx + dy * dy
    if squared == 0.0:
        return point_distance(p, (ax, ay))
    t = ((p[0] - ax) * dx + (p[1] - ay) * dy) / squared
    t = min(1.0, max(0.0, t))
    return math.hypot(p[0] - (ax + t * dx), p[1] - (ay + t * dy))


def segment_distance(s: Segment, t: Segment) -> float:
    """Smallest distance between any point of ``s`` and any point of ``t`` (0 if they touch)."""
    if segments_intersect(s, t):
        return 0.0
    return min(
        point_segment_distance(s[0], t),
        point_segment_distance(s[1], t),
        point_segment_distance(t[0], s),
        point_segment_distance(t[1], s),
    )


def segments_intersect(s: Segment, t: Segment) -> bool:
    """Whether two closed segments share a point (crossing, touching or overlapping)."""
    (p1, p2), (q1, q2) = s, t
    d1, d2 = _orientation(q1, q2, p1), _orientation(q1, q2, p2)
    d3, d4 = _orientation(p1, p2, q1), _orientation(p1, p2, q2)
    if ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4)):
        return True
    return (
        (d1 == 0 and _on_segment(q1, q2, p1))
        or (d2 == 0 and _on_segment(q1, q2, p2))
        or (d3 == 0 and _on_segment(p1, p2, q1))
        or (d4 == 0 and _on_segment(p1, p2, q2))
    )


def _orientation(a: Point, b: Point, c: Point) -> float:
    """Twice the signed area of triangle abc: > 0 counter-clockwise, < 0 clockwise, 0 collinear."""
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _on_segment(a: Point, b: Point, p: Point) -> bool:
    """For ``p`` collinear with ab: whether it lies within the segment's bounding box."""
    return min(a[0], b[0]) <= p[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= p[1] <= max(a[1], b[1])
