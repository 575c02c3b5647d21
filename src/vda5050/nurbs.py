"""NURBS trajectories (VDA 5050 §6.6.6 ``trajectory``; 3.0 §7.3): checked, evaluated, sampled.

An edge's ``trajectory`` is a rational B-spline: ``degree`` p, ``knotVector`` (p + 1 more knots
than control points, each in [0, 1]) and ``controlPoints`` (x, y and a weight, 1.0 when absent),
the first and last of which are the edge's start and end. 3.0 makes ``degree`` (1) and
``knotVector`` optional: the default is the clamped uniform vector (p + 1 zeros, equidistant
inner knots, p + 1 ones).

Both services need the curve as points: master control for an edge's length, its conflicts and
the live map, the simulated vehicle to drive along it. :func:`sample` turns it into a polyline
fine enough for that (a few centimetres off the curve at most for the radii of a factory floor).

Pure: no I/O, no clock.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final, Protocol

#: A point of the floor: x, y in metres.
Point = tuple[float, float]

#: Polyline pieces per control-point span; more for higher degrees (see :func:`sample`).
_PIECES_PER_SPAN: Final = 16
#: At most this many points per curve, however many control points it has.
_MAX_POINTS: Final = 2_000


@dataclass(frozen=True, slots=True)
class Curve:
    """A checked NURBS: ``points`` as (x, y, weight)."""

    degree: int
    knots: tuple[float, ...]
    points: tuple[tuple[float, float, float], ...]

    @property
    def start(self) -> Point:
        return self.evaluate(self.knots[self.degree])

    @property
    def end(self) -> Point:
        return self.evaluate(self.knots[len(self.points)])

    def evaluate(self, u: float) -> Point:
        """The curve's point at parameter ``u`` (clamped to the domain), by de Boor's algorithm
        in homogeneous coordinates."""
        p, knots, n = self.degree, self.knots, len(self.points)
        low, high = knots[p], knots[n]
        u = min(max(u, low), high)
        span = _span(knots, p, n, u)
        work = [
            (x * w, y * w, w) for x, y, w in self.points[span - p : span + 1]
        ]  # P[span-p .. span]
        for r in range(1, p + 1):
            for j in range(p, r - 1, -1):
                i = span - p + j
                denominator = knots[i + p - r + 1] - knots[i]
                alpha = 0.0 if denominator == 0 else (u - knots[i]) / denominator
                a, b = work[j - 1], work[j]
                work[j] = (
                    (1 - alpha) * a[0] + alpha * b[0],
                    (1 - alpha) * a[1] + alpha * b[1],
                    (1 - alpha) * a[2] + alpha * b[2],
                )
        x, y, w = work[p]
        return (x / w, y / w)


def _span(knots: Sequence[float], p: int, n: int, u: float) -> int:
    """The index k (p <= k < n) with knots[k] <= u < knots[k + 1]; the last non-empty span for
    u at the domain's end."""
    if u >= knots[n]:  # the last knot below the domain's end starts the last span
        return max(p, bisect.bisect_left(knots, knots[n], p, n) - 1)
    return min(n - 1, max(p, bisect.bisect_right(knots, u, p, n) - 1))


def uniform_knots(degree: int, count: int) -> tuple[float, ...]:
    """The clamped uniform knot vector for ``count`` control points (3.0's default)."""
    inner = count - degree - 1
    middle = tuple((i + 1) / (inner + 1) for i in range(inner))
    return (0.0,) * (degree + 1) + middle + (1.0,) * (degree + 1)


def build_curve(
    degree: float | None,
    knots: Sequence[float] | None,
    points: Sequence[tuple[float, float, float | None]],
) -> Curve | str:
    """The curve, or what makes it no NURBS VDA 5050 allows (the message names the rule)."""
    p = 1 if degree is None else degree
    if p != int(p) or p < 1:
        return f"degree {degree} is not a whole number of at least 1"
    p = int(p)
    if len(points) < p + 1:
        return f"a degree {p} curve needs at least {p + 1} control points, it has {len(points)}"
    vector = uniform_knots(p, len(points)) if knots is None else tuple(knots)
    weighted = tuple((x, y, 1.0 if w is None else w) for x, y, w in points)
    problem = _knot_problem(vector, p, len(points)) or _point_problem(weighted)
    return problem if problem is not None else Curve(p, vector, weighted)


