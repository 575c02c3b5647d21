"""When an order is expected to finish (``expectedFinishAt``, docs/master.md *Expected finish*):
the plan's driving and turning times, the part already driven, and the pace and dwell master
control learns from finished orders (:mod:`vda_master.eta`)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

import pytest

from vda5050.models import AgvPosition
from vda5050.testing import make_state
from vda_master.eta import (
    PACE_BOUNDS,
    Drive,
    FinishEstimates,
    LearnedMean,
    Leg,
    driving_left_s,
    graph_legs,
    leg_times,
)
from vda_master.traffic.testing import make_graph

#: Driving seconds to each node of a plan of six nodes, 10 s apart (the learning tests).
PLAN = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0)
#: a (0, 0) → b (4, 0) → c (4, 3): a right angle at b.
ELL = make_graph({"a": (0, 0), "b": (4, 0), "c": (4, 3)}, one_way=[("a", "b"), ("b", "c")])
EDGES = ("a-b", "b-c")


def test_driving_and_turning_add_up_along_the_plan() -> None:
    """Each edge at the vehicle's speed; at b a quarter turn on the spot at its turning speed;
    without a turning speed (a 2.0 factsheet has none) turns cost nothing."""
    turning = leg_times(ELL, graph_legs(ELL, EDGES), Drive(speed_mps=2.0, turn_radps=0.5))
    assert turning.to_node == pytest.approx((0.0, 2.0, 2.0 + (math.pi / 2) / 0.5 + 1.5))
    plain = leg_times(ELL, graph_legs(ELL, EDGES), Drive(speed_mps=2.0))
    assert plain.to_node == pytest.approx((0.0, 2.0, 3.5))


def test_an_edges_max_speed_caps_the_vehicles_and_follows_the_time_lapse() -> None:
    """An edge's maxSpeed (as the order gives it) caps the speed; for a fleet simulated F times
    faster than real time both the factsheet's speed and the edge's limit count F times."""
    legs = (Leg("a-b", max_speed=0.5), Leg("b-c"))
    assert leg_times(ELL, legs, Drive(speed_mps=2.0)).to_node[-1] == pytest.approx(8.0 + 1.5)
    lapsed = leg_times(ELL, legs, Drive(speed_mps=20.0, edge_speed_factor=10.0))
    assert lapsed.to_node[-1] == pytest.approx(0.8 + 0.15)


def test_an_edge_the_graph_lacks_is_timed_from_its_nodes() -> None:
    """The temporary first edge of an order that starts off the graph's nodes (§6.6.3.1) is not
    in the graph: its length comes from its nodes' positions."""
    legs = (Leg("start-b", ends=((1.0, 0.0), (4.0, 0.0))), Leg("b-c"))
    assert leg_times(ELL, legs, Drive(speed_mps=1.0)).to_node == pytest.approx((0.0, 3.0, 6.0))


def test_what_is_left_counts_the_part_driven_and_the_turn_still_to_make() -> None:
    """On an edge (distanceSinceLastNode) the part driven is off, and so is the turn onto it;
    standing on a node facing away from the next edge, the turn towards it is still to come."""
    drive = Drive(speed_mps=2.0, turn_radps=1.0)
    times = leg_times(ELL, graph_legs(ELL, EDGES), drive)
    on_edge = make_state(distance_since_last_node=3.0)
    assert driving_left_s(times, 0, on_edge, drive) == pytest.approx(times.to_node[-1] - 1.5)
    facing_west = make_state(
        agv_position=AgvPosition(
            x=0.0, y=0.0, theta=math.pi, map_id="test", position_initialized=True
        )
    )
    assert driving_left_s(times, 0, facing_west, drive) == pytest.approx(
        times.to_node[-1] + math.pi
    )
    after_the_turn = make_state(distance_since_last_node=1.5)
    assert driving_left_s(times, 1, after_the_turn, drive) == pytest.approx(1.5 / 2.0)
    assert driving_left_s(times, 2, None, drive) == 0.0


