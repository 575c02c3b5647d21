"""Simulations to run and their results, one process or several (each run is deterministic
and independent, so worker processes give exactly the figures of one)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vda_fleetsim.simulation import Simulation


@dataclass(frozen=True)
class SimRun:
    """One simulation to run: ``count`` vehicles, one seed (the arguments of
    :class:`~vda_fleetsim.simulation.Simulation`)."""

    graph: Path
    count: int
    seed: int
    latency_s: float
    sim_hours: float
    settings: Mapping[str, Any]
    any_station: frozenset[str] = frozenset()
    #: what :meth:`Simulation.dump` prints, and where the waits were, in the report
    dump: bool = False
    client_delay_s: float = 0.0
    two_stops: bool = False
    vehicle_settings: Mapping[str, Any] = field(default_factory=dict)
    start_node: str | None = None
    safety_m: float | None = None


def simulate(run: SimRun) -> tuple[dict[str, Any], str]:
    """Run one simulation: its report, and what :meth:`Simulation.dump` prints about it ("" but
    with ``dump``)."""
    sim = Simulation(
        run.graph,
        run.count,
        seed=run.seed,
        latency_s=run.latency_s,
        settings=dict(run.settings),
        any_station=run.any_station,
        client_delay_s=run.client_delay_s,
        two_stops=run.two_stops,
        vehicle_settings=run.vehicle_settings,
        start_node=run.start_node,
        safety_m=run.safety_m,
    )
    sim.profile_waits = run.dump
    sim.run(run.sim_hours * 3600)
    return sim.report(run.count, run.sim_hours), sim.dump() if run.dump else ""


def results_of(runs: list[SimRun], jobs: int) -> Iterator[tuple[dict[str, Any], str]]:
    """The runs' results in their order, ``jobs`` simulated at once (forked workers, which
    inherit this process's modules as they are)."""
    if jobs <= 1 or len(runs) <= 1:
        yield from map(simulate, runs)
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        yield from pool.map(simulate, runs)