class _ControlPoint(Protocol):
    @property
    def x(self) -> float: ...
    @property
    def y(self) -> float: ...
    @property
    def weight(self) -> float | None: ...


class TrajectoryLike(Protocol):
    """A ``trajectory`` as any model holds it: 2.x and 3.0 wire models, the graph file's."""

    @property
    def degree(self) -> int | None: ...
    @property
    def knot_vector(self) -> Sequence[float] | None: ...
    @property
    def control_points(self) -> Sequence[_ControlPoint]: ...


def curve_of(trajectory: TrajectoryLike) -> Curve | str:
    """:func:`build_curve` of a trajectory model."""
    points = [(p.x, p.y, p.weight) for p in trajectory.control_points]
    return build_curve(trajectory.degree, trajectory.knot_vector, points)


def _knot_problem(vector: tuple[float, ...], p: int, count: int) -> str | None:
    if len(vector) != count + p + 1:
        return (
            f"knotVector has {len(vector)} knots; {count} control points of degree {p} "
            f"need {count + p + 1}"
        )
    if any(not 0 <= k <= 1 for k in vector):
        return "every knot must lie in [0, 1]"
    if any(b < a for a, b in itertools.pairwise(vector)):
        return "knotVector must not decrease"
    if vector[p] >= vector[count]:
        return "knotVector leaves the curve no domain (its inner knots are all equal)"
    return None


def _point_problem(points: tuple[tuple[float, float, float], ...]) -> str | None:
    if any(not (math.isfinite(x) and math.isfinite(y)) for x, y, _ in points):
        return "control points must be finite numbers"
    if any(w <= 0 or not math.isfinite(w) for _, _, w in points):
        return "control point weights must be positive"
    return None


def sample(curve: Curve) -> tuple[Point, ...]:
    """The curve as a polyline from its start to its end: per non-empty knot span
    ``16 * degree`` pieces (a straight degree 1 span needs one), consecutive equal points
    dropped."""
    p, knots, n = curve.degree, curve.knots, len(curve.points)
    spans = [(knots[k], knots[k + 1]) for k in range(p, n) if knots[k + 1] > knots[k]]
    pieces = 1 if p == 1 else min(_PIECES_PER_SPAN * p, max(1, _MAX_POINTS // len(spans)))
    out: list[Point] = [curve.evaluate(spans[0][0])]
    for low, high in spans:
        for i in range(1, pieces + 1):
            point = curve.evaluate(low + (high - low) * i / pieces)
            if point != out[-1]:
                out.append(point)
    return tuple(out)


def polyline_length(points: Sequence[Point]) -> float:
    """Length of the polyline through ``points`` (metres)."""
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(points))


def path_from(path: Sequence[Point], position: Point) -> tuple[Point, ...]:
    """``path`` from ``position`` on: ``position``, then the points after the segment of
    ``path`` nearest to it (a vehicle standing on an edge drives the rest of its path)."""
    best_index, best_distance = 0, math.inf
    for index, (a, b) in enumerate(itertools.pairwise(path)):
        foot = _foot(position, a, b)
        distance = math.hypot(foot[0] - position[0], foot[1] - position[1])
        if distance < best_distance:
            best_index, best_distance = index, distance
    rest = [p for p in path[best_index + 1 :] if p != position]
    return (position, *rest) if rest else (position, path[-1])


def _foot(point: Point, a: Point, b: Point) -> Point:
    """The point of segment a-b nearest to ``point``."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    span = dx * dx + dy * dy
    if span == 0:
        return a
    u = max(0.0, min(1.0, ((point[0] - a[0]) * dx + (point[1] - a[1]) * dy) / span))
    return (a[0] + u * dx, a[1] + u * dy)
