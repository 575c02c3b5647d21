"""NURBS trajectories (§6.6.6 ``trajectory``; 3.0 §7.3): checked, evaluated, sampled."""

from __future__ import annotations

import math

import pytest

from vda5050.nurbs import Curve, build_curve, polyline_length, sample, uniform_knots

#: The weight that makes a degree 2 NURBS an exact circular arc of 90 degrees.
W = math.sqrt(2) / 2


def quarter_circle() -> Curve | str:
    """The unit circle from (1, 0) to (0, 1), counter-clockwise, as a rational degree 2 NURBS."""
    return build_curve(2, [0, 0, 0, 1, 1, 1], [(1, 0, 1.0), (1, 1, W), (0, 1, 1.0)])


def test_a_rational_quarter_circle_lies_on_the_unit_circle() -> None:
    curve = quarter_circle()
    assert not isinstance(curve, str)
    assert curve.start == pytest.approx((1.0, 0.0))
    assert curve.end == pytest.approx((0.0, 1.0))
    for i in range(11):
        x, y = curve.evaluate(i / 10)
        assert math.hypot(x, y) == pytest.approx(1.0, abs=1e-12)
    assert curve.evaluate(-1.0) == curve.start  # clamped to the domain
    assert curve.evaluate(2.0) == curve.end


def test_the_sampled_quarter_circle_is_as_long_as_the_arc() -> None:
    """The polyline runs from the start to the end, every point on the circle, its length
    within 0.1 % of pi / 2."""
    curve = quarter_circle()
    assert not isinstance(curve, str)
    points = sample(curve)
    assert (points[0], points[-1]) == (curve.start, curve.end)
    assert all(math.hypot(x, y) == pytest.approx(1.0, abs=1e-12) for x, y in points)
    assert polyline_length(points) == pytest.approx(math.pi / 2, rel=1e-3)


@pytest.mark.parametrize(
    ("degree", "knots", "points", "named"),
    [
        (1.5, None, [(0, 0, None), (1, 0, None)], "degree 1.5 is not a whole number"),
        (0, None, [(0, 0, None), (1, 0, None)], "degree 0 is not a whole number"),
        (2, None, [(0, 0, None), (1, 0, None)], "needs at least 3 control points, it has 2"),
        (1, [0, 0, 1], [(0, 0, None), (1, 0, None)], "knotVector has 3 knots"),
        (1, [0, 0, 1, 2], [(0, 0, None), (1, 0, None)], "every knot must lie in [0, 1]"),
        (1, [0, 1, 0, 1], [(0, 0, None), (1, 0, None)], "knotVector must not decrease"),
        (1, [0, 0.5, 0.5, 1], [(0, 0, None), (1, 0, None)], "no domain"),
        (1, None, [(0, 0, None), (math.inf, 0, None)], "control points must be finite"),
        (1, None, [(0, 0, None), (1, 0, 0.0)], "weights must be positive"),
    ],
)
def test_build_curve_names_what_makes_a_trajectory_no_nurbs(
    degree: float, knots: list[float] | None, points: list[tuple[float, float, float]], named: str
) -> None:
    problem = build_curve(degree, knots, points)
    assert isinstance(problem, str)
    assert named in problem


def test_uniform_knots_are_clamped_and_equidistant() -> None:
    assert uniform_knots(1, 2) == (0.0, 0.0, 1.0, 1.0)
    assert uniform_knots(2, 5) == pytest.approx((0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1))
    assert len(uniform_knots(3, 7)) == 7 + 3 + 1


def test_without_degree_and_knots_a_curve_is_the_3_0_default() -> None:
    """3.0 T101: degree 1 and uniform knots: the polyline through the control points, each
    weight 1 when absent."""
    curve = build_curve(None, None, [(0, 0, None), (3, 0, None), (3, 4, None)])
    assert not isinstance(curve, str)
    assert (curve.degree, curve.knots) == (1, uniform_knots(1, 3))
    assert {w for _, _, w in curve.points} == {1.0}
    assert sample(curve) == ((0.0, 0.0), (3.0, 0.0), (3.0, 4.0))
    assert polyline_length(sample(curve)) == pytest.approx(7.0)
