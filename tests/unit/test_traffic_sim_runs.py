"""benchmarks/traffic_sim.py: seeds given as ranges, and runs spread over worker processes
giving exactly the figures of one process (issue 9's co-simulation is judged over many seeds)."""

from __future__ import annotations

import argparse
import statistics
from typing import Any

import orjson
import pytest

from benchmarks.traffic_sim import WAREHOUSE
from vda_fleetsim.cli import seed_list
from vda_fleetsim.runs import SimRun, results_of
from vda_fleetsim.simulation import Simulation, _band
from vda_master.dispatcher import OrderStatus


def test_a_seed_or_an_inclusive_range() -> None:
    assert seed_list("7") == [7]
    assert seed_list("1-4") == [1, 2, 3, 4]
    assert seed_list("5-5") == [5]


@pytest.mark.parametrize(("text", "says"), [("x", "whole number"), ("4-1", "ends before")])
def test_a_malformed_seed_says_what_is_wrong(text: str, says: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=says):
        seed_list(text)


def test_workers_give_the_figures_of_one_process_in_seed_order() -> None:
    runs = [
        SimRun(WAREHOUSE, 3, seed, 0.02, 0.01, {"traffic_control": True}, frozenset(), dump=True)
        for seed in (1, 2, 3)
    ]
    alone = list(results_of(runs, jobs=1))
    spread = list(results_of(runs, jobs=2))
    assert spread == alone
    assert all(report["orders_per_h"] > 0 for report, _ in alone)  # the vehicles did drive
    assert all("waited where" in dumped for _, dumped in alone)
    assert all("stretch bands" in dumped and "<2x" in dumped for _, dumped in alone)


@pytest.mark.parametrize(
    ("stretch", "band"),
    [(1.0, "<2x"), (1.99, "<2x"), (2.0, "2-3x"), (3.5, "3-4x"), (4.99, "4-5x"), (5.0, ">=5x")],
)
def test_a_stretch_falls_in_the_band_of_its_lower_bound(stretch: float, band: str) -> None:
    assert _band(stretch) == band  # the last band starts at issue 9's deadlock factor


def test_a_vehicle_waits_for_the_client_before_its_next_order() -> None:
    """--client-delay-ms: a vehicle whose order ended is given the next one only after the
    delay (here longer than the run: each of six vehicles finishes its first order and then
    stands), and idle vehicles that master control moves out of another's way are counted."""

    def run(delay_s: float) -> dict[str, Any]:
        sim_run = SimRun(
            WAREHOUSE, 6, 1, 0.02, 0.05, {"traffic_control": True}, frozenset(),
            client_delay_s=delay_s,
        )  # fmt: skip
        report, _ = next(results_of([sim_run], jobs=1))
        return report

    prompt, waiting = run(0.0), run(3600.0)
    finished = round(waiting["orders_per_h"] * 0.05)
    assert finished == 6  # the first order of each, then nothing
    assert prompt["orders_per_h"] * 0.05 > 2 * finished  # asked at once: several each
    assert waiting["parking_moves"] >= 1  # standing at their destinations, in others' way


def test_two_stops_send_each_transport_as_one_order_that_picks_then_drops() -> None:
    """--two-stops: each vehicle's first order picks at a pick station and drops at a drop
    station (one order, two stops), so its free flow is both legs': about twice one leg's."""
    sim = Simulation(
        WAREHOUSE, 4, seed=1, latency_s=0.02, settings={"traffic_control": True}, two_stops=True
    )
    sim.run(300.0)
    tracks = list(sim.master.tracks.values())
    assert tracks
    for track in tracks:
        request = orjson.loads(track.request_json or "{}")
        assert [stop["actions"][0]["actionType"] for stop in request["stops"]] == ["pick", "drop"]
    assert sim.results.finished >= 4  # every vehicle finished a transport within 5 minutes
    assert all(track.plan.nodes[-1].actions[0].action_type == "drop" for track in tracks
               if track.status is OrderStatus.FINISHED)  # fmt: skip
    single = Simulation(WAREHOUSE, 4, seed=1, latency_s=0.02, settings={"traffic_control": True})
    single.run(300.0)
    one_leg = statistics.fmean(single.results.free_flows)
    assert statistics.fmean(sim.results.free_flows) > 1.5 * one_leg
