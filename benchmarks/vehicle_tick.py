"""CPU per simulation tick of a driving vehicle (issue 12: the vehicle process's tick).

The fleet benchmark's order for each of ``--vehicles`` simulated vehicles (two 8 m edges,
2 m/s, 5 ticks per second), then every vehicle is ticked until all have finished, as
``VehicleService``'s tick loop does: ``VehicleRuntime.tick`` with its publications going to a
sink that builds nothing (the MQTT path is measured by publish.py). Prints CPU µs per tick of a
vehicle with an order, for the whole tick and for the pure ``translator.advance`` in it.

Run: .venv/bin/python benchmarks/vehicle_tick.py [--vehicles 1000] [--runs 3]
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import math
import os
import pstats
import statistics
import time

from vda5050 import codec
from vda5050.clock import FakeClock
from vda5050.logs import configure_logging
from vda5050.mqtt import Payload
from vda5050.testing import make_order
from vda5050.topics import Topic
from vda_vehicle.config import VehicleSettings, capabilities
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.testing import make_runtime, make_stack
from vda_vehicle.translator import advance

DT_S = 0.2
SPEED_MPS = 2.0
ORDER_M = 16.0


def _discard(topic: str, kind: Topic, payload: Payload) -> None:
    """A sender that sends nothing (and builds nothing)."""


def _fleet(vehicles: int, clock: FakeClock) -> list[VehicleRuntime]:
    positions = [(0.0, 0.0), (ORDER_M / 2, 0.0), (ORDER_M, 0.0)]
    order = codec.encode(make_order(["n0", "n1", "n2"], positions=positions))
    fleet = []
    for _ in range(vehicles):
        runtime, _recorder = make_runtime(clock, speed_max_mps=SPEED_MPS)
        runtime.attach(_discard)
        runtime.handle_order(runtime.topics[Topic.ORDER], order)
        fleet.append(runtime)
    return fleet


def one_run(vehicles: int) -> tuple[float, float, int]:
    """(µs per tick, µs per advance, ticks) over the drive of ``vehicles`` vehicles."""
    clock = FakeClock()
    fleet = _fleet(vehicles, clock)
    starts = [runtime.state for runtime in fleet]
    # Tick every vehicle as often as the drive takes: reading ``runtime.state`` between ticks
    # would simulate skipped ticks at once (VehicleRuntime.tick), so the check comes after.
    rounds = math.ceil(ORDER_M / SPEED_MPS / DT_S) + 1
    begin = time.process_time()
    for _ in range(rounds):
        clock.advance(DT_S)
        now = clock.monotonic()
        for runtime in fleet:
            runtime.tick(DT_S, now)
    total = time.process_time() - begin
    ticks = rounds * len(fleet)
    unfinished = sum(1 for runtime in fleet if runtime.state.nodes)
    if unfinished:
        msg = f"{unfinished} vehicles did not finish within {rounds} ticks"
        raise RuntimeError(msg)
    # the same drive again, the pure core alone
    caps = capabilities(VehicleSettings(speed_max_mps=SPEED_MPS), None)
    stack = make_stack(caps)
    states = starts
    begin = time.process_time()
    while states:
        states = [advance(state, DT_S, caps=caps, stack=stack) for state in states]
        states = [state for state in states if state.nodes]
    pure = time.process_time() - begin
    return 1e6 * total / ticks, 1e6 * pure / ticks, ticks


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--vehicles", type=int, default=1000)
    cli.add_argument("--runs", type=int, default=3)
    cli.add_argument("--profile", action="store_true", help="one more run under cProfile")
    args = cli.parse_args()
    configure_logging(level="WARNING")  # as fleet.py runs the vehicles
    gc.disable()  # the vehicle process tunes its collector; here it would only add noise
    results = [one_run(args.vehicles) for _ in range(args.runs)]
    if args.profile:
        profiler = cProfile.Profile()
        profiler.runcall(one_run, args.vehicles)
        pstats.Stats(profiler).sort_stats("tottime").print_stats(25)
    for index, (tick, adv, ticks) in enumerate(results, 1):
        print(
            f"run {index}: {ticks} ticks, CPU per tick {tick:6.1f} µs, "
            f"translator.advance alone {adv:6.1f} µs"
        )
    tick = statistics.median(r[0] for r in results)
    adv = statistics.median(r[1] for r in results)
    print(
        f"median: tick {tick:.1f} µs, advance {adv:.1f} µs (load average {os.getloadavg()[0]:.2f})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