def test_a_driving_vehicle_has_driven_on_since_its_state_up_to_the_next_node() -> None:
    """States come at nodes and events (§6.10), not continuously: a vehicle whose last state
    says it drives has driven on since at the edge's speed, up to the edge's end."""
    drive = Drive(speed_mps=2.0)
    times = leg_times(ELL, graph_legs(ELL, EDGES), drive)  # a-b 2 s, b-c 1.5 s
    leaving = make_state(distance_since_last_node=0.0, driving=True)
    assert driving_left_s(times, 0, leaving, drive, since_state_s=0.5) == pytest.approx(3.0)
    assert driving_left_s(times, 0, leaving, drive, since_state_s=9.0) == pytest.approx(1.5)
    standing = make_state(driving=False)
    assert driving_left_s(times, 0, standing, drive, since_state_s=9.0) == pytest.approx(3.5)


def test_pace_and_dwell_are_learned_from_finished_orders() -> None:
    """An order expected to drive 10 s arrives after 15 s: pace 1.5 for its manufacturer;
    FINISHED 4 s after arriving with a pick there: dwell 4 s for (acme, pick). The next order
    of that manufacturer is expected at now + 10 × 1.5 + 4; while its vehicle stands at the
    destination the dwell counts down."""
    learned = FinishEstimates()
    learned.started("o1", "acme", 10.0, now=100.0)
    learned.progressed("o1", 1, 2, now=105.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start])
    learned.progressed("o1", 2, 2, now=115.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start])
    learned.ended("o1", ("pick",), 2, finished=True, now=119.0)
    assert learned.pace_of("acme") == pytest.approx(1.5)
    assert learned.dwell_of("acme", ("pick",)) == pytest.approx(4.0)
    assert (learned.pace_of("other"), learned.dwell_of("acme", ("drop",))) == (1.0, 0.0)

    times = leg_times(ELL, graph_legs(ELL, EDGES), Drive(speed_mps=1.0))  # 7 s
    learned.started("o2", "acme", 7.0, now=200.0)

    def expected(progress: int, now: float) -> float:
        return learned.expected_finish(
            order_id="o2",
            manufacturer="acme",
            times=times,
            progress=progress,
            state=None,
            drive=Drive(speed_mps=1.0),
            destination_actions=("pick",),
            stops_s=lambda: 0.0,
            now=now,
        )

    assert expected(0, 200.0) == pytest.approx(200.0 + 7.0 * 1.5 + 4.0)
    learned.progressed("o2", 2, 2, now=210.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start])
    assert expected(2, 211.0) == pytest.approx(211.0 + 3.0)


def test_orders_that_ended_otherwise_teach_no_dwell_and_a_pace_stays_in_bounds() -> None:
    """A cancelled order teaches no dwell; a vehicle stuck 100 times its drive teaches at most
    the upper bound; a further leg whose stop's actions were not seen to end teaches no pace."""
    learned = FinishEstimates()
    learned.started("o1", "acme", 1.0, now=0.0)
    learned.progressed("o1", 2, 2, now=100.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start])
    learned.ended("o1", ("pick",), 2, finished=False, now=101.0)
    assert learned.pace_of("acme") == PACE_BOUNDS[1]
    assert learned.dwell_of("acme", ("pick",)) == 0.0
    learned.started("o2", "beta", 10.0, now=0.0)
    learned.progressed("o2", 2, 2, now=10.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start])
    learned.progressed(
        "o2", 5, 5, now=500.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start]
    )  # no dwelt at node 2
    assert learned.pace_of("beta") == 1.0


