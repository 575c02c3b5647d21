"""Traffic-control micro-benchmark (issue 9 §4, §8): the pure core's cost per call.

On ``config/graphs/warehouse.json`` with K vehicles, each on a random trip (so the passage table
holds K planned routes), it times:

- ``conflicts``: building the conflict sets (once per graph load);
- ``plan``: one time-aware route (``TrafficController.plan``);
- ``choose``: the vehicle with the earliest expected arrival among all K (what
  ``POST /orders`` without a vehicle costs; target p99 < 50 ms at K = 20);
- ``assign`` and ``request_release``: the per-order and per-state work of the fold.

Run: python benchmarks/traffic_planner.py [--vehicles K] [--requests N] [--seed S]
"""

from __future__ import annotations

import argparse
import random
import statistics
import time
from collections.abc import Callable
from functools import partial
from typing import TypeVar

from vda_master.routing import Route, shortest_route
from vda_master.traffic.conflicts import build_conflicts
from vda_master.traffic.controller import AtNode, TrafficController
from vda_master.traffic.passages import SpeedModel
from vda_master.traffic.state import TrafficSettings
from vda_master.traffic.testing import SIM_SAFETY_M, agv, warehouse_graph

T = TypeVar("T")


def timed(samples: list[float], call: Callable[[], T]) -> T:
    """Call ``call``, add its duration in ms to ``samples``, return its result."""
    started = time.perf_counter()
    result = call()
    samples.append((time.perf_counter() - started) * 1000)
    return result


def report(name: str, samples: list[float]) -> None:
    ordered = sorted(samples)
    p99 = ordered[min(len(ordered) - 1, round(0.99 * (len(ordered) - 1)))]
    print(
        f"{name:<16} n={len(samples):<5} mean={statistics.fmean(samples):7.3f} ms  "
        f"p50={statistics.median(samples):7.3f} ms  p99={p99:7.3f} ms  max={ordered[-1]:7.3f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=20)
    parser.add_argument("--requests", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    graph = warehouse_graph()
    nodes = sorted(graph.nodes)
    print(f"warehouse: {len(graph.nodes)} nodes, {len(graph.edges)} edges; K = {args.vehicles}")

    build: list[float] = []
    for _ in range(10):
        timed(build, lambda: build_conflicts(graph, SIM_SAFETY_M))
    report("conflicts", build)

    settings = TrafficSettings(speed=SpeedModel(1.5))
    controller = TrafficController.for_graph(graph, SIM_SAFETY_M, settings)
    fleet = [agv(f"robot_{i}") for i in range(args.vehicles)]
    starts = rng.sample(nodes, len(fleet))
    for vehicle, start in zip(fleet, starts, strict=True):
        controller, _ = controller.observe(vehicle, AtNode(start), 0.0)

    assign: list[float] = []
    release: list[float] = []
    for vehicle, start in zip(fleet, starts, strict=True):
        route = shortest_route(graph, start, rng.choice([n for n in nodes if n != start]))
        assert isinstance(route, Route)  # noqa: S101 - the warehouse is strongly connected
        controller = timed(assign, partial(controller.assign, vehicle, route, 0.0))
        request = partial(
            controller.request_release, vehicle, route,
            progress_index=0, released_end=0, desired_end=3, now=0.0,
        )  # fmt: skip
        controller, _ = timed(release, request)

    plan: list[float] = []
    choose: list[float] = []
    for index in range(args.requests):
        destination = rng.choice(nodes)
        vehicle = fleet[index % len(fleet)]
        start = controller.vehicle(vehicle).node_id or starts[0]
        timed(plan, partial(controller.plan, vehicle, start, destination, 1.0))
        candidates = [(v, controller.vehicle(v).node_id or "SO0") for v in fleet]
        timed(choose, partial(controller.choose, candidates, (destination,), 1.0))
    report("assign", assign)
    report("request_release", release)
    report("plan", plan)
    report(f"choose (K={args.vehicles})", choose)


if __name__ == "__main__":
    main()
