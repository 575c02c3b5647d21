"""The fleet scenario's Python work, per component, in one process on a fake clock (issue 12).

``benchmarks/fleet.py`` measures whole processes over MQTT and HTTP, where the machine's load,
the kernel and the broker blur what each part of our code costs. This runs the same scenario's
core work without them: ``MasterService`` and ``VehicleService``'s runtimes (N vehicles on the
lanes graph of ``fleet.py``, VDA 2.0.0, 2 m/s, visualization at 1 Hz, ticked in slices of 100
at 5 Hz as the service ticks them, with the service's arrival timers), messages handed over
after ``--latency-ms``, the orders created with ``MasterService.create_order`` (what
``POST /orders`` calls) spread over one simulated second. The master runs without a store; the
cyclic collector is tuned during the drive as both services tune it (``vda5050.collector``).

Printed: CPU-seconds of the drive (from the first order until every vehicle is done) and per
component, with the count and the µs per call: the master's order creation and its ingest of
each message kind, the vehicles' order handling, ticks and arrival events, and the building of
each message kind (inside the callers above: a payload is built when it is published). Every
figure is deterministic work, so a change shows in one run (±4 % between runs on a quiet
machine, most of it the collector); ``--profile FILE`` writes a cProfile of the drive for
``pstats``.

Run: PYTHONPATH=. .venv/bin/python benchmarks/fleet_core.py [--vehicles 1000] [--profile FILE]
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import heapq
import itertools
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import structlog

from benchmarks.fleet import SPEED_MPS, lanes_graph
from vda5050.clock import FakeClock
from vda5050.collector import tuned_collector
from vda5050.graph_file import GraphFile
from vda5050.mqtt import Payload
from vda5050.topics import AgvId, Topic
from vda_master.config import MasterConfig
from vda_master.dispatcher import OrderStatus
from vda_master.graph import load_graph
from vda_master.planner import Target
from vda_master.requests import OrderRequest
from vda_master.service import MasterService
from vda_vehicle.config import VehicleSettings
from vda_vehicle.runtime import VehicleRuntime
from vda_vehicle.service import EVENT_SLACK_S, SLICE, VehicleService

T = TypeVar("T")
#: As fleet.py names its vehicles (ours/ours-1 …).
MANUFACTURER = "ours"


class Meter:
    """CPU-seconds and calls per component."""

    def __init__(self) -> None:
        self.cpu: defaultdict[str, float] = defaultdict(float)
        self.calls: defaultdict[str, int] = defaultdict(int)

    def run(self, key: str, work: Callable[[], T]) -> T:
        begin = time.process_time()
        try:
            return work()
        finally:
            self.cpu[key] += time.process_time() - begin
            self.calls[key] += 1

    def report(self) -> None:
        for key, seconds in sorted(self.cpu.items(), key=lambda item: -item[1]):
            calls = self.calls[key]
            print(f"  {key:30} {seconds:7.3f} s  {calls:7d} calls  {1e6 * seconds / calls:8.1f} µs")


class Events:
    """A fake clock and what is due on it, in time order."""

    def __init__(self, clock: FakeClock) -> None:
        self.clock = clock
        self._queue: list[tuple[float, int, Callable[[], None]]] = []
        self._seq = itertools.count()

    def at(self, when: float, action: Callable[[], None]) -> None:
        heapq.heappush(self._queue, (when, next(self._seq), action))

    def run_until(self, end: float) -> None:
        while self._queue and self._queue[0][0] <= end:
            when, _, action = heapq.heappop(self._queue)
            self.clock.advance(max(0.0, when - self.clock.monotonic()))
            action()
        self.clock.advance(max(0.0, end - self.clock.monotonic()))


class Scenario:
    """N vehicles and a master on one fake clock, messages ``latency_s`` under way."""

    def __init__(self, vehicles: int, graph: Path, latency_s: float) -> None:
        self.meter = Meter()
        self.clock = FakeClock()
        self.events = Events(self.clock)
        self.latency_s = latency_s
        config = MasterConfig.model_validate(
            {"graph": str(graph), "traffic_control": False, "release_window_nodes": 0}
        )
        self.fleet = VehicleService(
            VehicleSettings.model_validate(
                {"graph": str(graph), "start_node": "a0", "count": vehicles,
                 "manufacturer": MANUFACTURER, "serial_number": MANUFACTURER,
                 "vda_version": "2.0.0", "speed_max_mps": SPEED_MPS,
                 "visualization_interval_s": 1.0}
            ),
            GraphFile.model_validate_json(graph.read_bytes()),
            clock=self.clock,
        )  # fmt: skip
        self.runtimes = {r.agv.serial_number: r for r in self.fleet.runtimes}
        self.master = MasterService(config, load_graph(graph), self, self.clock)
        for index, runtime in enumerate(self.fleet.runtimes):
            runtime.attach(self._to_master, visualization_offset_s=index / vehicles)
            runtime.on_next_event(self._arrival_timer(runtime))
            runtime.on_connected()
        self._start_ticking()

    # -- the wires --------------------------------------------------------------------------

    def _built(self, kind: Topic, payload: Payload) -> bytes:
        if callable(payload):
            return self.meter.run(f"build {kind.value}", payload)
        return payload

    def publish(self, topic: str, kind: Topic, payload: Payload) -> None:
        """The master's publisher: orders go to their vehicle."""
        body = self._built(kind, payload)
        if kind is Topic.ORDER:
            runtime = self.runtimes[topic.split("/")[3]]
            self._later(
                lambda: self.meter.run("vehicle order", lambda: runtime.handle_order(topic, body))
            )

    def _to_master(self, topic: str, kind: Topic, payload: Payload) -> None:
        body = self._built(kind, payload)
        if kind is not Topic.VISUALIZATION:  # master control reads poses only for a live map
            self._later(
                lambda: self.meter.run(
                    f"master ingest {kind.value}", lambda: self.master.ingest(topic, body)
                )
            )

    def _later(self, action: Callable[[], None]) -> None:
        self.events.at(self.clock.monotonic() + self.latency_s, action)

    # -- the vehicle service's timing --------------------------------------------------------

    def _start_ticking(self) -> None:
        runtimes = self.fleet.runtimes
        period = 1 / self.fleet.settings.tick_hz
        slices = max(1, -(-len(runtimes) // SLICE))
        for index in range(slices):
            group = runtimes[index::slices]
            self.events.at(
                self.clock.monotonic() + period * (index + 1) / slices, self._ticker(group, period)
            )

    def _ticker(self, group: list[VehicleRuntime], period: float) -> Callable[[], None]:
        last = self.clock.monotonic()

        def tick() -> None:
            nonlocal last
            now = self.clock.monotonic()
            dt, last = now - last, now
            begin = time.process_time()
            for runtime in group:
                runtime.tick_to(now, dt)
            self.meter.cpu["vehicle ticks"] += time.process_time() - begin
            self.meter.calls["vehicle ticks"] += len(group)
            self.events.at(now + period, tick)

        return tick

    def _arrival_timer(self, runtime: VehicleRuntime) -> Callable[[float], None]:
        due: list[float] = []

        def fire(at: float) -> None:
            if due and due[-1] == at:
                due.clear()
                self.meter.run("vehicle arrival", lambda: runtime.tick_event(at))

        def schedule(at: float) -> None:
            if not (due and abs(due[-1] - at) < EVENT_SLACK_S):
                due[:] = [at]
                self.events.at(at, lambda: fire(at))

        return schedule

    # -- the drive ---------------------------------------------------------------------------

    def drive(self, profiler: cProfile.Profile | None = None) -> float:
        """CPU-seconds from the first order until every vehicle is done (under ``profiler``,
        if given)."""
        self.events.run_until(self.clock.monotonic() + 2.0)  # connected, known, available
        self.meter = Meter()
        gc.collect()
        start = self.clock.monotonic()
        for index, serial in enumerate(self.runtimes):
            request = OrderRequest(
                Target(route=(f"e1_{index}", f"e2_{index}")), AgvId(MANUFACTURER, serial), ()
            )
            self.events.at(start + index / len(self.runtimes), self._create_later(request))
        begin = time.process_time()
        with tuned_collector():  # as both services run
            if profiler is not None:
                profiler.enable()
            self._until_done()
            if profiler is not None:
                profiler.disable()
        return time.process_time() - begin

    def _create_later(self, request: OrderRequest) -> Callable[[], None]:
        """Creating ``request``'s order, timed, as an event."""

        def create() -> None:
            self.meter.run("master create_order", lambda: self.master.create_order(request))

        return create

    def _until_done(self) -> None:
        # Done as master control sees it (reading a vehicle's state would simulate its
        # skipped ticks and change what is measured).
        while sum(t.status is OrderStatus.FINISHED for t in self.master.tracks.values()) < len(
            self.runtimes
        ):
            self.events.run_until(self.clock.monotonic() + 0.5)


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--vehicles", type=int, default=1000)
    cli.add_argument("--latency-ms", type=float, default=2.0)
    cli.add_argument("--profile", type=Path, help="write a cProfile of the drive here")
    args = cli.parse_args()
    structlog.configure(
        wrapper_class=structlog.make_filtering_bound_logger(30), cache_logger_on_first_use=True
    )  # WARNING, as fleet.py runs the services
    with tempfile.TemporaryDirectory() as folder:
        graph = Path(folder) / "lanes.json"
        lanes_graph(graph, args.vehicles)
        scenario = Scenario(args.vehicles, graph, args.latency_ms / 1000)
        profiler = cProfile.Profile() if args.profile else None
        total = scenario.drive(profiler)
        if profiler is not None:
            profiler.dump_stats(args.profile)
    print(
        f"N = {args.vehicles}: {total:.3f} CPU-s for the drive (master and vehicles' Python work)"
    )
    scenario.meter.report()
    return 0


if __name__ == "__main__":
    sys.exit(main())