def test_an_order_with_a_further_stop_teaches_its_first_legs_pace_and_each_stops_dwell() -> None:
    """An order with two stops: its first leg (created to the first stop) is a pace sample, and
    the time until the first stop's actions ended a dwell sample; the plan then grows by the
    second leg, a pace sample from the end of those actions, and its dwell runs from the
    vehicle's arrival at the last stop to FINISHED."""
    learned = FinishEstimates()
    learned.started("o1", "acme", 10.0, now=0.0)
    learned.progressed(
        "o1", 2, 2, now=12.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start]
    )  # at the first stop
    assert learned.pace_of("acme") == pytest.approx(1.2)
    assert learned.arrived_at("o1", 2) == 12.0
    assert learned.waits_for_dwell("o1", 2)
    learned.dwelt("o1", ("pick",), 2, now=16.0)  # a state shows the pick FINISHED
    assert not learned.waits_for_dwell("o1", 2)
    assert learned.dwell_of("acme", ("pick",)) == pytest.approx(4.0)
    # the update appended nodes 3-5
    learned.progressed("o1", 3, 5, now=30.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start])
    assert learned.arrived_at("o1", 5) is None
    # from the end of the pick (16 s) to node 5: 36 s for the 30 s expected, pace 1.2 again
    learned.progressed("o1", 5, 5, now=52.0, leg_drive_s=lambda start: PLAN[-1] - PLAN[start])
    learned.ended("o1", ("drop",), 5, finished=True, now=55.0)
    assert learned.dwell_of("acme", ("drop",)) == pytest.approx(3.0)
    assert learned.pace_of("acme", planned=False) == pytest.approx(1.2)
    assert learned.pace["acme"].count == 1  # a leg not yet planned has a pace of its own


def test_the_learned_mean_follows_the_recent_orders() -> None:
    """After a change (a slower floor) the pace follows within about twenty orders."""
    learned = FinishEstimates()
    for n in range(60):
        order, slow = f"o{n}", n >= 30
        learned.started(order, "acme", 10.0, now=0.0)
        learned.progressed(
            order,
            1,
            1,
            now=20.0 if slow else 10.0,
            leg_drive_s=lambda start: PLAN[-1] - PLAN[start],
        )
        if n == 29:
            assert learned.pace_of("acme") == pytest.approx(1.0)
    assert learned.pace_of("acme") > 1.75


def _learned() -> FinishEstimates:
    estimates = FinishEstimates()
    estimates.pace["acme"] = LearnedMean(1.4, 20)
    estimates.unplanned_pace["acme"] = LearnedMean(1.9, 3)
    estimates.dwell[("acme", ("pick",))] = LearnedMean(4.5, 7)
    estimates.dwell[("other", ("drop", "charge"))] = LearnedMean(12.0, 1)
    return estimates


def test_what_was_learned_comes_back_as_it_was_written() -> None:
    document = json.loads(json.dumps(_learned().learned_document(10.0)))
    restored = FinishEstimates()
    assert restored.restore_learned(document, 10.0) is None
    assert restored.pace_of("acme") == 1.4
    assert restored.pace_of("acme", planned=False) == 1.9
    assert restored.dwell_of("acme", ("pick",)) == 4.5
    assert restored.dwell_of("other", ("drop", "charge")) == 12.0
    assert restored.pace["acme"].count == 20  # the window goes on where it was


@pytest.mark.parametrize(
    ("change", "why"),
    [
        (lambda d: d.update(version=99), "not a learned-estimates document"),
        (lambda d: d.update(timeLapse=1.0), "learned at time lapse 1.0, not 10.0"),
        (lambda d: d["pace"].update(acme={"mean": 50.0, "n": 3}), "out of range"),
        (lambda d: d["dwell"][0].update(n=0), "no positive whole number"),
        (lambda d: d["dwell"][0].update(mean="4"), "is no number"),
        (lambda d: d.pop("unplannedPace"), "malformed: KeyError"),
        (lambda d: d.update(pace=[1, 2]), "must be an object"),
    ],
)
def test_a_document_that_cannot_be_used_takes_nothing_and_says_why(
    change: Callable[[dict[str, Any]], object], why: str
) -> None:
    document = json.loads(json.dumps(_learned().learned_document(10.0)))
    change(document)
    restored = FinishEstimates()
    reason = restored.restore_learned(document, 10.0)
    assert reason is not None
    assert why in reason
    assert (restored.pace, restored.unplanned_pace, restored.dwell) == ({}, {}, {})
